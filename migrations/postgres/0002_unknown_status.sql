-- A joint whose parameters the trace cannot pin down (or that has no Table 4 baseline) has the
-- status `unknown` (the models' verdict); 0001 allowed only ok/watch/alarm.
ALTER TABLE fits DROP CONSTRAINT fits_status_check;
ALTER TABLE fits ADD CONSTRAINT fits_status_check
    CHECK (status IN ('unknown', 'ok', 'watch', 'alarm'));
ALTER TABLE fit_joints DROP CONSTRAINT fit_joints_status_check;
ALTER TABLE fit_joints ADD CONSTRAINT fit_joints_status_check
    CHECK (status IN ('unknown', 'ok', 'watch', 'alarm'));

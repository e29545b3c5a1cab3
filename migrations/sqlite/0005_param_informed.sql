-- Health from the fit that informed each parameter (issue 15): each joint's viscous and dry
-- carry whether the fit informed them and their own status, so a test that cannot inform a
-- parameter (a lift for J5's viscous damping, say) never changes that parameter's status.
-- `joint_latest` is then the worst status over each parameter's latest informing fit (the rule
-- in store::JOINT_LATEST_REFRESH_SQL, kept in step with the one below).
-- Same shape as migrations/postgres/0005_param_informed.sql.

ALTER TABLE fit_joints ADD COLUMN viscous_informed INTEGER CHECK (viscous_informed IN (0, 1));
ALTER TABLE fit_joints ADD COLUMN viscous_status TEXT
    CHECK (viscous_status IN ('unknown', 'ok', 'watch', 'alarm'));
ALTER TABLE fit_joints ADD COLUMN dry_informed INTEGER CHECK (dry_informed IN (0, 1));
ALTER TABLE fit_joints ADD COLUMN dry_status TEXT
    CHECK (dry_status IN ('unknown', 'ok', 'watch', 'alarm'));

-- Backfill from the stored fit results (a result without the per-parameter fields leaves NULL,
-- read as the joint's own flag and status).
UPDATE fit_joints SET
    viscous_informed = (SELECT CASE json_extract(e.value, '$.viscous.identifiable')
                                   WHEN 1 THEN 1 WHEN 0 THEN 0 END
                        FROM fits f, json_each(f.result_json, '$.joints') e
                        WHERE f.id = fit_joints.fit_id
                          AND json_extract(e.value, '$.joint') = fit_joints.joint),
    viscous_status = (SELECT json_extract(e.value, '$.viscous.status')
                      FROM fits f, json_each(f.result_json, '$.joints') e
                      WHERE f.id = fit_joints.fit_id
                        AND json_extract(e.value, '$.joint') = fit_joints.joint
                        AND json_extract(e.value, '$.viscous.status')
                            IN ('unknown', 'ok', 'watch', 'alarm')),
    dry_informed = (SELECT CASE json_extract(e.value, '$.dry.identifiable')
                               WHEN 1 THEN 1 WHEN 0 THEN 0 END
                    FROM fits f, json_each(f.result_json, '$.joints') e
                    WHERE f.id = fit_joints.fit_id
                      AND json_extract(e.value, '$.joint') = fit_joints.joint),
    dry_status = (SELECT json_extract(e.value, '$.dry.status')
                  FROM fits f, json_each(f.result_json, '$.joints') e
                  WHERE f.id = fit_joints.fit_id
                    AND json_extract(e.value, '$.joint') = fit_joints.joint
                    AND json_extract(e.value, '$.dry.status') IN ('unknown', 'ok', 'watch', 'alarm'));

DELETE FROM joint_latest;
INSERT INTO joint_latest
        (serial, joint, trace_id, fit_id, recorded_at, identifiable, status)
    SELECT serial, joint, trace_id, fit_id, recorded_at, (informs = 1), status FROM (
        SELECT p.*, ROW_NUMBER() OVER (PARTITION BY serial, joint
                        ORDER BY informs DESC,
                                 CASE status WHEN 'alarm' THEN 3 WHEN 'watch' THEN 2
                                             WHEN 'ok' THEN 1 ELSE 0 END DESC,
                                 recorded_at DESC, trace_id DESC) AS rn2
        FROM (
            SELECT o.*, ROW_NUMBER() OVER (PARTITION BY serial, joint, param
                            ORDER BY informs DESC, recorded_at DESC, trace_id DESC) AS rn
            FROM (
            SELECT t.serial, j.joint, 'viscous' AS param, t.trace_id, f.id AS fit_id, t.recorded_at,
                   CASE WHEN j.viscous IS NOT NULL AND COALESCE(j.viscous_informed, j.identifiable)
                             AND COALESCE(j.viscous_status, j.status) <> 'unknown' THEN 1 ELSE 0 END AS informs,
                   CASE WHEN j.viscous IS NOT NULL THEN COALESCE(j.viscous_status, j.status)
                        ELSE 'unknown' END AS status
            FROM traces t
            JOIN fits f ON f.trace_id = t.trace_id
                       AND f.id = (SELECT max(f2.id) FROM fits f2 WHERE f2.trace_id = t.trace_id)
            JOIN fit_joints j ON j.fit_id = f.id
            WHERE t.serial IS NOT NULL
            UNION ALL
            SELECT t.serial, j.joint, 'dry' AS param, t.trace_id, f.id AS fit_id, t.recorded_at,
                   CASE WHEN j.dry IS NOT NULL AND COALESCE(j.dry_informed, j.identifiable)
                             AND COALESCE(j.dry_status, j.status) <> 'unknown' THEN 1 ELSE 0 END AS informs,
                   CASE WHEN j.dry IS NOT NULL THEN COALESCE(j.dry_status, j.status)
                        ELSE 'unknown' END AS status
            FROM traces t
            JOIN fits f ON f.trace_id = t.trace_id
                       AND f.id = (SELECT max(f2.id) FROM fits f2 WHERE f2.trace_id = t.trace_id)
            JOIN fit_joints j ON j.fit_id = f.id
            WHERE t.serial IS NOT NULL
            ) o
        ) p WHERE rn = 1
    ) x WHERE rn2 = 1;

DELETE FROM pantograph_health;
INSERT INTO pantograph_health (serial, worst, not_ok)
SELECT serial,
       max(CASE status WHEN 'alarm' THEN 3 WHEN 'watch' THEN 2 WHEN 'ok' THEN 1 ELSE 0 END),
       group_concat(CASE WHEN status <> 'ok' THEN joint || ':' || status END, char(31))
FROM joint_latest GROUP BY serial;

-- Health from the fit that informed each parameter (issue 15): see
-- migrations/sqlite/0005_param_informed.sql (same shape).

ALTER TABLE fit_joints ADD COLUMN viscous_informed BOOLEAN;
ALTER TABLE fit_joints ADD COLUMN viscous_status TEXT
    CHECK (viscous_status IN ('unknown', 'ok', 'watch', 'alarm'));
ALTER TABLE fit_joints ADD COLUMN dry_informed BOOLEAN;
ALTER TABLE fit_joints ADD COLUMN dry_status TEXT
    CHECK (dry_status IN ('unknown', 'ok', 'watch', 'alarm'));

UPDATE fit_joints j SET
    viscous_informed = CASE jsonb_typeof(e -> 'viscous' -> 'identifiable')
                           WHEN 'boolean' THEN (e -> 'viscous' ->> 'identifiable')::boolean END,
    viscous_status = CASE WHEN e -> 'viscous' ->> 'status' IN ('unknown', 'ok', 'watch', 'alarm')
                          THEN e -> 'viscous' ->> 'status' END,
    dry_informed = CASE jsonb_typeof(e -> 'dry' -> 'identifiable')
                       WHEN 'boolean' THEN (e -> 'dry' ->> 'identifiable')::boolean END,
    dry_status = CASE WHEN e -> 'dry' ->> 'status' IN ('unknown', 'ok', 'watch', 'alarm')
                      THEN e -> 'dry' ->> 'status' END
FROM fits f, jsonb_array_elements(f.result_json -> 'joints') e
WHERE f.id = j.fit_id AND e ->> 'joint' = j.joint
  AND jsonb_typeof(f.result_json -> 'joints') = 'array';

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
       string_agg(CASE WHEN status <> 'ok' THEN joint || ':' || status END, chr(31))
FROM joint_latest GROUP BY serial;

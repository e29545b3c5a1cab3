-- Fleet health without a window over every fit: each pantograph joint's latest informed verdict
-- (`joint_latest`) and each pantograph's roll-up (`pantograph_health`), rewritten for one serial
-- by the store in the same transaction as every fit it writes (store::sqlite `refresh_health`).
-- Same shape as migrations/postgres/0004_joint_latest.sql. Traces and fits are never deleted
-- (no code path does), so a fit write is the only event that changes these rows.

CREATE TABLE joint_latest (
    serial       TEXT NOT NULL REFERENCES pantographs (serial),
    joint        TEXT NOT NULL CHECK (length(joint) > 0),
    trace_id     TEXT NOT NULL,
    fit_id       INTEGER NOT NULL,
    recorded_at  TEXT NOT NULL,
    identifiable INTEGER NOT NULL CHECK (identifiable IN (0, 1)),
    status       TEXT NOT NULL CHECK (status IN ('unknown', 'ok', 'watch', 'alarm')),
    PRIMARY KEY (serial, joint)
) STRICT;

-- `worst`: 3 alarm, 2 watch, 1 ok, 0 unknown (`Status::rank`); `not_ok`: `joint:status` pairs
-- joined by U+001F, NULL when every joint is ok.
CREATE TABLE pantograph_health (
    serial TEXT PRIMARY KEY REFERENCES pantographs (serial),
    worst  INTEGER NOT NULL CHECK (worst BETWEEN 0 AND 3),
    not_ok TEXT
) STRICT;
CREATE INDEX pantograph_health_worst ON pantograph_health (worst, serial);

-- Backfill from the fits already stored: the same rule as the store's window query.
INSERT INTO joint_latest (serial, joint, trace_id, fit_id, recorded_at, identifiable, status)
SELECT serial, joint, trace_id, fit_id, recorded_at, identifiable, status FROM (
    SELECT t.serial, j.joint, t.trace_id, f.id AS fit_id, t.recorded_at, j.identifiable, j.status,
           ROW_NUMBER() OVER (PARTITION BY t.serial, j.joint
                              ORDER BY j.identifiable DESC, t.recorded_at DESC, t.trace_id DESC) AS rn
    FROM traces t
    JOIN fits f ON f.trace_id = t.trace_id
               AND f.id = (SELECT max(f2.id) FROM fits f2 WHERE f2.trace_id = t.trace_id)
    JOIN fit_joints j ON j.fit_id = f.id
    WHERE t.serial IS NOT NULL
) WHERE rn = 1;

INSERT INTO pantograph_health (serial, worst, not_ok)
SELECT serial,
       max(CASE status WHEN 'alarm' THEN 3 WHEN 'watch' THEN 2 WHEN 'ok' THEN 1 ELSE 0 END),
       group_concat(CASE WHEN status <> 'ok' THEN joint || ':' || status END, char(31))
FROM joint_latest GROUP BY serial;

-- What each joint parameter's state rests on (issue 37, point 1): per pantograph, joint and
-- parameter (viscous, dry), the latest test of each kind that informed it (`informs`: a value,
-- identified, a verdict other than `unknown` — the rule of `joint_latest`, migration 0005), its
-- value and 95 % interval then: the latest over the kinds is the parameter's evidence, each
-- kind's interval the information that kind of test gives on it (the test plan). Rewritten for one serial by the store in the same transaction
-- as every fit it writes (store::rows PARAM_EVIDENCE_REFRESH_SQL, the same rule as below).
-- `slope_*`: the parameter's trend over its informing tests (models::trend), written by the
-- service after each fit of the pantograph (alerts::after_fit); NULL until then (the fleet's
-- wear rate is used). The fleet test plan reads this table alone.
-- Same shape as migrations/postgres/0008_param_evidence.sql.

CREATE TABLE param_evidence (
    serial            TEXT NOT NULL REFERENCES pantographs (serial),
    joint             TEXT NOT NULL CHECK (length(joint) > 0),
    param             TEXT NOT NULL CHECK (param IN ('viscous', 'dry')),
    trace_id          TEXT NOT NULL,
    fit_id            INTEGER NOT NULL,
    kind              TEXT NOT NULL,
    recorded_at       TEXT NOT NULL,
    value             REAL NOT NULL,
    lo                REAL NOT NULL,
    hi                REAL NOT NULL,
    status            TEXT NOT NULL CHECK (status IN ('unknown', 'ok', 'watch', 'alarm')),
    slope_per_day     REAL,
    slope_lo_per_day  REAL,
    slope_hi_per_day  REAL,
    slope_significant INTEGER,
    PRIMARY KEY (serial, joint, param, kind)
) STRICT;

-- A counter every write of `param_evidence` raises (the fit's refresh, the trends after it):
-- the service keeps the fleet plan's rows in memory until it moves (services::evidence).
CREATE TABLE evidence_version (
    id      INTEGER PRIMARY KEY CHECK (id = 1),
    version INTEGER NOT NULL
) STRICT;
INSERT INTO evidence_version (id, version) VALUES (1, 0);

-- Backfill from the fits already stored.
INSERT INTO param_evidence (serial, joint, param, trace_id, fit_id, kind, recorded_at, value, lo, hi, status)
SELECT serial, joint, param, trace_id, fit_id, kind, recorded_at, value, lo, hi, status FROM (
    SELECT o.*, ROW_NUMBER() OVER (PARTITION BY serial, joint, param, kind
                                   ORDER BY recorded_at DESC, trace_id DESC) AS rn
    FROM (
    SELECT t.serial, j.joint, 'viscous' AS param, t.trace_id, f.id AS fit_id, t.kind, t.recorded_at,
           j.viscous AS value, j.viscous_lo AS lo, j.viscous_hi AS hi, COALESCE(j.viscous_status, j.status) AS status
    FROM traces t
    JOIN fits f ON f.trace_id = t.trace_id
               AND f.id = (SELECT max(f2.id) FROM fits f2 WHERE f2.trace_id = t.trace_id)
    JOIN fit_joints j ON j.fit_id = f.id
    WHERE t.serial IS NOT NULL AND j.viscous IS NOT NULL AND j.viscous_lo IS NOT NULL
      AND j.viscous_hi IS NOT NULL AND j.viscous_hi > j.viscous_lo
      AND COALESCE(j.viscous_informed, j.identifiable)
      AND COALESCE(j.viscous_status, j.status) <> 'unknown'
    UNION ALL
    SELECT t.serial, j.joint, 'dry' AS param, t.trace_id, f.id AS fit_id, t.kind, t.recorded_at,
           j.dry AS value, j.dry_lo AS lo, j.dry_hi AS hi, COALESCE(j.dry_status, j.status) AS status
    FROM traces t
    JOIN fits f ON f.trace_id = t.trace_id
               AND f.id = (SELECT max(f2.id) FROM fits f2 WHERE f2.trace_id = t.trace_id)
    JOIN fit_joints j ON j.fit_id = f.id
    WHERE t.serial IS NOT NULL AND j.dry IS NOT NULL AND j.dry_lo IS NOT NULL
      AND j.dry_hi IS NOT NULL AND j.dry_hi > j.dry_lo
      AND COALESCE(j.dry_informed, j.identifiable)
      AND COALESCE(j.dry_status, j.status) <> 'unknown'
    ) o
) x WHERE rn = 1;

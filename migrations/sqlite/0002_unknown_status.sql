-- no-transaction
-- A joint whose parameters the trace cannot pin down (or that has no Table 4 baseline) has the
-- status `unknown` (the models' verdict); 0001 allowed only ok/watch/alarm. SQLite cannot alter
-- a CHECK constraint, so `fits` and `fit_joints` are rebuilt (foreign keys off while they are).
PRAGMA foreign_keys = OFF;
BEGIN IMMEDIATE;

CREATE TABLE fits_new (
    id            INTEGER PRIMARY KEY AUTOINCREMENT,
    trace_id      TEXT NOT NULL REFERENCES traces (trace_id) ON DELETE CASCADE,
    model_version TEXT NOT NULL CHECK (length(model_version) > 0),
    created_at    TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%f000Z', 'now')),
    result_json   TEXT NOT NULL CHECK (json_valid(result_json)),
    rmse          REAL,
    status        TEXT CHECK (status IN ('unknown', 'ok', 'watch', 'alarm')),
    UNIQUE (trace_id, model_version)
) STRICT;
INSERT INTO fits_new (id, trace_id, model_version, created_at, result_json, rmse, status)
    SELECT id, trace_id, model_version, created_at, result_json, rmse, status FROM fits;

CREATE TABLE fit_joints_new (
    fit_id       INTEGER NOT NULL REFERENCES fits (id) ON DELETE CASCADE,
    joint        TEXT NOT NULL CHECK (length(joint) > 0),
    viscous      REAL,
    viscous_lo   REAL,
    viscous_hi   REAL,
    dry          REAL,
    dry_lo       REAL,
    dry_hi       REAL,
    identifiable INTEGER NOT NULL CHECK (identifiable IN (0, 1)),
    status       TEXT NOT NULL CHECK (status IN ('unknown', 'ok', 'watch', 'alarm')),
    PRIMARY KEY (fit_id, joint)
) STRICT;
INSERT INTO fit_joints_new
    SELECT fit_id, joint, viscous, viscous_lo, viscous_hi, dry, dry_lo, dry_hi, identifiable, status
    FROM fit_joints;

DROP TABLE fit_joints;
DROP TABLE fits;
ALTER TABLE fits_new RENAME TO fits;
ALTER TABLE fit_joints_new RENAME TO fit_joints;
CREATE INDEX fit_joints_joint ON fit_joints (joint, fit_id);

COMMIT;
PRAGMA foreign_keys = ON;

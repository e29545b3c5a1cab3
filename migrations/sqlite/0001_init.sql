-- pantowatch schema, SQLite flavour (same shape as migrations/postgres/0001_init.sql).
-- Timestamps are UTC text 'YYYY-MM-DDTHH:MM:SS.ffffffZ' (fixed width, so text order = time order).

CREATE TABLE vehicles (
    id         TEXT PRIMARY KEY CHECK (length(id) > 0),
    created_at TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%f000Z', 'now'))
) STRICT;

CREATE TABLE pantographs (
    serial     TEXT PRIMARY KEY CHECK (length(serial) > 0),
    model      TEXT NOT NULL CHECK (length(model) > 0),
    created_at TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%f000Z', 'now'))
) STRICT;

-- Where a pantograph is mounted from `since` until the next mount of the same serial.
CREATE TABLE pantograph_mounts (
    serial     TEXT NOT NULL REFERENCES pantographs (serial),
    vehicle_id TEXT NOT NULL REFERENCES vehicles (id),
    since      TEXT NOT NULL,
    created_at TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%f000Z', 'now')),
    PRIMARY KEY (serial, since)
) STRICT;
CREATE INDEX pantograph_mounts_vehicle ON pantograph_mounts (vehicle_id);

CREATE TABLE traces (
    trace_id       TEXT PRIMARY KEY CHECK (length(trace_id) > 0),
    vehicle_id     TEXT NOT NULL REFERENCES vehicles (id),
    serial         TEXT REFERENCES pantographs (serial),
    model          TEXT NOT NULL,
    recorded_at    TEXT NOT NULL,
    kind           TEXT NOT NULL CHECK (length(kind) > 0),
    joint          TEXT,
    test_json      TEXT NOT NULL,
    content_sha256 TEXT NOT NULL CHECK (length(content_sha256) = 64),
    samples        BLOB NOT NULL,
    sample_count   INTEGER NOT NULL CHECK (sample_count >= 0),
    channel_names  TEXT NOT NULL,
    created_at     TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%f000Z', 'now'))
) STRICT;
CREATE INDEX traces_vehicle ON traces (vehicle_id, recorded_at);
CREATE INDEX traces_serial ON traces (serial, recorded_at);

CREATE TABLE fits (
    id            INTEGER PRIMARY KEY AUTOINCREMENT,
    trace_id      TEXT NOT NULL REFERENCES traces (trace_id) ON DELETE CASCADE,
    model_version TEXT NOT NULL CHECK (length(model_version) > 0),
    created_at    TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%f000Z', 'now')),
    result_json   TEXT NOT NULL CHECK (json_valid(result_json)),
    rmse          REAL,
    status        TEXT CHECK (status IN ('ok', 'watch', 'alarm')),
    UNIQUE (trace_id, model_version)
) STRICT;

CREATE TABLE fit_joints (
    fit_id       INTEGER NOT NULL REFERENCES fits (id) ON DELETE CASCADE,
    joint        TEXT NOT NULL CHECK (length(joint) > 0),
    viscous      REAL,
    viscous_lo   REAL,
    viscous_hi   REAL,
    dry          REAL,
    dry_lo       REAL,
    dry_hi       REAL,
    identifiable INTEGER NOT NULL CHECK (identifiable IN (0, 1)),
    status       TEXT NOT NULL CHECK (status IN ('ok', 'watch', 'alarm')),
    PRIMARY KEY (fit_id, joint)
) STRICT;
CREATE INDEX fit_joints_joint ON fit_joints (joint, fit_id);

CREATE TABLE jobs (
    id            INTEGER PRIMARY KEY AUTOINCREMENT,
    trace_id      TEXT NOT NULL REFERENCES traces (trace_id) ON DELETE CASCADE,
    model_version TEXT NOT NULL CHECK (length(model_version) > 0),
    state         TEXT NOT NULL DEFAULT 'queued'
                  CHECK (state IN ('queued', 'running', 'done', 'failed')),
    attempts      INTEGER NOT NULL DEFAULT 0,
    lease_until   TEXT,
    worker        TEXT,
    last_error    TEXT,
    created_at    TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%f000Z', 'now')),
    updated_at    TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%f000Z', 'now'))
) STRICT;
-- At most one live job per (trace, model version).
CREATE UNIQUE INDEX jobs_live_pair ON jobs (trace_id, model_version)
    WHERE state IN ('queued', 'running');
CREATE INDEX jobs_claimable ON jobs (state, id);
CREATE INDEX jobs_trace ON jobs (trace_id, id);

CREATE TABLE api_keys (
    id         INTEGER PRIMARY KEY AUTOINCREMENT,
    prefix     TEXT NOT NULL CHECK (length(prefix) = 8),
    key_sha256 TEXT NOT NULL UNIQUE CHECK (length(key_sha256) = 64),
    role       TEXT NOT NULL CHECK (role IN ('reader', 'writer', 'admin')),
    label      TEXT NOT NULL DEFAULT '',
    created_at TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%f000Z', 'now')),
    revoked_at TEXT
) STRICT;
CREATE INDEX api_keys_prefix ON api_keys (prefix);

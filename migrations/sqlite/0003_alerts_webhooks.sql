-- Alerts (one open per pantograph serial and joint), their full history, webhook subscriptions
-- and the durable delivery outbox. Same shape as migrations/postgres/0003_alerts_webhooks.sql.

CREATE TABLE alerts (
    id              INTEGER PRIMARY KEY AUTOINCREMENT,
    serial          TEXT NOT NULL REFERENCES pantographs (serial),
    joint           TEXT NOT NULL CHECK (length(joint) > 0),
    vehicle_id      TEXT,
    severity        TEXT NOT NULL CHECK (severity IN ('watch', 'alarm')),
    state           TEXT NOT NULL DEFAULT 'open'
                    CHECK (state IN ('open', 'acknowledged', 'resolved')),
    reason          TEXT NOT NULL,
    evidence_json   TEXT NOT NULL CHECK (json_valid(evidence_json)),
    trace_id        TEXT NOT NULL,
    opened_at       TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%f000Z', 'now')),
    updated_at      TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%f000Z', 'now')),
    acknowledged_by TEXT,
    acknowledged_at TEXT,
    resolved_by     TEXT,
    resolved_at     TEXT
) STRICT;
-- Deduplication: at most one alert per (serial, joint) that is not resolved.
CREATE UNIQUE INDEX alerts_live_pair ON alerts (serial, joint) WHERE state <> 'resolved';
CREATE INDEX alerts_state ON alerts (state, severity, id);

CREATE TABLE alert_events (
    id        INTEGER PRIMARY KEY AUTOINCREMENT,
    alert_id  INTEGER NOT NULL REFERENCES alerts (id) ON DELETE CASCADE,
    at        TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%f000Z', 'now')),
    kind      TEXT NOT NULL
              CHECK (kind IN ('opened', 'escalated', 'updated', 'acknowledged', 'resolved')),
    severity  TEXT NOT NULL CHECK (severity IN ('watch', 'alarm')),
    actor     TEXT NOT NULL,
    note      TEXT NOT NULL DEFAULT '',
    trace_id  TEXT
) STRICT;
CREATE INDEX alert_events_alert ON alert_events (alert_id, id);

CREATE TABLE webhooks (
    id         INTEGER PRIMARY KEY AUTOINCREMENT,
    url        TEXT NOT NULL CHECK (length(url) > 0),
    -- Comma-separated, e.g. 'watch,alarm'.
    severities TEXT NOT NULL,
    secret     TEXT NOT NULL CHECK (length(secret) > 0),
    created_at TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%f000Z', 'now')),
    deleted_at TEXT
) STRICT;

-- The outbox: written in the transaction of the alert change it reports.
CREATE TABLE webhook_deliveries (
    id              INTEGER PRIMARY KEY AUTOINCREMENT,
    webhook_id      INTEGER NOT NULL REFERENCES webhooks (id),
    alert_id        INTEGER NOT NULL REFERENCES alerts (id),
    event           TEXT NOT NULL,
    payload         TEXT NOT NULL CHECK (json_valid(payload)),
    state           TEXT NOT NULL DEFAULT 'pending'
                    CHECK (state IN ('pending', 'delivered', 'failed')),
    attempts        INTEGER NOT NULL DEFAULT 0,
    next_attempt_at TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%f000Z', 'now')),
    last_status     INTEGER,
    last_error      TEXT,
    created_at      TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%f000Z', 'now')),
    updated_at      TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%f000Z', 'now')),
    delivered_at    TEXT
) STRICT;
CREATE INDEX webhook_deliveries_due ON webhook_deliveries (state, next_attempt_at);
CREATE INDEX webhook_deliveries_hook ON webhook_deliveries (webhook_id, id);

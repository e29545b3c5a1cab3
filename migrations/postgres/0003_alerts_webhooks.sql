-- Alerts (one open per pantograph serial and joint), their full history, webhook subscriptions
-- and the durable delivery outbox. Same shape as migrations/sqlite/0003_alerts_webhooks.sql.

CREATE TABLE alerts (
    id              BIGSERIAL PRIMARY KEY,
    serial          TEXT NOT NULL REFERENCES pantographs (serial),
    joint           TEXT NOT NULL CHECK (length(joint) > 0),
    vehicle_id      TEXT,
    severity        TEXT NOT NULL CHECK (severity IN ('watch', 'alarm')),
    state           TEXT NOT NULL DEFAULT 'open'
                    CHECK (state IN ('open', 'acknowledged', 'resolved')),
    reason          TEXT NOT NULL,
    evidence_json   JSONB NOT NULL,
    trace_id        TEXT NOT NULL,
    opened_at       TIMESTAMPTZ NOT NULL DEFAULT now(),
    updated_at      TIMESTAMPTZ NOT NULL DEFAULT now(),
    acknowledged_by TEXT,
    acknowledged_at TIMESTAMPTZ,
    resolved_by     TEXT,
    resolved_at     TIMESTAMPTZ
);
-- Deduplication: at most one alert per (serial, joint) that is not resolved.
CREATE UNIQUE INDEX alerts_live_pair ON alerts (serial, joint) WHERE state <> 'resolved';
CREATE INDEX alerts_state ON alerts (state, severity, id);

CREATE TABLE alert_events (
    id        BIGSERIAL PRIMARY KEY,
    alert_id  BIGINT NOT NULL REFERENCES alerts (id) ON DELETE CASCADE,
    at        TIMESTAMPTZ NOT NULL DEFAULT now(),
    kind      TEXT NOT NULL
              CHECK (kind IN ('opened', 'escalated', 'updated', 'acknowledged', 'resolved')),
    severity  TEXT NOT NULL CHECK (severity IN ('watch', 'alarm')),
    actor     TEXT NOT NULL,
    note      TEXT NOT NULL DEFAULT '',
    trace_id  TEXT
);
CREATE INDEX alert_events_alert ON alert_events (alert_id, id);

CREATE TABLE webhooks (
    id         BIGSERIAL PRIMARY KEY,
    url        TEXT NOT NULL CHECK (length(url) > 0),
    -- Comma-separated, e.g. 'watch,alarm'.
    severities TEXT NOT NULL,
    secret     TEXT NOT NULL CHECK (length(secret) > 0),
    created_at TIMESTAMPTZ NOT NULL DEFAULT now(),
    deleted_at TIMESTAMPTZ
);

-- The outbox: written in the transaction of the alert change it reports.
CREATE TABLE webhook_deliveries (
    id              BIGSERIAL PRIMARY KEY,
    webhook_id      BIGINT NOT NULL REFERENCES webhooks (id),
    alert_id        BIGINT NOT NULL REFERENCES alerts (id),
    event           TEXT NOT NULL,
    payload         JSONB NOT NULL,
    state           TEXT NOT NULL DEFAULT 'pending'
                    CHECK (state IN ('pending', 'delivered', 'failed')),
    attempts        BIGINT NOT NULL DEFAULT 0,
    next_attempt_at TIMESTAMPTZ NOT NULL DEFAULT now(),
    last_status     BIGINT,
    last_error      TEXT,
    created_at      TIMESTAMPTZ NOT NULL DEFAULT now(),
    updated_at      TIMESTAMPTZ NOT NULL DEFAULT now(),
    delivered_at    TIMESTAMPTZ
);
CREATE INDEX webhook_deliveries_due ON webhook_deliveries (state, next_attempt_at);
CREATE INDEX webhook_deliveries_hook ON webhook_deliveries (webhook_id, id);

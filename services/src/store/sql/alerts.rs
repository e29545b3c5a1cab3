//! Alerts, alert events, webhook subscriptions and the delivery outbox: written once,
//! instantiated with `alerts_impl!();`. Every write is one transaction (alert row + event +
//! outbox rows together); raises serialise per (serial, joint) (`lock_alert_pair` on
//! PostgreSQL, `BEGIN IMMEDIATE` on SQLite); deliveries are claimed with `claim_lock!()`
//! (`SKIP LOCKED` on PostgreSQL).

macro_rules! alerts_impl {
    () => {
async fn alert_by_id(c: &mut Conn, id: i64) -> Result<Option<Alert>> {
    query(concat!(
        "SELECT ",
        alert_cols!(),
        " FROM alerts WHERE id = $1",
        for_update!()
    ))
    .bind(id)
    .fetch_optional(&mut *c)
    .await?
    .map(|r| alert_from(&r))
    .transpose()
}

async fn live_alert(c: &mut Conn, serial: &str, joint: &str) -> Result<Option<Alert>> {
    query(concat!(
        "SELECT ",
        alert_cols!(),
        " FROM alerts WHERE serial = $1 AND joint = $2 AND state <> 'resolved'",
        for_update!()
    ))
    .bind(serial)
    .bind(joint)
    .fetch_optional(&mut *c)
    .await?
    .map(|r| alert_from(&r))
    .transpose()
}

async fn add_event(
    c: &mut Conn,
    a: &Alert,
    kind: &str,
    actor: &str,
    note: &str,
    trace_id: Option<&str>,
) -> Result<()> {
    query(
        "INSERT INTO alert_events (alert_id, kind, severity, actor, note, trace_id)
         VALUES ($1, $2, $3, $4, $5, $6)",
    )
    .bind(a.id)
    .bind(kind)
    .bind(a.severity.as_str())
    .bind(actor)
    .bind(note)
    .bind(trace_id)
    .execute(&mut *c)
    .await?;
    Ok(())
}

/// The outbox rows of one alert change: one per live subscription to its severity.
async fn enqueue_deliveries(c: &mut Conn, a: &Alert, event: &str) -> Result<()> {
    let body = payload(event, a)?;
    query(concat!(
        "INSERT INTO webhook_deliveries (webhook_id, alert_id, event, payload)
         SELECT id, $1, $2, $3",
        jsonb!(),
        " FROM webhooks
         WHERE deleted_at IS NULL AND (',' || severities || ',') LIKE ('%,' || $4 || ',%')"
    ))
    .bind(a.id)
    .bind(event)
    .bind(body)
    .bind(a.severity.as_str())
    .execute(&mut *c)
    .await?;
    Ok(())
}

fn evidence_text(a: &NewAlert) -> Result<String> {
    serde_json::to_string(&a.evidence).map_err(|e| StoreError::Invalid(format!("evidence: {e}")))
}

impl AlertBackend for Backend {
    async fn raise_alert(&self, a: &NewAlert) -> Result<RaiseOutcome> {
        let ev = evidence_text(a)?;
        let mut tx = self.begin().await?;
        lock_alert_pair(&mut tx, &a.serial, &a.joint).await?;
        let out = match live_alert(&mut tx, &a.serial, &a.joint).await? {
            None => {
                let id: i64 = query_scalar(concat!(
                    "INSERT INTO alerts (serial, joint, vehicle_id, severity, reason,
                                         evidence_json, trace_id)
                     VALUES ($1, $2, $3, $4, $5, $6",
                    jsonb!(),
                    ", $7) RETURNING id"
                ))
                .bind(&a.serial)
                .bind(&a.joint)
                .bind(&a.vehicle_id)
                .bind(a.severity.as_str())
                .bind(&a.reason)
                .bind(&ev)
                .bind(&a.trace_id)
                .fetch_one(&mut *tx)
                .await?;
                let al = alert_by_id(&mut tx, id)
                    .await?
                    .ok_or_else(|| StoreError::Corrupt("inserted alert vanished".into()))?;
                add_event(
                    &mut tx,
                    &al,
                    "opened",
                    "system",
                    &a.reason,
                    Some(&a.trace_id),
                )
                .await?;
                enqueue_deliveries(&mut tx, &al, EVENT_OPENED).await?;
                RaiseOutcome::Opened(al)
            }
            Some(cur) => {
                let escalate = a.severity > cur.severity;
                let severity = cur.severity.max(a.severity);
                let state = if escalate {
                    AlertState::Open
                } else {
                    cur.state
                };
                query(concat!(
                    "UPDATE alerts SET severity = $2, state = $3, reason = $4, evidence_json = $5",
                    jsonb!(),
                    ", trace_id = $6, vehicle_id = coalesce(CAST($7 AS TEXT), vehicle_id),
                            updated_at = ",
                    now!(),
                    "
                     WHERE id = $1"
                ))
                .bind(cur.id)
                .bind(severity.as_str())
                .bind(state.as_str())
                .bind(&a.reason)
                .bind(&ev)
                .bind(&a.trace_id)
                .bind(&a.vehicle_id)
                .execute(&mut *tx)
                .await?;
                let al = alert_by_id(&mut tx, cur.id)
                    .await?
                    .ok_or_else(|| StoreError::Corrupt("updated alert vanished".into()))?;
                if escalate {
                    add_event(
                        &mut tx,
                        &al,
                        "escalated",
                        "system",
                        &a.reason,
                        Some(&a.trace_id),
                    )
                    .await?;
                    enqueue_deliveries(&mut tx, &al, EVENT_ESCALATED).await?;
                    RaiseOutcome::Escalated(al)
                } else {
                    add_event(
                        &mut tx,
                        &al,
                        "updated",
                        "system",
                        &a.reason,
                        Some(&a.trace_id),
                    )
                    .await?;
                    RaiseOutcome::Updated(al)
                }
            }
        };
        tx.commit().await?;
        Ok(out)
    }

    async fn acknowledge_alert(
        &self,
        id: i64,
        actor: &str,
        note: &str,
    ) -> Result<Transition> {
        let mut tx = self.begin().await?;
        let Some(cur) = alert_by_id(&mut tx, id).await? else {
            tx.rollback().await?;
            return Ok(Transition::NotFound);
        };
        if cur.state != AlertState::Open {
            tx.rollback().await?;
            return Ok(Transition::Refused(cur));
        }
        query(concat!(
            "UPDATE alerts SET state = 'acknowledged', acknowledged_by = $2,
                    acknowledged_at = ",
            now!(),
            ", updated_at = ",
            now!(),
            " WHERE id = $1"
        ))
        .bind(id)
        .bind(actor)
        .execute(&mut *tx)
        .await?;
        let al = alert_by_id(&mut tx, id)
            .await?
            .ok_or_else(|| StoreError::Corrupt("alert vanished".into()))?;
        add_event(&mut tx, &al, "acknowledged", actor, note, None).await?;
        tx.commit().await?;
        Ok(Transition::Done(al))
    }

    async fn resolve_alert(
        &self,
        target: Target<'_>,
        actor: &str,
        note: &str,
        trace_id: Option<&str>,
    ) -> Result<Transition> {
        let mut tx = self.begin().await?;
        let cur = match target {
            Target::Id(id) => alert_by_id(&mut tx, id).await?,
            Target::Pair(s, j) => live_alert(&mut tx, s, j).await?,
        };
        let Some(cur) = cur else {
            tx.rollback().await?;
            return Ok(Transition::NotFound);
        };
        if cur.state == AlertState::Resolved {
            tx.rollback().await?;
            return Ok(Transition::Refused(cur));
        }
        query(concat!(
            "UPDATE alerts SET state = 'resolved', resolved_by = $2, resolved_at = ",
            now!(),
            ",
                    updated_at = ",
            now!(),
            " WHERE id = $1"
        ))
        .bind(cur.id)
        .bind(actor)
        .execute(&mut *tx)
        .await?;
        let al = alert_by_id(&mut tx, cur.id)
            .await?
            .ok_or_else(|| StoreError::Corrupt("alert vanished".into()))?;
        add_event(&mut tx, &al, "resolved", actor, note, trace_id).await?;
        enqueue_deliveries(&mut tx, &al, EVENT_RESOLVED).await?;
        tx.commit().await?;
        Ok(Transition::Done(al))
    }

    async fn list_alerts(&self, f: &AlertFilter) -> Result<Vec<Alert>> {
        query(concat!(
            "SELECT ",
            alert_cols!(),
            " FROM alerts
             WHERE (CAST($1 AS TEXT) IS NULL OR state = CAST($1 AS TEXT))
               AND (CAST($2 AS TEXT) IS NULL OR severity = CAST($2 AS TEXT))
               AND (CAST($3 AS TEXT) IS NULL OR vehicle_id = CAST($3 AS TEXT))
               AND (NOT CAST($4 AS BOOLEAN) OR state <> 'resolved')
             ORDER BY id DESC"
        ))
        .bind(f.state.map(AlertState::as_str))
        .bind(f.severity.map(Severity::as_str))
        .bind(&f.vehicle_id)
        .bind(f.live && f.state.is_none())
        .fetch_all(self.pool())
        .await?
        .iter()
        .map(alert_from)
        .collect()
    }

    async fn get_alert(&self, id: i64) -> Result<Option<Alert>> {
        query(concat!(
            "SELECT ",
            alert_cols!(),
            " FROM alerts WHERE id = $1"
        ))
        .bind(id)
        .fetch_optional(self.pool())
        .await?
        .map(|r| alert_from(&r))
        .transpose()
    }

    async fn alert_events(&self, id: i64) -> Result<Vec<AlertEvent>> {
        query(
            "SELECT id, alert_id, at, kind, severity, actor, note, trace_id FROM alert_events
             WHERE alert_id = $1 ORDER BY id",
        )
        .bind(id)
        .fetch_all(self.pool())
        .await?
        .iter()
        .map(event_from)
        .collect()
    }

    async fn insert_webhook(&self, url: &str, sev: &str, secret: &str) -> Result<Webhook> {
        let r = query(
            "INSERT INTO webhooks (url, severities, secret) VALUES ($1, $2, $3)
             RETURNING id, url, severities, created_at, deleted_at",
        )
        .bind(url)
        .bind(sev)
        .bind(secret)
        .fetch_one(self.pool())
        .await?;
        webhook_from(&r)
    }

    async fn list_webhooks(&self) -> Result<Vec<Webhook>> {
        query("SELECT id, url, severities, created_at, deleted_at FROM webhooks ORDER BY id")
            .fetch_all(self.pool())
            .await?
            .iter()
            .map(webhook_from)
            .collect()
    }

    async fn delete_webhook(&self, id: i64) -> Result<bool> {
        let mut tx = self.begin().await?;
        let n = query(concat!(
            "UPDATE webhooks SET deleted_at = ",
            now!(),
            " WHERE id = $1 AND deleted_at IS NULL"
        ))
        .bind(id)
        .execute(&mut *tx)
        .await?
        .rows_affected();
        query(concat!(
            "UPDATE webhook_deliveries SET state = 'failed', last_error = 'subscription deleted',
                    updated_at = ",
            now!(),
            " WHERE webhook_id = $1 AND state = 'pending'"
        ))
        .bind(id)
        .execute(&mut *tx)
        .await?;
        tx.commit().await?;
        Ok(n > 0)
    }

    async fn claim_deliveries(&self, limit: i64, lease: Duration) -> Result<Vec<DueDelivery>> {
        let now = Utc::now();
        let until = ts(now + lease_delta(lease));
        let mut tx = self.begin().await?;
        let rows = query(concat!(
            "UPDATE webhook_deliveries
             SET attempts = attempts + 1, next_attempt_at = $1, updated_at = $2
             WHERE id IN (SELECT d.id FROM webhook_deliveries d
                          JOIN webhooks w ON w.id = d.webhook_id AND w.deleted_at IS NULL
                          WHERE d.state = 'pending' AND d.next_attempt_at <= $2
                          ORDER BY d.next_attempt_at, d.id LIMIT $3",
            claim_lock!(),
            ")
             RETURNING id, webhook_id, CAST(payload AS TEXT) AS payload, attempts"
        ))
        .bind(until)
        .bind(ts(now))
        .bind(limit)
        .fetch_all(&mut *tx)
        .await?;
        let mut out = Vec::with_capacity(rows.len());
        for r in &rows {
            let hook = query("SELECT url, secret FROM webhooks WHERE id = $1")
                .bind(r.int("webhook_id")?)
                .fetch_one(&mut *tx)
                .await?;
            out.push(DueDelivery {
                id: r.int("id")?,
                url: hook.text("url")?,
                secret: hook.text("secret")?,
                payload: r.text("payload")?,
                attempts: r.int("attempts")?,
            });
        }
        tx.commit().await?;
        Ok(out)
    }

    async fn finish_delivery(&self, id: i64, attempts: i64, r: &AttemptResult) -> Result<bool> {
        let (state, status, error, next, delivered) = match r {
            AttemptResult::Delivered { status } => ("delivered", Some(*status), None, None, true),
            AttemptResult::Retry {
                status,
                error,
                next_at,
            } => (
                "pending",
                *status,
                Some(error.as_str()),
                Some(ts(*next_at)),
                false,
            ),
            AttemptResult::Failed { status, error } => {
                ("failed", *status, Some(error.as_str()), None, false)
            }
        };
        let mut tx = self.begin().await?;
        let n = query(concat!(
            "UPDATE webhook_deliveries
             SET state = $3, last_status = $4, last_error = $5,
                 next_attempt_at = coalesce($6",
            ts_cast!(),
            ", next_attempt_at), updated_at = ",
            now!(),
            ",
                 delivered_at = CASE WHEN CAST($7 AS BOOLEAN) THEN ",
            now!(),
            " ELSE delivered_at END
             WHERE id = $1 AND attempts = $2 AND state = 'pending'"
        ))
        .bind(id)
        .bind(attempts)
        .bind(state)
        .bind(status)
        .bind(error)
        .bind(next)
        .bind(delivered)
        .execute(&mut *tx)
        .await?
        .rows_affected();
        tx.commit().await?;
        Ok(n > 0)
    }

    async fn list_deliveries(&self, webhook_id: i64, limit: i64) -> Result<Vec<Delivery>> {
        query(concat!(
            "SELECT ",
            delivery_cols!(),
            " FROM webhook_deliveries WHERE webhook_id = $1
             ORDER BY id DESC LIMIT $2"
        ))
        .bind(webhook_id)
        .bind(limit)
        .fetch_all(self.pool())
        .await?
        .iter()
        .map(delivery_from)
        .collect()
    }
}
    };
}

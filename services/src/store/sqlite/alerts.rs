//! sqlite: alerts and the webhook outbox (SQL in the `*_alerts` files).

use super::*;

impl AlertBackend for SqliteStore {
    async fn raise_alert(&self, a: &NewAlert) -> Result<RaiseOutcome> {
        self.a_raise(a).await
    }
    async fn acknowledge_alert(&self, id: i64, actor: &str, note: &str) -> Result<Transition> {
        self.a_acknowledge(id, actor, note).await
    }
    async fn resolve_alert(
        &self,
        target: Target<'_>,
        actor: &str,
        note: &str,
        trace_id: Option<&str>,
    ) -> Result<Transition> {
        self.a_resolve(target, actor, note, trace_id).await
    }
    async fn list_alerts(&self, f: &AlertFilter) -> Result<Vec<Alert>> {
        self.a_list(f).await
    }
    async fn get_alert(&self, id: i64) -> Result<Option<Alert>> {
        self.a_get(id).await
    }
    async fn alert_events(&self, id: i64) -> Result<Vec<AlertEvent>> {
        self.a_events(id).await
    }
    async fn insert_webhook(&self, url: &str, severities: &str, secret: &str) -> Result<Webhook> {
        self.w_insert(url, severities, secret).await
    }
    async fn list_webhooks(&self) -> Result<Vec<Webhook>> {
        self.w_list().await
    }
    async fn delete_webhook(&self, id: i64) -> Result<bool> {
        self.w_delete(id).await
    }
    async fn claim_deliveries(&self, limit: i64, lease: Duration) -> Result<Vec<DueDelivery>> {
        self.w_claim(limit, lease).await
    }
    async fn finish_delivery(&self, id: i64, attempts: i64, r: &AttemptResult) -> Result<bool> {
        self.w_finish(id, attempts, r).await
    }
    async fn list_deliveries(&self, webhook_id: i64, limit: i64) -> Result<Vec<Delivery>> {
        self.w_deliveries(webhook_id, limit).await
    }
}

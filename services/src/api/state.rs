//! What every handler, API and web alike, can reach: the store, the intake, the wake-ups, the
//! settings that shape answers. Below every route module; it imports none of them.

use std::sync::Arc;
use std::time::Duration;

use axum::http::HeaderValue;
use metrics_exporter_prometheus::PrometheusHandle;
use tokio::sync::Notify;

use super::ratelimit::RateLimit;
use super::session::SessionKey;
use super::telemetry;
use crate::alerts::AlertOptions;
use crate::config::Settings;
use crate::ingest::Intake;
use crate::store::Store;

/// What every handler can reach.
#[derive(Clone)]
pub struct AppState {
    pub store: Store,
    pub intake: Intake,
    /// Wakes in-process workers (uploads, re-fits).
    pub wake: Arc<Notify>,
    pub metrics: PrometheusHandle,
    pub body_limit: usize,
    pub timeout: Duration,
    /// Alert rules (horizon, alarm band) for trends and forecasts.
    pub alerts: AlertOptions,
    /// Wakes this process's webhook deliverer after an alert change.
    pub alert_wake: Arc<Notify>,
    /// Signs the web pages' session cookies.
    pub sessions: Arc<SessionKey>,
    /// Requests per key (or per peer IP without a key); `None`: no limit.
    pub rate_limit: Option<RateLimit>,
    /// Origins answered with CORS headers (empty: none).
    pub cors_origins: Vec<HeaderValue>,
    /// The fleet's evidence rows and the last fleet plan, kept until `param_evidence` changes.
    pub plan_cache: crate::plan_index::PlanCache,
}

impl AppState {
    pub fn new(store: Store, wake: Arc<Notify>, body_limit: usize, timeout: Duration) -> Self {
        AppState {
            intake: Intake::new(store.clone(), wake.clone()),
            plan_cache: Default::default(),
            store,
            wake,
            metrics: telemetry::prometheus(),
            body_limit,
            timeout,
            alerts: AlertOptions::default(),
            alert_wake: Arc::new(Notify::new()),
            sessions: Arc::new(SessionKey::random(12)),
            rate_limit: None,
            cors_origins: Vec::new(),
        }
    }

    /// Takes the alert rules, session, rate-limit and CORS settings from `settings`.
    pub fn configure(
        mut self,
        settings: &Settings,
        alert_wake: Arc<Notify>,
    ) -> anyhow::Result<Self> {
        self.alerts = AlertOptions {
            horizon_days: settings.alerts.horizon_days,
            alarm: settings.drift.alarm,
        };
        self.alert_wake = alert_wake;
        let hours = settings.web.session_hours;
        let secret = settings.web.session_secret.expose_secret();
        self.sessions = Arc::new(if secret.is_empty() {
            SessionKey::random(hours)
        } else {
            SessionKey::from_secret(secret, hours)
        });
        self.rate_limit = RateLimit::from_settings(&settings.http);
        self.cors_origins = settings
            .http
            .cors_origins
            .iter()
            .map(|o| {
                HeaderValue::from_str(&o.to_ascii_lowercase())
                    .map_err(|_| anyhow::anyhow!("http.cors_origins: {o:?} is not a header value"))
            })
            .collect::<anyhow::Result<_>>()?;
        Ok(self)
    }
}

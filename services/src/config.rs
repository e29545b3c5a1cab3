//! Service configuration, layered: built-in defaults → a TOML file (`--config`) → environment
//! variables `PANTOWATCH__<SECTION>__<KEY>` (`__` nests) → command-line flags.
//!
//! Environment values are read as TOML values when they parse as one (`4`, `true`,
//! `[0.67, 1.5]`) and as strings otherwise. Unknown keys are errors, so a typo never silently
//! falls back to a default. The database URL is a [`SecretString`]: it is never logged.

use std::fmt;
use std::net::SocketAddr;
use std::path::Path;
use std::time::Duration;

use pantowatch_models::drift::DriftThresholds;
use serde::Deserialize;

/// Prefix of the environment variables read by [`Settings::load`].
pub const ENV_PREFIX: &str = "PANTOWATCH__";

/// A string that is never printed: `Debug` and `Display` show `[redacted]`.
#[derive(Clone, Default, Deserialize, PartialEq, Eq)]
#[serde(transparent)]
pub struct SecretString(String);

impl SecretString {
    pub fn new(s: impl Into<String>) -> Self {
        SecretString(s.into())
    }
    /// The secret itself, for the one place that needs it (connecting).
    pub fn expose_secret(&self) -> &str {
        &self.0
    }
}

impl fmt::Debug for SecretString {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("SecretString([redacted])")
    }
}

impl fmt::Display for SecretString {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("[redacted]")
    }
}

/// Everything `pantowatch serve` / `worker` reads.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct Settings {
    /// Address the HTTP server binds.
    pub listen: SocketAddr,
    /// Fitting workers started with the server (0: the API only).
    pub workers: usize,
    pub database: DatabaseSettings,
    pub worker: WorkerSettings,
    pub http: HttpSettings,
    pub drift: DriftSettings,
    pub log: LogSettings,
    pub alerts: AlertSettings,
    pub webhooks: WebhookSettings,
    pub web: WebSettings,
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct AlertSettings {
    /// A joint whose forecast reaches the alarm band within this many days after its latest
    /// test gets a `watch` alert.
    pub horizon_days: f64,
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct WebhookSettings {
    /// Wait before the second attempt, milliseconds; doubles each attempt (capped at 1 h).
    pub backoff_base_ms: u64,
    /// Attempts before a delivery is failed for good.
    pub max_attempts: u32,
    /// Longest wait for a receiver's answer (connect + response), milliseconds.
    pub timeout_ms: u64,
    /// How often the outbox is looked at, milliseconds (alert changes in-process wake it).
    pub poll_ms: u64,
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct WebSettings {
    /// Key that signs the web pages' session cookies; empty: a random key per process start
    /// (sessions end with the process; several processes behind one address need a shared one).
    pub session_secret: SecretString,
    /// A sign-in lasts this many hours.
    pub session_hours: u64,
}

impl Default for AlertSettings {
    fn default() -> Self {
        AlertSettings { horizon_days: 90.0 }
    }
}

impl Default for WebhookSettings {
    fn default() -> Self {
        WebhookSettings {
            backoff_base_ms: 1000,
            max_attempts: 6,
            timeout_ms: 10_000,
            poll_ms: 1000,
        }
    }
}

impl Default for WebSettings {
    fn default() -> Self {
        WebSettings {
            session_secret: SecretString::default(),
            session_hours: 12,
        }
    }
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct DatabaseSettings {
    /// `postgres://…` for PostgreSQL; otherwise a SQLite file path (created if missing).
    pub url: SecretString,
    /// Longest wait for a database connection, milliseconds; past it (database down, pool
    /// exhausted) a request is answered 503 with `Retry-After` instead of hanging.
    pub acquire_timeout_ms: u64,
    /// Refuse to start unless the PostgreSQL URL asks for TLS (`sslmode=require`, `verify-ca`
    /// or `verify-full`; sqlx honours `sslmode` and `sslrootcert` in the URL). Assumes the
    /// URL is the only place the mode is set: a `PGSSLMODE` variable is not consulted here.
    pub require_tls: bool,
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct WorkerSettings {
    /// How long a claimed job is a worker's before another may take it over, seconds.
    pub lease_secs: u64,
    /// How often an idle worker looks for jobs queued by other processes, milliseconds.
    pub poll_ms: u64,
    /// On shutdown a running fit may finish within this many milliseconds; then it is stopped
    /// and its job released to the queue, its attempt counted (a fit that outlasts every
    /// shutdown fails at the attempt limit instead of looping) and the process stops.
    pub shutdown_grace_ms: u64,
    /// Longest one fit may run, seconds: past it the fit is stopped (`models::budget`, within
    /// ~1 ms), its job fails with that reason and the worker takes the next (issue 18). The worker
    /// renews the job's lease every third of `lease_secs` while it fits, so a fit may outlast
    /// the lease and a dead worker's job is still taken over within one lease.
    pub fit_budget_secs: u64,
    /// Most model evaluations (simulations of the trace, one per Levenberg–Marquardt step,
    /// every stage and residual candidate included) one fit may spend; past it the job fails
    /// with that reason. Default 10,000: ~12× the most a valid trace was measured to need (836,
    /// a slider held and released; lifts 4–123, pendulums 4–239, quadrangle swings 6–7).
    pub fit_max_evaluations: u64,
    /// `pantowatch worker` serves `/metrics` and `/healthz` here (none by default: several
    /// workers may share a host; deploy sets `0.0.0.0:9464`).
    pub metrics_listen: Option<std::net::SocketAddr>,
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct HttpSettings {
    /// Largest accepted request body, MiB.
    pub body_limit_mib: u64,
    /// Longest a request may take before it is answered 503, seconds.
    pub request_timeout_secs: u64,
    /// Sustained requests per second allowed to one API key (or, without a valid key, to one
    /// client IP) in this process; 0 turns the limit off. Replicas count separately.
    pub rate_limit_per_s: f64,
    /// Requests one key (or IP) may send at once before the sustained rate applies.
    pub rate_limit_burst: u32,
    /// Browser origins (`https://host[:port]`) allowed to call the API cross-origin; empty:
    /// no CORS headers at all, so browsers refuse cross-origin reads.
    pub cors_origins: Vec<String>,
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct DriftSettings {
    /// `watch` when the 95 % interval lies wholly outside `[lo, hi]` × baseline.
    pub watch: [f64; 2],
    /// `alarm` when the 95 % interval lies wholly outside `[lo, hi]` × baseline.
    pub alarm: [f64; 2],
}

/// Log line format.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq, Default)]
#[serde(rename_all = "lowercase")]
pub enum LogFormat {
    /// Human-readable lines.
    #[default]
    Text,
    /// One JSON object per line.
    Json,
}

#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct LogSettings {
    pub format: LogFormat,
    /// `tracing` filter directives (`info`, `pantowatch=debug,sqlx=warn`); `RUST_LOG` wins.
    pub filter: String,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            listen: SocketAddr::from(([127, 0, 0, 1], 8080)),
            workers: 2,
            database: DatabaseSettings::default(),
            worker: WorkerSettings::default(),
            http: HttpSettings::default(),
            drift: DriftSettings::default(),
            log: LogSettings::default(),
            alerts: AlertSettings::default(),
            webhooks: WebhookSettings::default(),
            web: WebSettings::default(),
        }
    }
}

impl Default for DatabaseSettings {
    fn default() -> Self {
        DatabaseSettings {
            url: SecretString::new("pantowatch.db"),
            acquire_timeout_ms: 1000,
            require_tls: false,
        }
    }
}

impl Default for WorkerSettings {
    fn default() -> Self {
        WorkerSettings {
            lease_secs: 60,
            poll_ms: 500,
            shutdown_grace_ms: 8_000,
            // A lift fit takes ~0.3 s, a pooled or quadrangle fit a few seconds: 60 s is far
            // beyond any fit that will ever finish well.
            fit_budget_secs: 60,
            fit_max_evaluations: 10_000,
            metrics_listen: None,
        }
    }
}

impl Default for HttpSettings {
    fn default() -> Self {
        HttpSettings {
            body_limit_mib: 64,
            request_timeout_secs: 60,
            rate_limit_per_s: 20.0,
            rate_limit_burst: 100,
            cors_origins: Vec::new(),
        }
    }
}

impl Default for DriftSettings {
    fn default() -> Self {
        let d = DriftThresholds::default();
        DriftSettings {
            watch: d.watch,
            alarm: d.alarm,
        }
    }
}

impl Default for LogSettings {
    fn default() -> Self {
        LogSettings {
            format: LogFormat::Text,
            filter: "info".into(),
        }
    }
}

/// A configuration that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("reading {path}: {source}")]
    Read {
        path: String,
        source: std::io::Error,
    },
    #[error("{origin}: {message}")]
    Invalid { origin: String, message: String },
}

fn invalid(origin: impl Into<String>, message: impl fmt::Display) -> ConfigError {
    ConfigError::Invalid {
        origin: origin.into(),
        message: message.to_string(),
    }
}

/// Deep merge: tables merge key by key, anything else in `over` replaces `base`.
fn merge(base: &mut toml::Table, over: toml::Table) {
    for (k, v) in over {
        match (base.get_mut(&k), v) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge(b, o),
            (_, v) => {
                base.insert(k, v);
            }
        }
    }
}

/// The `PANTOWATCH__…` variables as a TOML table.
fn env_table(vars: impl IntoIterator<Item = (String, String)>) -> Result<toml::Table, ConfigError> {
    let mut root = toml::Table::new();
    for (name, raw) in vars {
        let Some(path) = name.strip_prefix(ENV_PREFIX) else {
            continue;
        };
        let keys: Vec<String> = path.split("__").map(str::to_ascii_lowercase).collect();
        if keys.iter().any(String::is_empty) {
            return Err(invalid(&name, "empty key segment"));
        }
        let value = toml::from_str::<toml::Table>(&format!("v = {raw}"))
            .ok()
            .and_then(|mut t| t.remove("v"))
            .unwrap_or_else(|| toml::Value::String(raw.clone()));
        let mut table = &mut root;
        let (last, parents) = keys.split_last().ok_or_else(|| invalid(&name, "no key"))?;
        for k in parents {
            let entry = table
                .entry(k.clone())
                .or_insert_with(|| toml::Value::Table(toml::Table::new()));
            table = entry
                .as_table_mut()
                .ok_or_else(|| invalid(&name, format!("`{k}` is not a section")))?;
        }
        table.insert(last.clone(), value);
    }
    Ok(root)
}

impl Settings {
    /// Defaults, then `file` if given, then the process environment.
    pub fn load(file: Option<&Path>) -> Result<Settings, ConfigError> {
        Self::load_from(file, std::env::vars())
    }

    /// As [`Settings::load`] with an explicit environment (tests).
    pub fn load_from(
        file: Option<&Path>,
        env: impl IntoIterator<Item = (String, String)>,
    ) -> Result<Settings, ConfigError> {
        let mut table = toml::Table::new();
        let mut origin = "defaults".to_owned();
        if let Some(path) = file {
            let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
                path: path.display().to_string(),
                source,
            })?;
            let file_table: toml::Table =
                toml::from_str(&text).map_err(|e| invalid(path.display().to_string(), e))?;
            merge(&mut table, file_table);
            origin = path.display().to_string();
        }
        let env = env_table(env)?;
        if !env.is_empty() {
            origin = format!("{origin} + {ENV_PREFIX}* environment");
        }
        merge(&mut table, env);
        let settings: Settings = toml::Value::Table(table)
            .try_into()
            .map_err(|e| invalid(&origin, e))?;
        settings.validate().map_err(|m| invalid(origin, m))?;
        Ok(settings)
    }

    /// Checks values that parse but cannot work.
    pub fn validate(&self) -> Result<(), String> {
        self.thresholds().validate()?;
        if self.database.url.expose_secret().trim().is_empty() {
            return Err("database.url is empty".into());
        }
        if self.worker.fit_budget_secs == 0 || self.worker.fit_max_evaluations == 0 {
            return Err("worker.fit_budget_secs and worker.fit_max_evaluations must be > 0".into());
        }
        if self.database.acquire_timeout_ms == 0 {
            return Err("database.acquire_timeout_ms must be > 0".into());
        }
        if self.worker.lease_secs == 0 || self.worker.poll_ms == 0 {
            return Err("worker.lease_secs and worker.poll_ms must be > 0".into());
        }
        if self.http.body_limit_mib == 0 || self.http.request_timeout_secs == 0 {
            return Err("http.body_limit_mib and http.request_timeout_secs must be > 0".into());
        }
        let rate = self.http.rate_limit_per_s;
        if !(rate.is_finite() && (0.0..=MAX_RATE_PER_S).contains(&rate)) {
            return Err(format!(
                "http.rate_limit_per_s must be a number in [0, {MAX_RATE_PER_S}] (0: no limit)"
            ));
        }
        if rate > 0.0 && self.http.rate_limit_burst == 0 {
            return Err("http.rate_limit_burst must be > 0 when http.rate_limit_per_s > 0".into());
        }
        for (i, origin) in self.http.cors_origins.iter().enumerate() {
            check_origin(origin).map_err(|m| format!("http.cors_origins[{i}] {origin:?}: {m}"))?;
        }
        self.check_tls()?;
        if !(self.alerts.horizon_days.is_finite() && self.alerts.horizon_days >= 0.0) {
            return Err("alerts.horizon_days must be a number ≥ 0".into());
        }
        let w = &self.webhooks;
        if w.backoff_base_ms == 0 || w.max_attempts == 0 || w.timeout_ms == 0 || w.poll_ms == 0 {
            return Err(
                "webhooks.backoff_base_ms, max_attempts, timeout_ms and poll_ms must be > 0".into(),
            );
        }
        if self.web.session_hours == 0 {
            return Err("web.session_hours must be > 0".into());
        }
        Ok(())
    }

    /// `database.require_tls`: a PostgreSQL URL whose `sslmode` insists on TLS.
    fn check_tls(&self) -> Result<(), String> {
        if !self.database.require_tls {
            return Ok(());
        }
        let url = self.database.url.expose_secret();
        if backend_name(&self.database.url) != "postgresql" {
            return Err(
                "database.require_tls is true but database.url is not a postgres:// URL".into(),
            );
        }
        match postgres_sslmode(url) {
            Some("require" | "verify-ca" | "verify-full") => Ok(()),
            Some(mode) => Err(format!(
                "database.require_tls is true but database.url has sslmode={mode}; \
                 use sslmode=require, verify-ca or verify-full"
            )),
            None => Err(
                "database.require_tls is true but database.url has no sslmode; \
                 add ?sslmode=verify-full (or require, verify-ca)"
                    .into(),
            ),
        }
    }

    /// The drift bands as the models take them.
    pub fn thresholds(&self) -> DriftThresholds {
        DriftThresholds {
            watch: self.drift.watch,
            alarm: self.drift.alarm,
        }
    }

    /// Body limit in bytes.
    pub fn body_limit_bytes(&self) -> usize {
        usize::try_from(self.http.body_limit_mib.saturating_mul(1 << 20)).unwrap_or(usize::MAX)
    }

    pub fn lease(&self) -> Duration {
        Duration::from_secs(self.worker.lease_secs)
    }

    pub fn poll(&self) -> Duration {
        Duration::from_millis(self.worker.poll_ms)
    }

    /// Longest one fit may run before its job fails.
    pub fn fit_budget(&self) -> Duration {
        Duration::from_secs(self.worker.fit_budget_secs)
    }

    /// How long a shutdown waits for a running fit before releasing its job.
    pub fn shutdown_grace(&self) -> Duration {
        Duration::from_millis(self.worker.shutdown_grace_ms)
    }

    /// The store's pool options.
    pub fn pool_options(&self) -> crate::store::PoolOptions {
        crate::store::PoolOptions {
            acquire_timeout: Duration::from_millis(self.database.acquire_timeout_ms),
        }
    }
}

/// Highest `http.rate_limit_per_s` (the limiter's period is 1 ns at 10⁹/s).
pub const MAX_RATE_PER_S: f64 = 1e6;

/// A CORS origin as browsers send it: `http(s)://host[:port]`, nothing after the authority.
fn check_origin(origin: &str) -> Result<(), String> {
    let rest = origin
        .strip_prefix("https://")
        .or_else(|| origin.strip_prefix("http://"))
        .ok_or("must start with https:// or http:// (a wildcard `*` is not allowed)")?;
    if rest.is_empty() {
        return Err("has no host".into());
    }
    if rest.contains(['/', '?', '#', '*', '@']) || rest.chars().any(|c| c.is_whitespace()) {
        return Err("must be scheme://host[:port] with no path, wildcard or credentials".into());
    }
    if !origin.is_ascii() {
        return Err("must be ASCII (use the punycode form of the host)".into());
    }
    Ok(())
}

/// The last `sslmode` (or `ssl-mode`) parameter of a `postgres://` URL's query, as sqlx reads it.
pub fn postgres_sslmode(url: &str) -> Option<&str> {
    let (_, query) = url.split_once('?')?;
    query
        .split('&')
        .filter_map(|kv| kv.split_once('='))
        .filter(|(k, _)| *k == "sslmode" || *k == "ssl-mode")
        .map(|(_, v)| v)
        .next_back()
}

/// Which backend a database URL selects (what may be logged about it).
pub fn backend_name(url: &SecretString) -> &'static str {
    let u = url.expose_secret();
    if u.starts_with("postgres://") || u.starts_with("postgresql://") {
        "postgresql"
    } else {
        "sqlite"
    }
}

/// Installs the global `tracing` subscriber (stderr; `RUST_LOG` overrides the filter).
pub fn init_logging(log: &LogSettings) {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .or_else(|_| tracing_subscriber::EnvFilter::try_new(&log.filter))
        .unwrap_or_else(|_| "info".into());
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_writer(std::io::stderr);
    // A second call (tests, demo → serve) keeps the first subscriber.
    let _ = match log.format {
        LogFormat::Json => builder.json().try_init(),
        LogFormat::Text => builder.try_init(),
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env(pairs: &[(&str, &str)]) -> Vec<(String, String)> {
        pairs
            .iter()
            .map(|(k, v)| ((*k).to_owned(), (*v).to_owned()))
            .collect()
    }

    #[test]
    fn layers_defaults_file_env() {
        let dir = tempfile::tempdir().expect("dir");
        let file = dir.path().join("pw.toml");
        std::fs::write(
            &file,
            "workers = 3\n[database]\nurl = \"file.db\"\n[drift]\nwatch = [0.7, 1.4]\n",
        )
        .expect("write");
        let s = Settings::load_from(
            Some(&file),
            env(&[
                ("PANTOWATCH__WORKERS", "5"),
                ("PANTOWATCH__DATABASE__URL", "postgres://u:p@h/db"),
                ("PANTOWATCH__LOG__FORMAT", "json"),
                ("PANTOWATCH_EXAMPLES", "ignored"),
            ]),
        )
        .expect("settings");
        assert_eq!(s.workers, 5);
        assert_eq!(s.database.url.expose_secret(), "postgres://u:p@h/db");
        assert_eq!(s.drift.watch, [0.7, 1.4]);
        assert_eq!(s.drift.alarm, [0.5, 2.0]);
        assert_eq!(s.log.format, LogFormat::Json);
        assert_eq!(s.listen, Settings::default().listen);
        assert!(
            !format!("{s:?}").contains("u:p"),
            "the URL is never printed"
        );
        assert_eq!(backend_name(&s.database.url), "postgresql");
    }

    #[test]
    fn the_example_file_is_the_defaults() {
        let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("../deploy/pantowatch.example.toml");
        let s = Settings::load_from(Some(&file), Vec::new()).expect("example config");
        assert_eq!(s, Settings::default());
    }

    #[test]
    fn limits_and_origins_come_from_the_environment() {
        let s = Settings::load_from(
            None,
            env(&[
                ("PANTOWATCH__HTTP__RATE_LIMIT_PER_S", "2.5"),
                ("PANTOWATCH__HTTP__RATE_LIMIT_BURST", "7"),
                (
                    "PANTOWATCH__HTTP__CORS_ORIGINS",
                    r#"["https://depot.example", "http://localhost:5173"]"#,
                ),
            ]),
        )
        .expect("settings");
        assert_eq!(s.http.rate_limit_per_s, 2.5);
        assert_eq!(s.http.rate_limit_burst, 7);
        assert_eq!(
            s.http.cors_origins,
            ["https://depot.example", "http://localhost:5173"]
        );
        // An integer rate is a rate too; 0 switches the limit off.
        let s = Settings::load_from(None, env(&[("PANTOWATCH__HTTP__RATE_LIMIT_PER_S", "0")]))
            .expect("settings");
        assert_eq!(s.http.rate_limit_per_s, 0.0);
        assert!(
            Settings::default().http.cors_origins.is_empty(),
            "no CORS by default"
        );
    }

    #[test]
    fn bad_limits_and_origins_are_refused_by_name() {
        for (var, value, named) in [
            (
                "PANTOWATCH__HTTP__RATE_LIMIT_PER_S",
                "-1",
                "http.rate_limit_per_s",
            ),
            (
                "PANTOWATCH__HTTP__RATE_LIMIT_PER_S",
                "nan",
                "http.rate_limit_per_s",
            ),
            (
                "PANTOWATCH__HTTP__RATE_LIMIT_BURST",
                "0",
                "http.rate_limit_burst",
            ),
            (
                "PANTOWATCH__HTTP__CORS_ORIGINS",
                r#"["*"]"#,
                "http.cors_origins[0]",
            ),
            (
                "PANTOWATCH__HTTP__CORS_ORIGINS",
                r#"["https://ok.example", "https://a.example/path"]"#,
                "http.cors_origins[1]",
            ),
            (
                "PANTOWATCH__HTTP__CORS_ORIGINS",
                r#"["depot.example"]"#,
                "http.cors_origins[0]",
            ),
            (
                "PANTOWATCH__HTTP__CORS_ORIGINS",
                r#"["https://"]"#,
                "http.cors_origins[0]",
            ),
        ] {
            let e = Settings::load_from(None, env(&[(var, value)])).unwrap_err();
            assert!(e.to_string().contains(named), "{var}={value}: {e}");
        }
    }

    #[test]
    fn require_tls_needs_a_tls_sslmode() {
        let with = |url: &str| {
            Settings::load_from(
                None,
                env(&[
                    ("PANTOWATCH__DATABASE__URL", url),
                    ("PANTOWATCH__DATABASE__REQUIRE_TLS", "true"),
                ]),
            )
        };
        for ok in [
            "postgres://u:p@db:5432/pw?sslmode=require",
            "postgresql://u@db/pw?application_name=x&sslmode=verify-full&sslrootcert=/ca.pem",
            "postgres://u@db/pw?ssl-mode=verify-ca",
        ] {
            assert!(with(ok).is_ok(), "{ok}");
        }
        for (bad, says) in [
            ("postgres://u:p@db/pw", "no sslmode"),
            ("postgres://u:p@db/pw?sslmode=prefer", "sslmode=prefer"),
            (
                "postgres://u@db/pw?sslmode=require&sslmode=disable",
                "sslmode=disable",
            ),
            ("pantowatch.db", "not a postgres:// URL"),
        ] {
            let e = with(bad).unwrap_err().to_string();
            assert!(
                e.contains("database.require_tls") && e.contains(says),
                "{bad}: {e}"
            );
            assert!(
                !e.contains("u:p"),
                "the URL's password is not in the error: {e}"
            );
        }
        assert_eq!(
            postgres_sslmode("postgres://h/d?sslmode=require"),
            Some("require")
        );
        assert_eq!(postgres_sslmode("postgres://h/d"), None);
    }

    /// The `PANTOWATCH__*` values of deploy/k8s (ConfigMap + placeholder Secret) and of
    /// deploy/compose.yaml are settings this version accepts (a renamed key fails here).
    #[test]
    fn deploy_manifests_set_only_known_settings() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../deploy");
        let mut vars = Vec::new();
        for file in ["k8s/configmap.yaml", "k8s/secret.yaml", "compose.yaml"] {
            let text = std::fs::read_to_string(root.join(file)).expect("deploy file");
            for line in text.lines() {
                let Some((k, v)) = line.trim().split_once(": ") else {
                    continue;
                };
                if k.starts_with(ENV_PREFIX) {
                    // Compose interpolations stand for a value given at `up` time.
                    let v = v.trim().trim_matches('"');
                    let v = if v.contains("${") { "x" } else { v };
                    vars.push((k.to_owned(), v.to_owned()));
                }
            }
        }
        assert!(vars.len() >= 10, "found {} variables", vars.len());
        let names: Vec<&str> = vars.iter().map(|(k, _)| k.as_str()).collect();
        for must in [
            "PANTOWATCH__DATABASE__URL",
            "PANTOWATCH__HTTP__RATE_LIMIT_PER_S",
        ] {
            assert!(names.contains(&must), "{must} not set in deploy/");
        }
        for (k, v) in &vars {
            // One at a time, so a failure names its variable.
            let mut one = vec![(k.clone(), v.clone())];
            if k == "PANTOWATCH__DATABASE__REQUIRE_TLS" {
                one.push((
                    "PANTOWATCH__DATABASE__URL".into(),
                    "postgres://u@h/d?sslmode=verify-full".into(),
                ));
            }
            if let Err(e) = Settings::load_from(None, one) {
                panic!("deploy/ sets {k}={v}: {e}");
            }
        }
    }

    #[test]
    fn errors_name_the_key() {
        let e = Settings::load_from(None, env(&[("PANTOWATCH__WORKRS", "2")])).unwrap_err();
        assert!(e.to_string().contains("workrs"), "{e}");
        let e = Settings::load_from(None, env(&[("PANTOWATCH__DRIFT__WATCH", "[1.2, 1.5]")]))
            .unwrap_err();
        assert!(e.to_string().contains("drift bands"), "{e}");
        let e = Settings::load_from(None, env(&[("PANTOWATCH__LISTEN", "nowhere")])).unwrap_err();
        assert!(
            e.to_string().contains("listen") || e.to_string().contains("address"),
            "{e}"
        );
    }
}

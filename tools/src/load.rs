//! `pantowatch-tools load`: N concurrent uploaders against a running service, then a read-back
//! check that every accepted trace is stored exactly once with the content sent (counts and
//! SHA-256).
//!
//! The documents are a pure function of `(run id, worker, index)`, so `--verify-only` can
//! regenerate what a run sent and check the server again later (e.g. after a restart).

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Parser;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use pantowatch_models::noise::Noise;
use reqwest::StatusCode;
use serde::Serialize;
use serde_json::Value;
use sha2::{Digest, Sha256};

use pantowatch::cli::serve::runtime;
use pantowatch::cli::simulate::{SimulateArgs, simulate_doc};
use pantowatch::ingest::content_sha256;
use pantowatch::trace::TraceDoc;

/// Longest `--run-id`: the ids built from it (`{run}-w000-000000`) stay well under the
/// contract's 256 characters.
const MAX_RUN_ID: usize = 64;
/// Retry-After values above this are capped (a load run should not sleep for minutes).
const MAX_BACKOFF: Duration = Duration::from_secs(5);
/// Errors kept verbatim in the summary (the rest are only counted).
const KEEP_ERRORS: usize = 10;

#[derive(Debug, Clone, clap::Args)]
pub struct LoadArgs {
    /// Base URL of the service.
    #[arg(long, default_value = "http://127.0.0.1:8080")]
    pub url: String,
    /// API key with the writer role (default: the environment variable PANTOWATCH_KEY).
    #[arg(long)]
    pub key: Option<String>,
    /// Concurrent uploaders.
    #[arg(long, default_value_t = 32)]
    pub concurrency: usize,
    /// Traces each uploader sends, one after the other.
    #[arg(long, default_value_t = 500)]
    pub traces_per_worker: usize,
    /// Prefix of every trace, vehicle and serial id of this run (default: `load-` + random hex).
    /// Re-using a run id re-sends the same documents (idempotent uploads).
    #[arg(long)]
    pub run_id: Option<String>,
    /// Length of each synthetic pendulum trace, s.
    #[arg(long, default_value_t = 2.0)]
    pub duration_s: f64,
    /// Sample rate of each trace, Hz.
    #[arg(long, default_value_t = 200.0)]
    pub fs_hz: f64,
    /// Retries of one request on 429/502/503/504 or a transport error, then it counts as failed.
    #[arg(long, default_value_t = 8)]
    pub max_retries: u32,
    /// Per-request timeout, s.
    #[arg(long, default_value_t = 30)]
    pub timeout_s: u64,
    /// Send nothing: regenerate the run's documents and verify the server holds each exactly
    /// once with the same content (needs `--run-id`).
    #[arg(long)]
    pub verify_only: bool,
    /// Print the summary as JSON on stdout.
    #[arg(long)]
    pub json: bool,
}

/// Latency percentiles of the accepted uploads, ms (nearest rank).
#[derive(Debug, Clone, Default, Serialize, PartialEq)]
pub struct Latency {
    pub p50_ms: f64,
    pub p90_ms: f64,
    pub p99_ms: f64,
    pub max_ms: f64,
}

/// What a run did and what the read-back found.
#[derive(Debug, Clone, Default, Serialize)]
pub struct LoadSummary {
    pub run_id: String,
    pub concurrency: usize,
    pub traces_per_worker: usize,
    /// Distinct documents this run is about (sent, or regenerated with `--verify-only`).
    pub expected: usize,
    /// Uploads answered 202 (with `--verify-only`: every expected document).
    pub accepted: usize,
    /// Uploads not accepted after the retries (or refused outright).
    pub failed: usize,
    /// Requests repeated after 429/502/503/504 or a transport error.
    pub retries: u64,
    /// Upload phase wall time, s (0 with `--verify-only`).
    pub upload_s: f64,
    pub traces_per_s: f64,
    /// Request bodies of the accepted uploads, MB (10⁶ bytes) per second.
    pub mb_per_s: f64,
    pub body_bytes: u64,
    pub latency: Latency,
    /// Traces of this run the server holds (sum over the run's vehicles in `GET /v1/vehicles`).
    pub server_count: i64,
    /// Accepted but not readable back (404).
    pub lost: usize,
    /// Rows beyond one per trace id: the server's count minus the distinct traces found.
    pub duplicated: i64,
    /// Found with other content (content SHA-256, sample count or samples SHA-256 differ).
    pub mismatched: usize,
    /// Found although no upload was acknowledged (a request that timed out after storing).
    pub stored_unacknowledged: usize,
    /// Read-back requests that failed after retries (the trace's state is unknown).
    pub unreadable: usize,
    /// Verify phase wall time, s.
    pub verify_s: f64,
    /// The first few errors, verbatim.
    pub errors: Vec<String>,
    /// True when nothing was lost, duplicated, altered, failed or unreadable.
    pub ok: bool,
}

/// One document of a run and the checksums the server must give back.
#[derive(Debug, Clone)]
pub struct Expected {
    pub trace_id: String,
    pub vehicle_id: String,
    /// The canonical document hash the server reports (`content_sha256`).
    pub content_sha256: String,
    /// SHA-256 of the samples, see [`samples_sha256`].
    pub samples_sha256: String,
    pub sample_count: i64,
}

/// SHA-256 over the channels in name order: each name, a 0 byte, the value count (u64 LE),
/// then every value's IEEE-754 bits (LE), so any changed bit of any sample changes it.
pub fn samples_sha256<'a>(channels: impl IntoIterator<Item = (&'a str, &'a [f64])>) -> String {
    let sorted: BTreeMap<&str, &[f64]> = channels.into_iter().collect();
    let mut h = Sha256::new();
    for (name, values) in sorted {
        h.update(name.as_bytes());
        h.update([0u8]);
        h.update((values.len() as u64).to_le_bytes());
        for v in values {
            h.update(v.to_bits().to_le_bytes());
        }
    }
    hex::encode(h.finalize())
}

/// A run id usable inside trace, vehicle and serial ids.
pub fn check_run_id(run: &str) -> anyhow::Result<()> {
    anyhow::ensure!(
        !run.is_empty()
            && run.len() <= MAX_RUN_ID
            && run
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || "-_.".contains(c)),
        "--run-id: `{}` must be 1-{MAX_RUN_ID} letters, digits, - _ or .",
        run.chars().take(80).collect::<String>()
    );
    Ok(())
}

/// The noise-free pendulum every document of a run perturbs (J1, the paper rig's release).
#[derive(Debug, Clone)]
pub struct BaseTrace {
    t_s: Vec<f64>,
    alpha_deg: Vec<f64>,
}

impl BaseTrace {
    /// Simulates `duration_s` at `fs_hz` (the real simulator, so fitting workers get real work).
    pub fn new(duration_s: f64, fs_hz: f64) -> anyhow::Result<Self> {
        #[derive(Parser)]
        struct Sim {
            #[command(flatten)]
            a: SimulateArgs,
        }
        anyhow::ensure!(
            duration_s.is_finite() && duration_s > 0.0 && duration_s <= 60.0,
            "--duration-s must be in (0, 60]"
        );
        anyhow::ensure!(
            (10.0..=5000.0).contains(&fs_hz),
            "--fs-hz must be in [10, 5000]"
        );
        let (d, f) = (duration_s.to_string(), fs_hz.to_string());
        let a = Sim::try_parse_from([
            "sim",
            "--duration",
            &d,
            "--fs",
            &f,
            "--noise",
            "0",
            "--quantum",
            "0",
        ])?
        .a;
        let doc = simulate_doc(&a).context("simulating the base trace")?;
        let get = |n: &str| doc.channel(n).map(<[f64]>::to_vec).unwrap_or_default();
        Ok(BaseTrace {
            t_s: get("t_s"),
            alpha_deg: get("alpha_deg"),
        })
    }
}

/// 64-bit FNV-1a: a stable seed from the run id and position (same on every machine).
fn seed_of(run: &str, worker: usize, index: usize) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let key = format!("{run}/{worker}/{index}");
    for b in key.bytes() {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h
}

/// Document `index` of uploader `worker`: its JSON body and what the server must give back.
///
/// Ids: trace `{run}-w{worker:03}-{index:06}`, vehicle `{run}-V{worker:03}`, serial
/// `{run}-S{worker:03}`; one recording per hour from 2026-01-01. The samples are the base
/// pendulum plus 0.02° Gaussian sensor noise seeded by the position, so no two documents share
/// content.
pub fn make_doc(
    run: &str,
    worker: usize,
    index: usize,
    base: &BaseTrace,
) -> anyhow::Result<(Vec<u8>, Expected)> {
    const START_UNIX_S: i64 = 1_767_225_600; // 2026-01-01T00:00:00Z
    let mut rng = Noise::new(seed_of(run, worker, index));
    let alpha: Vec<f64> = base
        .alpha_deg
        .iter()
        .map(|a| a + 0.02 * rng.normal())
        .collect();
    let hours = i64::try_from(index).unwrap_or(i64::MAX / 7200);
    let recorded_at = chrono::DateTime::from_timestamp(START_UNIX_S + hours * 3600, 0)
        .context("recorded_at out of range")?
        .to_rfc3339_opts(chrono::SecondsFormat::Secs, true);
    let trace_id = format!("{run}-w{worker:03}-{index:06}");
    let vehicle_id = format!("{run}-V{worker:03}");
    let v = serde_json::json!({
        "format": pantowatch::trace::FORMAT,
        "trace_id": trace_id,
        "vehicle_id": vehicle_id,
        "pantograph": {"model": "160EC", "serial": format!("{run}-S{worker:03}")},
        "recorded_at": recorded_at,
        "test": {"kind": "pendulum", "joint": "J1", "rig": {}},
        "channels": {"t_s": base.t_s, "alpha_deg": alpha},
    });
    // Validated like an upload, so a generator bug shows here and not as a 422 under load.
    let doc = TraceDoc::from_value(&v).map_err(|e| anyhow::anyhow!("generated document: {e}"))?;
    let expected = Expected {
        content_sha256: content_sha256(&doc),
        samples_sha256: samples_sha256(doc.channels.iter().map(|(n, v)| (n.as_str(), &v[..]))),
        sample_count: doc.channels.first().map_or(0, |(_, v)| v.len() as i64),
        trace_id,
        vehicle_id,
    };
    Ok((serde_json::to_vec(&v)?, expected))
}

/// Nearest-rank percentiles of latencies in ms (zeros when empty).
pub fn latency(mut ms: Vec<f64>) -> Latency {
    if ms.is_empty() {
        return Latency::default();
    }
    ms.sort_by(f64::total_cmp);
    let at = |p: f64| {
        let rank = ((p / 100.0) * ms.len() as f64).ceil() as usize;
        ms[rank.clamp(1, ms.len()) - 1]
    };
    Latency {
        p50_ms: at(50.0),
        p90_ms: at(90.0),
        p99_ms: at(99.0),
        max_ms: ms[ms.len() - 1],
    }
}

/// The HTTP side shared by the uploaders and the verifier.
struct Http {
    client: reqwest::Client,
    base: String,
    key: String,
    max_retries: u32,
}

/// How one request ended after its retries.
enum Answer {
    /// A final (non-retryable) status with the body.
    Done(StatusCode, bytes::Bytes, Duration),
    /// Retries exhausted, or a refusal that no retry changes.
    GaveUp(String),
}

fn retryable(s: StatusCode) -> bool {
    matches!(
        s,
        StatusCode::TOO_MANY_REQUESTS
            | StatusCode::BAD_GATEWAY
            | StatusCode::SERVICE_UNAVAILABLE
            | StatusCode::GATEWAY_TIMEOUT
    )
}

impl Http {
    /// Sends a request built by `build`, retrying with exponential backoff (50 ms · 2ⁿ, capped
    /// at 5 s, jittered; `Retry-After` seconds honoured up to the cap). Safe for uploads because
    /// every document carries its `trace_id` (the server is idempotent on it).
    async fn send(
        &self,
        build: impl Fn() -> reqwest::RequestBuilder,
        rng: &mut Noise,
        retries: &mut u64,
    ) -> Answer {
        let mut attempt = 0u32;
        loop {
            let t0 = Instant::now();
            let res = build().bearer_auth(&self.key).send().await;
            let why = match res {
                Ok(r) if !retryable(r.status()) => {
                    let status = r.status();
                    return match r.bytes().await {
                        Ok(b) => Answer::Done(status, b, t0.elapsed()),
                        Err(e) => Answer::GaveUp(format!("reading the answer: {e}")),
                    };
                }
                Ok(r) => {
                    let after = r
                        .headers()
                        .get(reqwest::header::RETRY_AFTER)
                        .and_then(|v| v.to_str().ok())
                        .and_then(|v| v.trim().parse::<u64>().ok())
                        .map(Duration::from_secs);
                    (format!("HTTP {}", r.status()), after)
                }
                Err(e) => (format!("transport: {e}"), None),
            };
            if attempt >= self.max_retries {
                return Answer::GaveUp(format!("{} after {} retries", why.0, attempt));
            }
            attempt += 1;
            *retries += 1;
            let exp = Duration::from_millis(50u64 << attempt.min(7)).min(MAX_BACKOFF);
            let wait = why.1.unwrap_or(exp).min(MAX_BACKOFF);
            tokio::time::sleep(wait.mul_f64(0.5 + rng.uniform())).await;
        }
    }
}

/// What one uploader did.
#[derive(Default)]
struct WorkerOutcome {
    accepted: Vec<Expected>,
    failed: Vec<Expected>,
    latencies_ms: Vec<f64>,
    bytes: u64,
    retries: u64,
    errors: Vec<String>,
}

async fn upload_worker(
    http: Arc<Http>,
    base: Arc<BaseTrace>,
    run: Arc<str>,
    worker: usize,
    n: usize,
    bar: ProgressBar,
) -> anyhow::Result<WorkerOutcome> {
    let mut out = WorkerOutcome::default();
    let mut rng = Noise::new(seed_of(&run, worker, usize::MAX));
    let url = format!("{}/v1/traces", http.base);
    for index in 0..n {
        let (b, r) = (base.clone(), run.clone());
        let (body, exp) = tokio::task::spawn_blocking(move || make_doc(&r, worker, index, &b))
            .await
            .context("document generator task")??;
        let body = bytes::Bytes::from(body);
        let answer = http
            .send(
                || {
                    http.client
                        .post(&url)
                        .header(reqwest::header::CONTENT_TYPE, "application/json")
                        .body(body.clone())
                },
                &mut rng,
                &mut out.retries,
            )
            .await;
        match answer {
            Answer::Done(StatusCode::ACCEPTED, _, took) => {
                out.latencies_ms.push(took.as_secs_f64() * 1e3);
                out.bytes += body.len() as u64;
                out.accepted.push(exp);
            }
            Answer::Done(s, b, _) => {
                if out.errors.len() < KEEP_ERRORS {
                    let text = String::from_utf8_lossy(&b);
                    out.errors.push(format!(
                        "upload {}: HTTP {s}: {}",
                        exp.trace_id,
                        text.chars().take(300).collect::<String>()
                    ));
                }
                out.failed.push(exp);
            }
            Answer::GaveUp(why) => {
                if out.errors.len() < KEEP_ERRORS {
                    out.errors.push(format!("upload {}: {why}", exp.trace_id));
                }
                out.failed.push(exp);
            }
        }
        bar.inc(1);
    }
    Ok(out)
}

/// What reading one trace back found.
enum Found {
    Same,
    Missing,
    Different(String),
    Unreadable(String),
}

async fn read_back(http: &Http, e: &Expected, rng: &mut Noise, retries: &mut u64) -> Found {
    let meta_url = format!("{}/v1/traces/{}", http.base, e.trace_id);
    let meta = match http.send(|| http.client.get(&meta_url), rng, retries).await {
        Answer::Done(StatusCode::NOT_FOUND, _, _) => return Found::Missing,
        Answer::Done(StatusCode::OK, b, _) => b,
        Answer::Done(s, _, _) => return Found::Unreadable(format!("GET {meta_url}: HTTP {s}")),
        Answer::GaveUp(why) => return Found::Unreadable(format!("GET {meta_url}: {why}")),
    };
    let meta: Value = match serde_json::from_slice(&meta) {
        Ok(v) => v,
        Err(err) => return Found::Unreadable(format!("GET {meta_url}: not JSON: {err}")),
    };
    if meta["content_sha256"] != e.content_sha256.as_str() {
        return Found::Different(format!(
            "{}: content_sha256 {} , sent {}",
            e.trace_id, meta["content_sha256"], e.content_sha256
        ));
    }
    if meta["sample_count"] != e.sample_count {
        return Found::Different(format!(
            "{}: sample_count {}, sent {}",
            e.trace_id, meta["sample_count"], e.sample_count
        ));
    }
    let samples_url = format!("{meta_url}/samples");
    let body = match http
        .send(|| http.client.get(&samples_url), rng, retries)
        .await
    {
        Answer::Done(StatusCode::OK, b, _) => b,
        Answer::Done(s, _, _) => {
            return Found::Different(format!("GET {samples_url}: HTTP {s}"));
        }
        Answer::GaveUp(why) => return Found::Unreadable(format!("GET {samples_url}: {why}")),
    };
    // Hashing 16 000 sample sets is CPU work: off the runtime.
    let want = e.samples_sha256.clone();
    let id = e.trace_id.clone();
    let checked = tokio::task::spawn_blocking(move || -> Result<(), String> {
        #[derive(serde::Deserialize)]
        struct Samples {
            channels: BTreeMap<String, Vec<f64>>,
        }
        let s: Samples =
            serde_json::from_slice(&body).map_err(|err| format!("{id}: samples: {err}"))?;
        let got = samples_sha256(s.channels.iter().map(|(n, v)| (n.as_str(), &v[..])));
        if got == want {
            Ok(())
        } else {
            Err(format!("{id}: samples SHA-256 {got}, sent {want}"))
        }
    })
    .await;
    match checked {
        Ok(Ok(())) => Found::Same,
        Ok(Err(why)) => Found::Different(why),
        Err(err) => Found::Unreadable(format!("hash task: {err}")),
    }
}

/// Reads every expected trace back with `concurrency` readers and counts the run's traces per
/// vehicle; fills the read-back half of `summary`.
async fn verify(
    http: Arc<Http>,
    expected: Vec<(Expected, bool)>,
    concurrency: usize,
    run: &str,
    summary: &mut LoadSummary,
) -> anyhow::Result<()> {
    let t0 = Instant::now();
    let bar = progress(expected.len() as u64, "verify");
    let expected = Arc::new(expected);
    let next = Arc::new(std::sync::atomic::AtomicUsize::new(0));
    let mut set = tokio::task::JoinSet::new();
    for w in 0..concurrency.max(1) {
        let (http, expected, next, bar) =
            (http.clone(), expected.clone(), next.clone(), bar.clone());
        let mut rng = Noise::new(seed_of(run, w, usize::MAX - 1));
        set.spawn(async move {
            let mut found = Vec::new();
            let mut retries = 0u64;
            loop {
                let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                let Some((e, acked)) = expected.get(i) else {
                    break;
                };
                let f = read_back(&http, e, &mut rng, &mut retries).await;
                found.push((i, *acked, f));
                bar.inc(1);
            }
            (found, retries)
        });
    }
    let mut found_per_vehicle: BTreeMap<String, i64> = BTreeMap::new();
    while let Some(res) = set.join_next().await {
        let (found, retries) = res.context("verifier task")?;
        summary.retries += retries;
        for (i, acked, f) in found {
            let e = &expected[i].0;
            let mut note = |s: String| {
                if summary.errors.len() < KEEP_ERRORS {
                    summary.errors.push(s);
                }
            };
            match f {
                Found::Same | Found::Different(_) => {
                    *found_per_vehicle.entry(e.vehicle_id.clone()).or_default() += 1;
                    if !acked {
                        summary.stored_unacknowledged += 1;
                    }
                    if let Found::Different(why) = f {
                        summary.mismatched += 1;
                        note(format!("altered: {why}"));
                    }
                }
                Found::Missing if acked => {
                    summary.lost += 1;
                    note(format!(
                        "lost: {} answered 202 but is not stored",
                        e.trace_id
                    ));
                }
                Found::Missing => {}
                Found::Unreadable(why) => {
                    summary.unreadable += 1;
                    note(format!("unreadable: {why}"));
                }
            }
        }
    }
    bar.finish_and_clear();
    // The count the server gives, per vehicle of this run.
    let url = format!("{}/v1/vehicles", http.base);
    let mut rng = Noise::new(seed_of(run, 0, usize::MAX - 2));
    let body = match http
        .send(|| http.client.get(&url), &mut rng, &mut summary.retries)
        .await
    {
        Answer::Done(StatusCode::OK, b, _) => b,
        Answer::Done(s, b, _) => anyhow::bail!(
            "GET {url}: HTTP {s}: {}",
            String::from_utf8_lossy(&b)
                .chars()
                .take(300)
                .collect::<String>()
        ),
        Answer::GaveUp(why) => anyhow::bail!("GET {url}: {why}"),
    };
    let list: Value = serde_json::from_slice(&body).with_context(|| format!("GET {url}"))?;
    let prefix = format!("{run}-V");
    let mut server_count = 0i64;
    let mut duplicated = 0i64;
    let mut seen_vehicles = std::collections::BTreeSet::new();
    for v in list["vehicles"].as_array().into_iter().flatten() {
        let Some(id) = v["vehicle_id"].as_str() else {
            continue;
        };
        if !id.starts_with(&prefix) {
            continue;
        }
        let n = v["traces"].as_i64().unwrap_or(0);
        server_count += n;
        let found = found_per_vehicle.get(id).copied().unwrap_or(0);
        duplicated += (n - found).max(0);
        seen_vehicles.insert(id.to_owned());
    }
    // A vehicle with found traces must be listed (else the listing itself lost rows).
    for (vid, n) in &found_per_vehicle {
        if !seen_vehicles.contains(vid) && summary.errors.len() < KEEP_ERRORS {
            summary
                .errors
                .push(format!("vehicle {vid} with {n} traces is not listed"));
        }
    }
    summary.server_count = server_count;
    summary.duplicated = duplicated;
    summary.verify_s = t0.elapsed().as_secs_f64();
    Ok(())
}

fn progress(n: u64, what: &str) -> ProgressBar {
    let bar = ProgressBar::with_draw_target(Some(n), ProgressDrawTarget::stderr());
    if let Ok(style) = ProgressStyle::with_template(&format!(
        "{what} {{bar:40}} {{pos}}/{{len}} {{per_sec}} eta {{eta}}"
    )) {
        bar.set_style(style);
    }
    bar
}

/// Runs the load (or only the verification) and returns the summary; `ok` says if it passed.
pub async fn run_load(a: &LoadArgs, key: String) -> anyhow::Result<LoadSummary> {
    anyhow::ensure!(
        (1..=1024).contains(&a.concurrency),
        "--concurrency must be 1-1024"
    );
    anyhow::ensure!(
        (1..=1_000_000).contains(&a.traces_per_worker),
        "--traces-per-worker must be 1-1000000"
    );
    let run: Arc<str> = match &a.run_id {
        Some(r) => r.as_str().into(),
        None if a.verify_only => anyhow::bail!("--verify-only needs the --run-id of the run"),
        None => {
            let mut b = [0u8; 4];
            getrandom::fill(&mut b).map_err(|e| anyhow::anyhow!("random run id: {e}"))?;
            format!("load-{}", hex::encode(b)).into()
        }
    };
    check_run_id(&run)?;
    let base_url = a.url.trim_end_matches('/').to_owned();
    let parsed = reqwest::Url::parse(&base_url).with_context(|| format!("--url `{base_url}`"))?;
    let mut builder = reqwest::Client::builder()
        .timeout(Duration::from_secs(a.timeout_s.max(1)))
        .connect_timeout(Duration::from_secs(5))
        .pool_max_idle_per_host(a.concurrency);
    // A proxy from the environment must not sit between a load test and a local server.
    if matches!(
        parsed.host_str(),
        Some("127.0.0.1" | "localhost" | "[::1]" | "::1")
    ) {
        builder = builder.no_proxy();
    }
    let http = Arc::new(Http {
        client: builder.build().context("HTTP client")?,
        base: base_url,
        key,
        max_retries: a.max_retries,
    });
    // Fail fast on a wrong --url rather than retrying every upload against nothing.
    let health = format!("{}/healthz", http.base);
    match http.client.get(&health).send().await {
        Ok(r) if r.status().is_success() => {}
        Ok(r) => anyhow::bail!("--url: GET {health} answered HTTP {}", r.status()),
        Err(e) => anyhow::bail!("--url: cannot reach {health}: {e}"),
    }
    let base = Arc::new(
        tokio::task::spawn_blocking({
            let (d, f) = (a.duration_s, a.fs_hz);
            move || BaseTrace::new(d, f)
        })
        .await
        .context("simulator task")??,
    );
    let mut summary = LoadSummary {
        run_id: run.to_string(),
        concurrency: a.concurrency,
        traces_per_worker: a.traces_per_worker,
        expected: a.concurrency * a.traces_per_worker,
        ..LoadSummary::default()
    };
    let expected: Vec<(Expected, bool)> = if a.verify_only {
        let (n, c, r, b) = (
            a.traces_per_worker,
            a.concurrency,
            run.clone(),
            base.clone(),
        );
        let all = tokio::task::spawn_blocking(move || -> anyhow::Result<Vec<Expected>> {
            let mut v = Vec::with_capacity(n * c);
            for w in 0..c {
                for i in 0..n {
                    v.push(make_doc(&r, w, i, &b)?.1);
                }
            }
            Ok(v)
        })
        .await
        .context("document generator task")??;
        summary.accepted = all.len();
        all.into_iter().map(|e| (e, true)).collect()
    } else {
        let bar = progress(summary.expected as u64, "upload");
        let t0 = Instant::now();
        let mut set = tokio::task::JoinSet::new();
        for w in 0..a.concurrency {
            set.spawn(upload_worker(
                http.clone(),
                base.clone(),
                run.clone(),
                w,
                a.traces_per_worker,
                bar.clone(),
            ));
        }
        let mut all = Vec::with_capacity(summary.expected);
        let mut lat = Vec::with_capacity(summary.expected);
        while let Some(res) = set.join_next().await {
            let o = res.context("uploader task")??;
            summary.accepted += o.accepted.len();
            summary.failed += o.failed.len();
            summary.retries += o.retries;
            summary.body_bytes += o.bytes;
            lat.extend(o.latencies_ms);
            for e in o.errors {
                if summary.errors.len() < KEEP_ERRORS {
                    summary.errors.push(e);
                }
            }
            all.extend(o.accepted.into_iter().map(|e| (e, true)));
            all.extend(o.failed.into_iter().map(|e| (e, false)));
        }
        let secs = t0.elapsed().as_secs_f64();
        bar.finish_and_clear();
        summary.upload_s = secs;
        summary.traces_per_s = summary.accepted as f64 / secs.max(1e-9);
        summary.mb_per_s = summary.body_bytes as f64 / 1e6 / secs.max(1e-9);
        summary.latency = latency(lat);
        all
    };
    verify(http, expected, a.concurrency, &run, &mut summary).await?;
    let found = summary.accepted - summary.lost + summary.stored_unacknowledged;
    summary.ok = summary.failed == 0
        && summary.lost == 0
        && summary.duplicated == 0
        && summary.mismatched == 0
        && summary.unreadable == 0
        && summary.server_count == found as i64
        && summary.errors.is_empty();
    Ok(summary)
}

fn print_human(s: &LoadSummary) {
    println!(
        "run {}: {} uploaders x {} traces = {} documents",
        s.run_id, s.concurrency, s.traces_per_worker, s.expected
    );
    if s.upload_s > 0.0 {
        println!(
            "upload: {} accepted, {} failed, {} retries in {:.1} s: {:.1} traces/s, {:.2} MB/s",
            s.accepted, s.failed, s.retries, s.upload_s, s.traces_per_s, s.mb_per_s
        );
        println!(
            "latency (accepted uploads): p50 {:.1} ms, p90 {:.1} ms, p99 {:.1} ms, max {:.1} ms",
            s.latency.p50_ms, s.latency.p90_ms, s.latency.p99_ms, s.latency.max_ms
        );
    }
    println!(
        "verify ({:.1} s): server holds {}, lost {}, duplicated {}, altered {}, unreadable {}, \
         stored without a 202 {}",
        s.verify_s,
        s.server_count,
        s.lost,
        s.duplicated,
        s.mismatched,
        s.unreadable,
        s.stored_unacknowledged
    );
    for e in &s.errors {
        println!("  {e}");
    }
    println!("{}", if s.ok { "OK" } else { "FAILED" });
}

/// `pantowatch-tools load`: exit status 1 when anything was lost, duplicated, altered or failed.
pub fn run(a: LoadArgs) -> anyhow::Result<()> {
    let key = match a
        .key
        .clone()
        .or_else(|| std::env::var("PANTOWATCH_KEY").ok())
    {
        Some(k) if !k.trim().is_empty() => k.trim().to_owned(),
        _ => {
            anyhow::bail!("--key (or PANTOWATCH_KEY) is required: an API key with the writer role")
        }
    };
    let s = runtime()?.block_on(run_load(&a, key))?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&s)?);
    } else {
        print_human(&s);
    }
    if s.ok {
        Ok(())
    } else {
        anyhow::bail!(
            "load check failed: {} failed, {} lost, {} duplicated, {} altered, {} unreadable",
            s.failed,
            s.lost,
            s.duplicated,
            s.mismatched,
            s.unreadable
        )
    }
}

#[cfg(test)]
mod tests;

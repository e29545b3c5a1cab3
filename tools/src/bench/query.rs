//! Fleet-health query speed: a store filled with `--pantographs` × 12 fits (trace and fit rows
//! written through the Store API, no fitting), then `--queries` fleet-health pages timed through
//! `Store::fleet_health` and through `GET /v1/fleet/health` of the in-process service, on
//! PostgreSQL and on SQLite; p50 and p99 per path.

use std::sync::Arc;
use std::time::{Duration, Instant};

use chrono::{TimeZone, Utc};
use pantowatch_models::report::{FitResult, JointResult, ParamResult, Quantity};
use serde_json::json;
use tokio::sync::Semaphore;
use tokio::task::JoinSet;

use super::harness::{FreshPg, Server};
use super::table::{Row, Sizes, SuiteArgs, quantile};
use pantowatch::store::{FleetFilter, NewFit, NewTrace, Page, Role, Status, Store};

/// Target p99 of one fleet-health page, s.
const P99_TARGET_S: f64 = 0.020;
/// Tests per pantograph: a year of monthly tests.
const FITS_EACH: usize = 12;
/// Joints of each stored fit (a lift's fit result lists them all).
const JOINTS: [&str; 9] = ["J1", "J2", "J3", "J4", "J5", "J6", "J7", "J8", "J9"];

pub fn run(a: &SuiteArgs, sizes: &Sizes) -> Vec<Row> {
    let rt = match pantowatch::cli::serve::runtime() {
        Ok(rt) => rt,
        Err(e) => {
            return vec![Row::failed(
                "query: fleet health",
                "p99 ≤ 20 ms",
                &format!("{e:#}"),
            )];
        }
    };
    rt.block_on(async {
        let mut rows = Vec::new();
        let label = |b: &str| {
            format!(
                "query: fleet health, {b} ({} pantographs, {} fits)",
                sizes.pantographs,
                sizes.pantographs * FITS_EACH
            )
        };
        match FreshPg::create(&a.pg_url).await {
            Ok(db) => {
                let r = backend(&db.url, sizes, 8).await;
                db.drop_now().await;
                rows.push(r.map_or_else(
                    |e| Row::failed(&label("PostgreSQL"), "p99 ≤ 20 ms", &format!("{e:#}")),
                    |m| m.row(label("PostgreSQL")),
                ));
            }
            Err(e) => rows.push(Row::failed(
                &label("PostgreSQL"),
                "p99 ≤ 20 ms",
                &format!("{e:#}"),
            )),
        }
        let sqlite = async {
            let mut b = [0u8; 6];
            getrandom::fill(&mut b).map_err(|e| anyhow::anyhow!("random name: {e}"))?;
            let path = std::env::temp_dir().join(format!("pw_bench_{}.db", hex::encode(b)));
            let url = path
                .to_str()
                .ok_or_else(|| anyhow::anyhow!("non-UTF-8 temp path"))?
                .to_owned();
            let r = backend(&url, sizes, 2).await;
            for suffix in ["", "-wal", "-shm"] {
                let _ = std::fs::remove_file(format!("{url}{suffix}"));
            }
            r
        };
        rows.push(sqlite.await.map_or_else(
            |e| Row::failed(&label("SQLite"), "p99 ≤ 20 ms", &format!("{e:#}")),
            |m| m.row(label("SQLite")),
        ));
        rows
    })
}

/// Timings of one backend, s.
struct Measured {
    fill_s: f64,
    store: Vec<f64>,
    http: Vec<f64>,
}

impl Measured {
    fn row(&self, measure: String) -> Row {
        let q = |v: &[f64], p: f64| quantile(v.to_vec(), p) * 1e3;
        let worst = q(&self.store, 0.99).max(q(&self.http, 0.99));
        Row {
            measure,
            measured: format!(
                "Store p50 {:.1} ms, p99 **{:.1} ms**; HTTP p50 {:.1} ms, p99 **{:.1} ms** ({} queries each)",
                q(&self.store, 0.5),
                q(&self.store, 0.99),
                q(&self.http, 0.5),
                q(&self.http, 0.99),
                self.store.len()
            ),
            target: "p99 ≤ 20 ms".into(),
            pass: Some(worst <= P99_TARGET_S * 1e3),
            value: Some(worst),
            unit: "ms (p99, worse path)".into(),
            detail: json!({"fill_s": self.fill_s,
                "store_ms": {"p50": q(&self.store, 0.5), "p99": q(&self.store, 0.99), "max": q(&self.store, 1.0)},
                "http_ms": {"p50": q(&self.http, 0.5), "p99": q(&self.http, 0.99), "max": q(&self.http, 1.0)}}),
        }
    }
}

/// A fit result of `joints` with statuses drawn from `r` (mostly ok; ~1 in 12 watch, 1 in 40
/// alarm, J6/J9 unknown: what a lift cannot identify).
fn fit_result(trace_id: &str, r: u64) -> FitResult {
    let param = |value: f64, ci95: [f64; 2], status: Status| ParamResult {
        value,
        ci95,
        baseline: Some(value),
        unit: String::new(),
        identifiable: status != Status::Unknown,
        status,
        combination: None,
    };
    let joints = JOINTS
        .iter()
        .enumerate()
        .map(|(k, j)| {
            let x = (r >> (k * 6)) % 120;
            let status = if *j == "J6" || *j == "J9" {
                Status::Unknown
            } else if x < 3 {
                Status::Alarm
            } else if x < 13 {
                Status::Watch
            } else {
                Status::Ok
            };
            JointResult {
                joint: (*j).to_owned(),
                viscous: param(0.03, [0.02, 0.04], status),
                dry: param(0.2, [0.18, 0.22], status),
                identifiable: status != Status::Unknown,
                status,
            }
        })
        .collect();
    FitResult {
        trace_id: trace_id.to_owned(),
        joints,
        rmse: Quantity {
            value: 0.5,
            unit: "mm".into(),
        },
        ..FitResult::default()
    }
}

/// A splitmix64 step: the deterministic statuses of the fill.
pub(super) fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Writes pantograph `p`'s year: 12 traces (50 samples: the query never reads samples) each
/// with its fit, in time order, as an upload and a worker's fit would.
async fn fill_one(store: Store, p: usize) -> anyhow::Result<()> {
    let serial = format!("160EC-{:04}", p + 1);
    let vehicle = format!("EN57-{:04}", p / 2 + 1);
    for m in 0..FITS_EACH {
        let id = format!("{serial}-m{m:02}");
        let t: Vec<f64> = (0..50).map(|i| f64::from(i) * 0.002).collect();
        let h: Vec<f64> = (0..50).map(|i| f64::from(i % 7)).collect();
        let recorded = Utc
            .with_ymd_and_hms(2025, 1 + m as u32, 1 + (p % 27) as u32, 8, 0, 0)
            .single()
            .ok_or_else(|| anyhow::anyhow!("date"))?;
        let mut sha = format!("{:016x}", mix((p * 100 + m) as u64));
        sha = sha.repeat(4);
        store
            .insert_trace(NewTrace {
                trace_id: Some(id.clone()),
                vehicle_id: vehicle.clone(),
                serial: Some(serial.clone()),
                model: "160EC".into(),
                recorded_at: recorded,
                kind: "lift".into(),
                joint: None,
                test_json: r#"{"kind":"lift"}"#.into(),
                content_sha256: sha,
                channels: vec![("t_s".into(), t), ("H_mm".into(), h)],
                model_version: "bench".into(),
            })
            .await?;
        let fit = NewFit::from_result(fit_result(&id, mix((p * 100 + m) as u64 + 7)));
        store.insert_fit(&id, "bench", &fit).await?;
    }
    Ok(())
}

/// The query of round `i`: the first page, alarms only, one vehicle's, or a later page.
fn variant(i: usize, pantographs: usize) -> (FleetFilter, Page, String) {
    let page = Page::default();
    match i % 4 {
        0 => (FleetFilter::default(), page, "/v1/fleet/health".into()),
        1 => (
            FleetFilter {
                status: Some(Status::Alarm),
                vehicle_id: None,
            },
            page,
            "/v1/fleet/health?status=alarm".into(),
        ),
        2 => {
            let v = format!("EN57-{:04}", (i * 37) % pantographs.div_ceil(2) + 1);
            (
                FleetFilter {
                    status: None,
                    vehicle_id: Some(v.clone()),
                },
                page,
                format!("/v1/fleet/health?vehicle={v}"),
            )
        }
        _ => {
            let offset = ((i * 53) % pantographs.max(1)) as u64;
            (
                FleetFilter::default(),
                Page { limit: 50, offset },
                format!("/v1/fleet/health?offset={offset}"),
            )
        }
    }
}

/// Writes pantographs `0..n` with `fill_one`, `writers` at a time, then refreshes the planner's
/// statistics, as autovacuum (PostgreSQL) or `PRAGMA optimize` (SQLite) would give a store that
/// was not written a minute ago. Returns the writing's seconds.
pub(super) async fn fill<F, Fut>(
    store: &Store,
    n: usize,
    writers: usize,
    fill_one: F,
) -> anyhow::Result<f64>
where
    F: Fn(Store, usize) -> Fut,
    Fut: std::future::Future<Output = anyhow::Result<()>> + Send + 'static,
{
    let t0 = Instant::now();
    let sem = Arc::new(Semaphore::new(writers));
    let mut set = JoinSet::new();
    for p in 0..n {
        let permit = sem.clone().acquire_owned().await?;
        let fut = fill_one(store.clone(), p);
        set.spawn(async move {
            let r = fut.await;
            drop(permit);
            r
        });
    }
    while let Some(r) = set.join_next().await {
        r??;
    }
    let fill_s = t0.elapsed().as_secs_f64();
    match store {
        Store::Postgres(s) => {
            sqlx::query("ANALYZE").execute(s.pool()).await?;
        }
        Store::Sqlite(s) => {
            sqlx::query("ANALYZE").execute(s.pool()).await?;
        }
    }
    Ok(fill_s)
}

async fn backend(url: &str, sizes: &Sizes, writers: usize) -> anyhow::Result<Measured> {
    let store = Store::connect(url).await?;
    let n = sizes.pantographs;
    eprintln!(
        "   {:?}: writing {n} pantographs × {FITS_EACH} traces and fits",
        store.kind()
    );
    let fill_s = fill(&store, n, writers, fill_one).await?;
    let check = store
        .fleet_health(&FleetFilter::default(), Page::default())
        .await?;
    anyhow::ensure!(
        check.total == n as u64,
        "fleet health lists {} of {n} pantographs",
        check.total
    );

    eprintln!("   timing {} queries (Store, then HTTP)", sizes.queries);
    // A few warm-up rounds (connections, statement cache) before the clock.
    for i in 0..8 {
        let (f, p, _) = variant(i, n);
        store.fleet_health(&f, p).await?;
    }
    let mut direct = Vec::with_capacity(sizes.queries);
    for i in 0..sizes.queries {
        let (f, p, _) = variant(i, n);
        let t = Instant::now();
        store.fleet_health(&f, p).await?;
        direct.push(t.elapsed().as_secs_f64());
    }
    let server = Server::start(&store, Role::Reader).await?;
    let get = |path: &str| {
        server
            .client
            .get(server.url(path))
            .bearer_auth(&server.key)
            .timeout(Duration::from_secs(10))
            .send()
    };
    for i in 0..8 {
        get(&variant(i, n).2).await?.error_for_status()?;
    }
    let mut http = Vec::with_capacity(sizes.queries);
    for i in 0..sizes.queries {
        let path = variant(i, n).2;
        let t = Instant::now();
        let r = get(&path).await?.error_for_status()?;
        r.bytes().await?;
        http.push(t.elapsed().as_secs_f64());
    }
    server.stop().await?;
    store.close().await;
    Ok(Measured {
        fill_s,
        store: direct,
        http,
    })
}

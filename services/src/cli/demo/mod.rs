//! `pantowatch demo`: a year of a synthetic fleet on a fresh SQLite database — synthesised,
//! uploaded through the same path as `POST /v1/traces`, fitted by the worker pool on every core
//! — then the fleet health table, the worst joints, and the API served on it.

pub mod fleet;

use std::collections::HashMap;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context;
use indicatif::{MultiProgress, ProgressBar, ProgressStyle};
use tokio::sync::{Notify, Semaphore, watch};
use tokio::task::JoinSet;

use super::serve::runtime;
use super::simulate::simulate_doc;
use crate::config::{LogFormat, LogSettings, SecretString, Settings, init_logging};
use crate::ingest::{BodyFormat, Intake};
use crate::server;
use crate::store::{FleetFilter, Page, Role, Status, Store};
use crate::worker::{JobEvent, OnJob, WorkerPool};
use fleet::Param;

#[derive(Debug, clap::Args)]
pub struct DemoArgs {
    /// SQLite file to create (removed first if it exists).
    #[arg(long, default_value = "pantowatch-demo.db")]
    pub database: PathBuf,
    /// Address the API is served on afterwards.
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub listen: SocketAddr,
    /// Stop after printing the tables (tests and CI).
    #[arg(long)]
    pub no_serve: bool,
    /// Vehicles in the fleet (two pantographs each).
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u16).range(1..=1000))]
    pub vehicles: u16,
    /// Fitting workers while the fleet is fitted (default: every core).
    #[arg(long)]
    pub workers: Option<usize>,
}

fn style(template: &str) -> ProgressStyle {
    ProgressStyle::with_template(template).unwrap_or_else(|_| ProgressStyle::default_bar())
}

/// Removes a SQLite database and its WAL files.
fn remove_database(path: &Path) -> anyhow::Result<()> {
    for suffix in ["", "-wal", "-shm", "-journal"] {
        let mut p = path.as_os_str().to_owned();
        p.push(suffix);
        match std::fs::remove_file(&p) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => {
                return Err(e).with_context(|| format!("removing {}", Path::new(&p).display()));
            }
        }
    }
    Ok(())
}

pub fn run(a: DemoArgs) -> anyhow::Result<()> {
    init_logging(&LogSettings {
        format: LogFormat::Text,
        filter: "warn,pantowatch::http=info,pantowatch::server=info".into(),
    });
    runtime()?.block_on(demo(a))
}

async fn demo(a: DemoArgs) -> anyhow::Result<()> {
    let t_all = Instant::now();
    let vehicles = usize::from(a.vehicles);
    let cores = std::thread::available_parallelism().map_or(2, |n| n.get());
    let workers = a.workers.unwrap_or(cores).max(1);
    let plan = fleet::plan(vehicles)?;
    let n = plan.len();
    let truth: HashMap<String, (Param, f64)> = plan
        .iter()
        .filter_map(|t| Some((t.args.trace_id.clone()?, t.true_factor?)))
        .collect();
    remove_database(&a.database)?;
    let db = a
        .database
        .to_str()
        .context("the database path is not UTF-8")?
        .to_owned();
    let store = Store::connect(&db)
        .await
        .with_context(|| format!("creating {db}"))?;
    println!(
        "pantowatch demo: {vehicles} vehicles × 2 pantographs × {} months (monthly lift, quarterly workshop, force gauge twice on every fourth pantograph) = {n} tests, \
         database {db}, {workers} fitting workers",
        fleet::MONTHS
    );

    // Fitting runs while the fleet is uploaded: the workers wake on each upload.
    let bars = MultiProgress::new();
    let up_bar = bars.add(ProgressBar::new(n as u64));
    up_bar.set_style(style(
        "{prefix:>9} [{bar:40}] {pos}/{len} {per_sec:>10} {elapsed}",
    ));
    up_bar.set_prefix("upload");
    let fit_bar = bars.add(ProgressBar::new(n as u64));
    fit_bar.set_style(style(
        "{prefix:>9} [{bar:40}] {pos}/{len} {per_sec:>10} {elapsed} {msg}",
    ));
    fit_bar.set_prefix("fit");
    let failed = Arc::new(AtomicUsize::new(0));
    let on_job: OnJob = {
        let (bar, failed) = (fit_bar.clone(), failed.clone());
        Arc::new(move |ev: &JobEvent| {
            match ev {
                JobEvent::Failed { .. } => {
                    failed.fetch_add(1, Ordering::Relaxed);
                    bar.set_message(format!("{} failed", failed.load(Ordering::Relaxed)));
                }
                JobEvent::LeaseLost { .. } | JobEvent::Released { .. } => return,
                JobEvent::Done { .. } => {}
            }
            bar.inc(1);
        })
    };
    let settings = Settings {
        listen: a.listen,
        workers: 2,
        database: crate::config::DatabaseSettings {
            url: SecretString::new(db.clone()),
            ..Default::default()
        },
        ..Settings::default()
    };
    let mut pool_opts = server::worker_options(&settings, workers);
    pool_opts.poll = Duration::from_millis(100);
    let wake = Arc::new(Notify::new());
    let (stop_tx, stop_rx) = watch::channel(false);
    let pool = WorkerPool::spawn(
        store.clone(),
        pool_opts,
        wake.clone(),
        stop_rx,
        Some(on_job),
    );

    let t_fit = Instant::now();
    let intake = Intake::new(store.clone(), wake);
    let permits = Arc::new(Semaphore::new(2 * workers));
    let mut uploads = JoinSet::new();
    for test in plan {
        let permit = permits.clone().acquire_owned().await?;
        let (intake, bar) = (intake.clone(), up_bar.clone());
        uploads.spawn(async move {
            let body = tokio::task::spawn_blocking(move || -> anyhow::Result<Vec<u8>> {
                let doc = simulate_doc(&test.args)?;
                Ok(serde_json::to_vec(&doc.to_value())?)
            })
            .await??;
            // The upload path of POST /v1/traces: parse, validate, store, queue the fit.
            intake.upload(BodyFormat::Json, body.into()).await?;
            drop(permit);
            bar.inc(1);
            anyhow::Ok(())
        });
        while let Some(r) = uploads.try_join_next() {
            r??;
        }
    }
    while let Some(r) = uploads.join_next().await {
        r??;
    }
    up_bar.finish();
    let t_upload = t_fit.elapsed();
    crate::worker::wait_until_drained(&store, Duration::from_millis(50)).await?;
    let _ = stop_tx.send(true);
    pool.join().await;
    fit_bar.finish();
    let t_fitted = t_fit.elapsed();
    let counts = store.counts().await?;
    println!(
        "uploaded {} traces in {:.1} s; {} fits written, {} failed, all done {:.1} s after the first \
         upload ({:.0} traces/s synthesised, stored and fitted)",
        counts.traces,
        t_upload.as_secs_f64(),
        counts.fits,
        failed.load(Ordering::Relaxed),
        t_fitted.as_secs_f64(),
        counts.traces as f64 / t_fitted.as_secs_f64()
    );

    print_fleet(&store, vehicles).await?;
    print_worst(&store, &truth).await?;
    println!("demo prepared in {:.1} s", t_all.elapsed().as_secs_f64());

    if a.no_serve {
        store.close().await;
        return Ok(());
    }
    let (_, reader) = store.create_api_key(Role::Reader, "demo reader").await?;
    let (_, writer) = store.create_api_key(Role::Writer, "demo writer").await?;
    let listener = tokio::net::TcpListener::bind(a.listen)
        .await
        .with_context(|| format!("binding {} (choose another with --listen)", a.listen))?;
    let url = format!("http://{}", listener.local_addr()?);
    println!();
    println!("Serving the API on {url}   (OpenAPI document: {url}/openapi.json)");
    println!("  reader key: {reader}");
    println!("  writer key: {writer}   (uploads)");
    println!(
        "  try: curl -H \"Authorization: Bearer {reader}\" '{url}/v1/fleet/health?status=alarm'"
    );
    crate::web::print_banner(&store, &url).await?;
    println!("Ctrl-C stops it.");
    let res = server::run(
        listener,
        store.clone(),
        &settings,
        server::shutdown_signal(),
    )
    .await;
    store.close().await;
    res
}

fn status_str(s: Option<Status>) -> &'static str {
    s.map_or("—", Status::as_str)
}

/// One pantograph's joints as fleet health and the alerts see them (`Store::joint_states`:
/// each parameter from the latest test that informed it), each with the history point of the
/// test that decides it.
async fn latest_informed(
    store: &Store,
    serial: &str,
) -> anyhow::Result<Vec<(String, crate::store::JointPoint)>> {
    let mut out = Vec::new();
    for s in store.joint_states(serial).await? {
        let history = store.joint_history(serial, &s.joint).await?;
        if let Some(mut p) = history.into_iter().find(|p| p.trace_id == s.trace_id) {
            p.fit.status = s.status;
            out.push((s.joint, p));
        }
    }
    Ok(out)
}

async fn print_fleet(store: &Store, vehicles: usize) -> anyhow::Result<()> {
    let page = store
        .fleet_health(
            &FleetFilter::default(),
            Page {
                limit: 10_000,
                offset: 0,
            },
        )
        .await?;
    let mut by: HashMap<&'static str, usize> = HashMap::new();
    let mut rows = Vec::new();
    for r in &page.rows {
        let joints = latest_informed(store, &r.serial).await?;
        let worst = joints.iter().map(|(_, p)| p.fit.status).max();
        *by.entry(status_str(worst)).or_default() += 1;
        let flagged: Vec<String> = joints
            .iter()
            .filter(|(_, p)| matches!(p.fit.status, Status::Watch | Status::Alarm))
            .map(|(j, p)| format!("{j} {}", p.fit.status))
            .collect();
        rows.push((r, worst, flagged));
    }
    rows.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.serial.cmp(&b.0.serial)));
    let n = |s: &str| by.get(s).copied().unwrap_or(0);
    println!();
    println!(
        "Fleet health: {} pantographs on {vehicles} vehicles — {} alarm, {} watch, {} ok, {} unknown \
         (each joint at its latest informed fit)",
        page.total,
        n("alarm"),
        n("watch"),
        n("ok"),
        n("unknown")
    );
    println!(
        "{:<11} {:<10} {:<8} {:<34} last test",
        "serial", "vehicle", "worst", "joints not ok"
    );
    let mut hidden = 0;
    for (r, worst, flagged) in &rows {
        if flagged.is_empty() {
            hidden += 1;
            continue;
        }
        println!(
            "{:<11} {:<10} {:<8} {:<34} {}",
            r.serial,
            r.vehicle_id.as_deref().unwrap_or("—"),
            status_str(*worst),
            flagged.join(", "),
            r.last_test
                .map_or("—".into(), |t| t.format("%Y-%m-%d").to_string())
        );
    }
    if hidden > 0 {
        println!("({hidden} pantographs with every informed joint ok are not listed)");
    }
    Ok(())
}

async fn print_worst(store: &Store, truth: &HashMap<String, (Param, f64)>) -> anyhow::Result<()> {
    let page = store
        .fleet_health(
            &FleetFilter::default(),
            Page {
                limit: 10_000,
                offset: 0,
            },
        )
        .await?;
    struct Row {
        serial: String,
        joint: String,
        status: Status,
        param: Param,
        value: f64,
        ci: (f64, f64),
        factor: f64,
        first: f64,
        tests: usize,
        truth: Option<f64>,
    }
    let mut rows = Vec::new();
    for r in &page.rows {
        for (joint, latest) in latest_informed(store, &r.serial)
            .await?
            .into_iter()
            .filter(|(_, p)| matches!(p.fit.status, Status::Watch | Status::Alarm))
        {
            let history: Vec<_> = store
                .joint_history(&r.serial, &joint)
                .await?
                .into_iter()
                .filter(|p| p.fit.identifiable)
                .collect();
            let (Some(first), last) = (history.first(), &latest) else {
                continue;
            };
            let Ok((bv, bd)) = fleet::baseline(&joint) else {
                continue;
            };
            let pick = |p: &crate::store::JointFit| {
                let v = p.viscous.unwrap_or(f64::NAN) / bv;
                let d = p.dry.unwrap_or(f64::NAN) / bd;
                if v.ln().abs() >= d.ln().abs() || d.is_nan() {
                    (Param::Viscous, v)
                } else {
                    (Param::Dry, d)
                }
            };
            // A lift's J8 viscous is per slide (Table 4 0.99 N·s/m), the slider test's is J8 and
            // J9 together (3.99): only dry friction compares across the two; a lift informs only
            // J8's dry friction anyway.
            let (param, factor) = if joint == "J8" && last.trace_id.ends_with("-lift") {
                (Param::Dry, last.fit.dry.unwrap_or(f64::NAN) / bd)
            } else {
                pick(&last.fit)
            };
            let (value, lo, hi) = match param {
                Param::Viscous => (last.fit.viscous, last.fit.viscous_lo, last.fit.viscous_hi),
                Param::Dry => (last.fit.dry, last.fit.dry_lo, last.fit.dry_hi),
            };
            let first_factor = match param {
                Param::Viscous => first.fit.viscous.unwrap_or(f64::NAN) / bv,
                Param::Dry => first.fit.dry.unwrap_or(f64::NAN) / bd,
            };
            rows.push(Row {
                serial: r.serial.clone(),
                joint: joint.clone(),
                status: latest.fit.status,
                param,
                value: value.unwrap_or(f64::NAN),
                ci: (lo.unwrap_or(f64::NAN), hi.unwrap_or(f64::NAN)),
                factor,
                first: first_factor,
                tests: history.len(),
                truth: truth
                    .get(&last.trace_id)
                    .filter(|(p, _)| *p == param)
                    .map(|(_, f)| *f),
            });
        }
    }
    rows.sort_by(|a, b| {
        b.status
            .cmp(&a.status)
            .then(b.factor.ln().abs().total_cmp(&a.factor.ln().abs()))
    });
    println!();
    println!(
        "Worst joints (latest fit against Table 4; \"true ×\" is what the synthetic fleet was given)"
    );
    println!(
        "{:<11} {:<5} {:<6} {:<8} {:>9} {:>21} {:>7} {:>7} {:>6}  trend over the year",
        "serial",
        "joint",
        "status",
        "param",
        "fitted",
        "95 % interval",
        "× base",
        "true ×",
        "tests"
    );
    for r in rows.iter().take(12) {
        println!(
            "{:<11} {:<5} {:<6} {:<8} {:>9.4} {:>21} {:>7.2} {:>7} {:>6}  ×{:.2} → ×{:.2}",
            r.serial,
            r.joint,
            r.status,
            r.param.as_str(),
            r.value,
            format!("[{:.4}, {:.4}]", r.ci.0, r.ci.1),
            r.factor,
            r.truth.map_or("—".into(), |t| format!("{t:.2}")),
            r.tests,
            r.first,
            r.factor
        );
    }
    if rows.len() > 12 {
        println!("({} more joints at watch or alarm)", rows.len() - 12);
    }
    Ok(())
}

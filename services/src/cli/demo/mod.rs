//! `pantowatch demo`: a year of a synthetic fleet on a fresh SQLite database — synthesised,
//! uploaded through the same path as `POST /v1/traces`, fitted by the worker pool on every core
//! — with the fleet health table and the worst joints printed when every fit is done.
//!
//! Served (the default), the API and the web pages answer at once: the database is migrated,
//! the service started on it and its URL and keys printed before the first trace is
//! synthesised; the fleet is then uploaded in the background and fitted by the service's own
//! workers, so the pages fill in as the fits complete (the fleet page shows how many are done,
//! the terminal a bar). `--no-serve` fits the fleet with a worker pool of its own, prints the
//! tables and exits.

pub mod fleet;
mod progress;

use std::collections::HashMap;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::Context;
use indicatif::MultiProgress;
use tokio::sync::{Notify, Semaphore, watch};
use tokio::task::JoinSet;

use super::serve::{ABANDONED_FIT_WAIT, runtime};
use super::simulate::simulate_doc;
use crate::config::{SecretString, Settings};
use crate::ingest::{BodyFormat, Intake};
use crate::server;
use crate::store::{FleetFilter, Page, Role, Status, Store};
use crate::worker::WorkerPool;
use fleet::{Param, PlannedTest};
use progress::Progress;

#[derive(Debug, clap::Args)]
pub struct DemoArgs {
    /// SQLite file to create (removed first if it exists).
    #[arg(long, default_value = "pantowatch-demo.db")]
    pub database: PathBuf,
    /// Address the API and the web pages are served on, from the start.
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub listen: SocketAddr,
    /// Fit the fleet, print the tables and stop, serving nothing (tests and CI).
    #[arg(long)]
    pub no_serve: bool,
    /// Vehicles in the fleet (two pantographs each).
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u16).range(1..=1000))]
    pub vehicles: u16,
    /// Months of tests, from the first of the year (a shorter look at the same fleet).
    #[arg(long, default_value_t = 12, value_parser = clap::value_parser!(u8).range(1..=12))]
    pub months: u8,
    /// Fitting workers while the fleet is fitted (default: every core).
    #[arg(long)]
    pub workers: Option<usize>,
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
    let bars = MultiProgress::new();
    progress::init_logging_above(&bars, "warn,pantowatch::http=info,pantowatch::server=info");
    let rt = runtime()?;
    let res = rt.block_on(demo(a, bars));
    // A fit abandoned after the shutdown grace (its job released) must not hold the exit.
    rt.shutdown_timeout(ABANDONED_FIT_WAIT);
    res
}

/// The fleet to fit and what it was given, on its fresh store.
struct Fleet {
    store: Store,
    plan: Vec<PlannedTest>,
    /// Months of tests (the year: 12).
    plan_months: usize,
    /// A worn joint's true factor by trace id.
    truth: HashMap<String, (Param, f64)>,
    vehicles: usize,
    workers: usize,
    /// The demo's service settings: its database, `workers` fitting workers.
    settings: Settings,
}

async fn demo(a: DemoArgs, bars: MultiProgress) -> anyhow::Result<()> {
    let t_all = Instant::now();
    let vehicles = usize::from(a.vehicles);
    let months = usize::from(a.months);
    let cores = std::thread::available_parallelism().map_or(2, |n| n.get());
    let workers = a.workers.unwrap_or(cores).max(1);
    let plan = fleet::plan_months(vehicles, months)?;
    let n = plan.len();
    let truth = plan
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
        "pantowatch demo: {vehicles} vehicles × 2 pantographs × {months} months (monthly lift; quarterly workshop: J1, J2, J6, J7 every time, one of J3, J4, J5, J8 in turn; force gauge twice on every fourth pantograph) = {n} tests, \
         database {db}, {workers} fitting workers"
    );
    let settings = Settings {
        listen: a.listen,
        workers,
        database: crate::config::DatabaseSettings {
            url: SecretString::new(db),
            ..Default::default()
        },
        ..Settings::default()
    };
    let f = Fleet {
        store: store.clone(),
        plan_months: months,
        plan,
        truth,
        vehicles,
        workers,
        settings,
    };
    let res = if a.no_serve {
        fit_then_exit(f, &bars, t_all).await
    } else {
        serve_while_fitting(f, &bars, t_all).await
    };
    store.close().await;
    res
}

/// `--no-serve`: the fleet fitted by a worker pool of the demo's own, the tables, the end.
async fn fit_then_exit(f: Fleet, bars: &MultiProgress, t_all: Instant) -> anyhow::Result<()> {
    let progress = Progress::new(bars, f.plan.len());
    let mut pool_opts = server::worker_options(&f.settings, f.workers);
    pool_opts.poll = Duration::from_millis(100);
    let wake = Arc::new(Notify::new());
    let (stop_tx, stop_rx) = watch::channel(false);
    let pool = WorkerPool::spawn(
        f.store.clone(),
        pool_opts,
        wake.clone(),
        stop_rx,
        Some(progress.on_job()),
    );
    let intake = Intake::new(f.store.clone(), wake);
    let filled = fill(&f, &intake, &progress).await;
    let _ = stop_tx.send(true);
    pool.join().await;
    report(&f, &progress, filled?).await?;
    println!("demo prepared in {:.1} s", t_all.elapsed().as_secs_f64());
    Ok(())
}

/// Served: the service started on the fresh store first (its URL and keys printed), then the
/// fleet uploaded in the background and fitted by the service's workers; the tables when every
/// fit is done; serving until Ctrl-C or SIGTERM.
async fn serve_while_fitting(f: Fleet, bars: &MultiProgress, t_all: Instant) -> anyhow::Result<()> {
    let store = &f.store;
    let (_, reader) = store.create_api_key(Role::Reader, "demo reader").await?;
    let (_, writer) = store.create_api_key(Role::Writer, "demo writer").await?;
    let listen = f.settings.listen;
    let listener = tokio::net::TcpListener::bind(listen)
        .await
        .with_context(|| format!("binding {listen} (choose another with --listen)"))?;
    let url = format!("http://{}", listener.local_addr()?);

    let (stop_tx, stop_rx) = watch::channel(false);
    let stop_tx = Arc::new(stop_tx);
    tokio::spawn({
        let stop_tx = stop_tx.clone();
        async move {
            server::shutdown_signal().await;
            let _ = stop_tx.send(true);
        }
    });
    let progress = Progress::new(bars, f.plan.len());
    let wake = Arc::new(Notify::new());
    let hooks = server::Hooks {
        wake: Some(wake.clone()),
        on_job: Some(progress.on_job()),
    };
    let mut server = tokio::spawn({
        let (store, settings, mut stop) = (store.clone(), f.settings.clone(), stop_rx.clone());
        let stopped = async move {
            let _ = stop.wait_for(|s| *s).await;
        };
        async move { server::run_with(listener, store, &settings, stopped, hooks).await }
    });
    bars.suspend(|| {
        println!(
            "Serving the API on {url}   (OpenAPI document: {url}/openapi.json), {:.1} s after the start",
            t_all.elapsed().as_secs_f64()
        );
        println!("  reader key: {reader}");
        println!("  writer key: {writer}   (uploads)");
        println!(
            "  try: curl -H \"Authorization: Bearer {reader}\" '{url}/v1/fleet/health?status=alarm'"
        );
        println!(
            "Web pages: {url}/  (sign in with the reader or writer key; the fleet page fills in as \
             the fits complete)"
        );
        println!(
            "Fitting the fleet in the background; the tables follow when every fit is done. \
             Ctrl-C stops it."
        );
    });

    let intake = Intake::new(store.clone(), wake);
    let mut stopped = stop_rx.clone();
    let fitted = tokio::select! {
        r = async {
            let filled = fill(&f, &intake, &progress).await?;
            report(&f, &progress, filled).await
        } => Some(r),
        // Ctrl-C while the fleet is fitted: the service stops (fits in flight finish or are
        // released), the rest of the fleet is not uploaded.
        _ = stopped.wait_for(|s| *s) => None,
        // The service ended by itself (it could not start): its error.
        r = &mut server => {
            progress.upload.abandon();
            progress.fit.abandon();
            return r.context("the service task")?;
        }
    };
    match fitted {
        Some(Ok(())) => {
            crate::web::print_banner(store, &url).await?;
            println!(
                "demo prepared in {:.1} s; still serving on {url} — Ctrl-C stops it.",
                t_all.elapsed().as_secs_f64()
            );
        }
        Some(Err(e)) => {
            let _ = stop_tx.send(true);
            let _ = server.await;
            return Err(e);
        }
        None => {
            progress.upload.abandon();
            progress.fit.abandon();
        }
    }
    server.await.context("the service task")?
}

/// What [`fill`] took, and the story's test plan and its follow-up.
struct Filled {
    upload: Duration,
    fitted: Duration,
    story: Story,
}

/// Issue 37, point 4: the fleet plan at the year's end, the workshop swings it asks for, and
/// what they found.
struct Story {
    at: chrono::DateTime<chrono::Utc>,
    plan: crate::evidence::FleetPlan,
    /// Per swing done: serial, joint, its status before (the worst of its parameters' last
    /// informing tests), the true wear then, the swing's trace and the joint's status in it.
    found: Vec<Found>,
}

/// One follow-up swing: serial, joint, its status before (the worst of its parameters' last
/// informing tests), the true wear then, the swing's trace and the joint's status in it.
type Found = (
    String,
    String,
    Status,
    Option<(Param, f64)>,
    String,
    Option<Status>,
);

/// Swings the plan picks from the top of the fleet plan.
const STORY_SWINGS: usize = 6;

/// The fleet plan [`fleet::STORY_MONTHS_AFTER`] months after the year, then the top [`STORY_SWINGS`] swings it
/// asks for, uploaded and fitted like every test (the plan read from `param_evidence`, as
/// `GET /v1/fleet/plan?at=` reads it).
async fn plan_and_follow_up(f: &Fleet, intake: &Intake) -> anyhow::Result<Story> {
    use chrono::TimeZone;
    // Three months after the year, before the next workshop cycle: the joints drifting where
    // the monthly lifts cannot see have had time to cross unseen.
    let months = f.plan_months + fleet::STORY_MONTHS_AFTER;
    let (y, mo) = fleet::month_start(months);
    let at = chrono::Utc
        .with_ymd_and_hms(y, mo, 1, 0, 0, 0)
        .single()
        .context("the plan's date")?;
    let rows = f.store.param_evidence(None).await?;
    let plan = crate::evidence::fleet_plan(&rows, at, 10);
    let picks: Vec<(String, String)> = plan
        .tests
        .iter()
        .filter_map(|e| Some((e.serial.clone(), e.test.joint.clone()?)))
        .take(STORY_SWINGS)
        .collect();
    let before: Vec<Status> = {
        let mut v = Vec::new();
        for (serial, joint) in &picks {
            let st = f.store.joint_states(serial).await?;
            v.push(
                st.iter()
                    .find(|s| &s.joint == joint)
                    .map_or(Status::Unknown, |s| s.status),
            );
        }
        v
    };
    let tests = fleet::follow_up(f.vehicles, months, &picks)?;
    for t in &tests {
        let doc = simulate_doc(&t.args)?;
        intake
            .upload(
                BodyFormat::Json,
                serde_json::to_vec(&doc.to_value())?.into(),
            )
            .await?;
    }
    crate::worker::wait_until_drained(&f.store, Duration::from_millis(50)).await?;
    let mut found = Vec::new();
    for ((t, (serial, joint)), was) in tests.iter().zip(&picks).zip(before) {
        let id = t.args.trace_id.clone().unwrap_or_default();
        let now = match f.store.get_fit(&id).await? {
            Some(fit) => fit
                .result()?
                .joints
                .iter()
                .find(|j| &j.joint == joint)
                .map(|j| j.status),
            None => None,
        };
        found.push((serial.clone(), joint.clone(), was, t.true_factor, id, now));
    }
    Ok(Story { at, plan, found })
}

/// Prints the story: the plan, then what each swing found against the truth.
fn print_story(s: &Story) {
    let at = s.at.format("%Y-%m-%d");
    println!();
    println!(
        "Test plan at {at} (GET /v1/fleet/plan?at={}): each pantograph's workshop test that buys \
         most — the chance it finds a crossing the joint's last test did not show, times the \
         uncertainty it removes",
        s.at.to_rfc3339_opts(chrono::SecondsFormat::Secs, true)
    );
    println!(
        "{:<3} {:<11} {:<16} {:>8} {:>7} {:>10}  due",
        "#", "serial", "test", "P unseen", "buys", "oldest"
    );
    for (i, e) in s.plan.tests.iter().enumerate() {
        let test = match e.test.joint.as_deref() {
            Some(j) => format!("swing {j}"),
            None => e.test.kind.clone(),
        };
        println!(
            "{:<3} {:<11} {:<16} {:>8.2} {:>7.3} {:>8} d  {}",
            i + 1,
            e.serial,
            test,
            e.test.p_unseen,
            e.test.buys,
            e.oldest_evidence_days
                .map_or("—".into(), |d| format!("{d:.0}")),
            if e.tests_due.is_empty() {
                "—".into()
            } else {
                e.tests_due.join(", ")
            }
        );
    }
    println!();
    println!(
        "The workshop swings the top {} of them on {at}; what they found:",
        s.found.len()
    );
    println!(
        "{:<11} {:<6} {:<8} {:<22} {:<9} trace",
        "serial", "joint", "before", "truth", "swing"
    );
    for (serial, joint, was, truth, id, now) in &s.found {
        let truth = match truth {
            Some((p, f)) => format!("{} ×{f:.2}", p.as_str()),
            None => "at baseline".into(),
        };
        let verdict = match now {
            Some(n) if *n > *was && *n >= Status::Watch => " (crossed unseen: confirmed)",
            Some(_) => "",
            None => " (not fitted)",
        };
        println!(
            "{:<11} {:<6} {:<8} {:<22} {:<9} {id}{verdict}",
            serial,
            joint,
            was.as_str(),
            truth,
            status_str(*now)
        );
    }
}

/// Synthesises the fleet's tests and uploads each through `intake` (the upload path of
/// `POST /v1/traces`: parse, validate, store, queue the fit — the workers wake on each), a few
/// at a time; then waits until no job is queued or running.
async fn fill(f: &Fleet, intake: &Intake, progress: &Progress) -> anyhow::Result<Filled> {
    let t0 = Instant::now();
    let permits = Arc::new(Semaphore::new(2 * f.workers));
    let mut uploads = JoinSet::new();
    for test in f.plan.iter().cloned() {
        let permit = permits.clone().acquire_owned().await?;
        let (intake, bar) = (intake.clone(), progress.upload.clone());
        uploads.spawn(async move {
            let body = tokio::task::spawn_blocking(move || -> anyhow::Result<Vec<u8>> {
                let doc = simulate_doc(&test.args)?;
                Ok(serde_json::to_vec(&doc.to_value())?)
            })
            .await??;
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
    progress.upload.finish();
    let upload = t0.elapsed();
    crate::worker::wait_until_drained(&f.store, Duration::from_millis(50)).await?;
    progress.fit.finish();
    let fitted = t0.elapsed();
    let story = plan_and_follow_up(f, intake).await?;
    Ok(Filled {
        upload,
        fitted,
        story,
    })
}

/// What was stored and fitted, then the fleet health table and the worst joints.
async fn report(f: &Fleet, progress: &Progress, filled: Filled) -> anyhow::Result<()> {
    let counts = f.store.counts().await?;
    println!(
        "uploaded {} traces in {:.1} s; {} fits written, {} failed, all done {:.1} s after the first \
         upload ({:.0} traces/s synthesised, stored and fitted)",
        counts.traces,
        filled.upload.as_secs_f64(),
        counts.fits,
        progress.failed(),
        filled.fitted.as_secs_f64(),
        counts.traces as f64 / filled.fitted.as_secs_f64()
    );
    print_fleet(&f.store, f.vehicles).await?;
    // The follow-up swings' truths too: the worst joints may be at their follow-up swing.
    let mut truth = f.truth.clone();
    for (_, _, _, t, id, _) in &filled.story.found {
        if let Some(t) = t {
            truth.insert(id.clone(), *t);
        }
    }
    print_worst(&f.store, &truth).await?;
    print_story(&filled.story);
    Ok(())
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

//! Ingest and storage on PostgreSQL: trace documents uploaded concurrently through
//! `POST /v1/traces` of the in-process service (traces/s, MB/s), against a binary `COPY` of the
//! same bytes into a one-column table (the floor); then the stored samples per value and a
//! bit-exact read-back of every uploaded trace.

use std::sync::Arc;
use std::time::Instant;

use serde_json::{Value, json};
use tokio::sync::Semaphore;
use tokio::task::JoinSet;

use super::harness::{FreshPg, Server};
use super::table::{Row, Sizes, SuiteArgs};
use pantowatch::cli::simulate::docs::{lift_doc, simulate_defaults};
use pantowatch::cli::simulate::{SimulateArgs, simulate_doc};
use pantowatch::store::{Role, Store};
use pantowatch::trace::TraceDoc;

/// Target: the API within this factor of the `COPY` floor.
const RATIO_TARGET: f64 = 3.0;
/// Target stored bytes per sample value, lossless.
const BYTES_TARGET: f64 = 4.0;

/// The distinct recordings the uploads are made of, like a fleet's month: lift tests (raise and
/// lower, 8 s at 500 Hz), pendulum tests (15 s at 250 Hz, 0.05° encoder) and a head slider
/// test (5 s at 500 Hz) — what `pantowatch demo` uploads.
fn base_docs() -> anyhow::Result<Vec<TraceDoc>> {
    let d = simulate_defaults()?;
    let mut out = vec![lift_doc(21, 1.0, "x", "x")?, lift_doc(22, 1.6, "x", "x")?];
    for (k, joint) in ["J1", "J3", "J5", "J7"].into_iter().enumerate() {
        out.push(simulate_doc(&SimulateArgs {
            kind: "pendulum".into(),
            joint: joint.into(),
            noise: 0.05,
            quantum: 0.01,
            fs: 250.0,
            duration: 15.0,
            seed: 30 + k as u64,
            ..d.clone()
        })?);
    }
    out.push(simulate_doc(&SimulateArgs {
        kind: "slider".into(),
        joint: "J8".into(),
        noise: 0.02,
        quantum: 0.005,
        fs: 500.0,
        duration: 5.0,
        seed: 40,
        ..d
    })?);
    Ok(out)
}

/// Upload `i`: base document `i % bases` under its own trace id, vehicle, serial and date (so
/// every upload is a new trace; the samples repeat, each is compressed on its own).
fn body(bases: &[Value], i: usize) -> Vec<u8> {
    let mut v = bases[i % bases.len()].clone();
    let p = i / bases.len();
    v["trace_id"] = json!(format!("bench-ingest-{i}"));
    v["vehicle_id"] = json!(format!("EN57-{:04}", p / 2 + 1));
    v["pantograph"]["serial"] = json!(format!("160EC-{:04}", p + 1));
    v["recorded_at"] = json!(format!(
        "2026-{:02}-{:02}T{:02}:00:00Z",
        1 + (i / 28) % 12,
        1 + i % 28,
        i % 24
    ));
    serde_json::to_vec(&v).unwrap_or_default()
}

pub fn run(a: &SuiteArgs, sizes: &Sizes) -> Vec<Row> {
    let fail = |why: String| {
        vec![
            Row::failed(
                "ingest: API into PostgreSQL",
                "≤ 3× the raw COPY time",
                &why,
            ),
            Row::failed("storage: bytes per sample", "≤ 4 B, lossless", &why),
        ]
    };
    let rt = match pantowatch::cli::serve::runtime() {
        Ok(rt) => rt,
        Err(e) => return fail(format!("{e:#}")),
    };
    rt.block_on(async {
        let db = match FreshPg::create(&a.pg_url).await {
            Ok(db) => db,
            Err(e) => return fail(format!("{e:#}")),
        };
        let r = measure(&db.url, sizes).await;
        db.drop_now().await;
        r.unwrap_or_else(|e| fail(format!("{e:#}")))
    })
}

async fn measure(url: &str, sizes: &Sizes) -> anyhow::Result<Vec<Row>> {
    let docs = tokio::task::spawn_blocking(base_docs).await??;
    let bases: Vec<Value> = docs.iter().map(TraceDoc::to_value).collect();
    let n = sizes.ingest_traces;
    let bodies: Vec<Arc<Vec<u8>>> = (0..n).map(|i| Arc::new(body(&bases, i))).collect();
    let bytes: usize = bodies.iter().map(|b| b.len()).sum();
    let store = Store::connect(url).await?;
    let server = Server::start(&store, Role::Writer).await?;

    eprintln!(
        "   uploading {n} documents ({:.1} MB), {} at a time",
        bytes as f64 / 1e6,
        sizes.concurrency
    );
    let sem = Arc::new(Semaphore::new(sizes.concurrency));
    let mut set = JoinSet::new();
    let t0 = Instant::now();
    for b in &bodies {
        let permit = sem.clone().acquire_owned().await?;
        let req = server
            .client
            .post(server.url("/v1/traces"))
            .bearer_auth(&server.key)
            .header("content-type", "application/json")
            .body(b.as_ref().clone());
        set.spawn(async move {
            let r = req.send().await;
            drop(permit);
            match r {
                Ok(r) if r.status().is_success() => Ok(()),
                Ok(r) => Err(format!(
                    "{}: {}",
                    r.status(),
                    r.text().await.unwrap_or_default()
                )),
                Err(e) => Err(e.to_string()),
            }
        });
    }
    let mut errors = Vec::new();
    while let Some(r) = set.join_next().await {
        if let Err(e) = r? {
            errors.push(e);
        }
    }
    let api_s = t0.elapsed().as_secs_f64();
    server.stop().await?;
    if let Some(e) = errors.first() {
        anyhow::bail!("{} of {n} uploads refused, first: {e}", errors.len());
    }

    let copy_s = copy_floor(&store, &bodies).await?;
    // The documents as the service parsed them (the JSON round trip is the reference).
    let parsed = bodies
        .iter()
        .take(bases.len())
        .map(|b| TraceDoc::from_json(b).map_err(|e| anyhow::anyhow!("{e}")))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let storage = storage(&store, &parsed, n).await;
    store.close().await;

    let mb = bytes as f64 / 1e6;
    let ratio = api_s / copy_s;
    let ingest = Row {
        measure: format!("ingest: API into PostgreSQL ({n} documents, {mb:.0} MB)"),
        measured: format!(
            "{:.0} traces/s, {:.1} MB/s ({} concurrent) vs COPY {:.1} MB/s: **{ratio:.1}×** the floor",
            n as f64 / api_s,
            mb / api_s,
            sizes.concurrency,
            mb / copy_s
        ),
        target: "≤ 3× the raw COPY time".into(),
        pass: Some(ratio <= RATIO_TARGET),
        value: Some(ratio),
        unit: "× COPY".into(),
        detail: json!({"documents": n, "bytes": bytes, "api_s": api_s, "copy_s": copy_s,
                       "concurrency": sizes.concurrency}),
    };
    Ok(vec![ingest, storage?])
}

/// Time of one binary `COPY … FROM STDIN` of every body into `copy_floor (doc bytea)`.
async fn copy_floor(store: &Store, bodies: &[Arc<Vec<u8>>]) -> anyhow::Result<f64> {
    let Store::Postgres(pg) = store else {
        anyhow::bail!("the COPY floor needs PostgreSQL");
    };
    let mut conn = pg.pool().acquire().await?;
    sqlx::query("CREATE TABLE copy_floor (doc bytea NOT NULL)")
        .execute(&mut *conn)
        .await?;
    // PGCOPY binary: signature, flags, header extension; per tuple: 1 field, its length, bytes;
    // trailer −1. Built before the clock starts: the floor is the server's work.
    let mut buf = Vec::with_capacity(bodies.iter().map(|b| b.len() + 6).sum::<usize>() + 21);
    buf.extend_from_slice(b"PGCOPY\n\xff\r\n\0");
    buf.extend_from_slice(&0i32.to_be_bytes());
    buf.extend_from_slice(&0i32.to_be_bytes());
    for b in bodies {
        buf.extend_from_slice(&1i16.to_be_bytes());
        buf.extend_from_slice(&i32::try_from(b.len())?.to_be_bytes());
        buf.extend_from_slice(b);
    }
    buf.extend_from_slice(&(-1i16).to_be_bytes());
    let t0 = Instant::now();
    let mut copy = conn
        .copy_in_raw("COPY copy_floor (doc) FROM STDIN (FORMAT binary)")
        .await?;
    for chunk in buf.chunks(1 << 20) {
        copy.send(chunk).await?;
    }
    let rows = copy.finish().await?;
    let s = t0.elapsed().as_secs_f64();
    anyhow::ensure!(rows == bodies.len() as u64, "COPY wrote {rows} rows");
    Ok(s)
}

/// Stored bytes per sample value (every channel, `t_s` included) and a bit-exact comparison of
/// every uploaded trace's samples with its document.
async fn storage(store: &Store, docs: &[TraceDoc], n: usize) -> anyhow::Result<Row> {
    let (mut blob, mut values, mut exact) = (0i64, 0i64, 0usize);
    for i in 0..n {
        let id = format!("bench-ingest-{i}");
        let meta = store
            .get_trace(&id)
            .await?
            .ok_or_else(|| anyhow::anyhow!("{id} not stored"))?;
        blob += meta.samples_bytes;
        values += meta.sample_count * meta.channel_names.len() as i64;
        let back = store
            .get_samples(&id)
            .await?
            .ok_or_else(|| anyhow::anyhow!("{id} has no samples"))?;
        let doc = &docs[i % docs.len()];
        let same = back.len() == doc.channels.len()
            && back.iter().all(|(name, v)| {
                doc.channel(name).is_some_and(|w| {
                    w.len() == v.len() && w.iter().zip(v).all(|(x, y)| x.to_bits() == y.to_bits())
                })
            });
        exact += usize::from(same);
    }
    let per = blob as f64 / values as f64;
    Ok(Row {
        measure: format!("storage: bytes per sample ({n} traces, {values} values)"),
        measured: format!(
            "**{per:.2} B** per value (raw f64: 8 B; the document JSON: {:.1} B); {exact} of {n} read back bit-exact",
            json_bytes_per_value(docs)
        ),
        target: "≤ 4 B, lossless".into(),
        pass: Some(per <= BYTES_TARGET && exact == n),
        value: Some(per),
        unit: "B/value".into(),
        detail: json!({"blob_bytes": blob, "values": values, "bit_exact": exact, "traces": n}),
    })
}

/// Bytes of the documents' JSON per sample value, for scale.
fn json_bytes_per_value(docs: &[TraceDoc]) -> f64 {
    let bytes: usize = docs
        .iter()
        .map(|d| serde_json::to_vec(&d.to_value()).map_or(0, |v| v.len()))
        .sum();
    let values: usize = docs
        .iter()
        .map(|d| d.channels.iter().map(|(_, v)| v.len()).sum::<usize>())
        .sum();
    bytes as f64 / values.max(1) as f64
}

//! Pooled lift fits (issue 15, point 4): after a lift's own fit is written, the pantograph's
//! recent lifts are fitted together and the result stored as the newest lift's current fit.
//! Pooled rig fits (issue 36, point 5, [`after_rig`]): after a single-joint test's fit, the
//! recordings of its rig (`test.rig_id`) are fitted with one set of physical parameters.
//!
//! Window (stated): the newest lift and the lifts before it within [`WINDOW_DAYS`], at most
//! [`MAX_LIFTS`] — a month of monthly lifts is three tests; J2/J2'/J5 become informed only over
//! several. The pooled result is a contract fit result with a `pooled` block naming the tests,
//! written with the model version [`pooled_version`] (so once per set of tests), and it feeds
//! health and alerts like any fit. A lift whose own fit withheld its joints (issue 16: the
//! residual showed a model error) or named an effect neither pools nor is pooled. The
//! pantograph's force-gauge records (`static_force` traces, issue 20) in the same window, at most
//! [`MAX_GAUGES`], pool in too (`fit_pooled_lift_and_gauge_traces`): a lift with one gauge record
//! is a pool; a gauge record whose own fit named an effect or withheld its joints is left out, as
//! a lift is. The pool is fitted under the fleet prior its lift's fit used (`fleet_prior`),
//! recorded in `fit.prior` and `fits.prior_version`, its model version naming the prior
//! ([`pooled_version_under`]): a new prior's refit of the lift writes a new pool, and a pool
//! already under the newest prior is not queued again. No physics here: `models::lift::report`
//! fits.

use chrono::TimeDelta;

use crate::alerts::{self, AlertOptions};
use crate::fitting::FitLimits;
use crate::fleet_prior::FitPrior;
use crate::ingest::stored_doc;
use crate::store::{NewFit, Store, StoreError};
use pantowatch_models::budget::Budget;
use pantowatch_models::drift::DriftThresholds;
use pantowatch_models::lift::gauge::report::GaugeChannels;
use pantowatch_models::lift::report::fit_pooled_lift_and_gauge_traces_with;
use pantowatch_models::report::MODEL_VERSION;

/// How far back a pooled fit reaches from the newest lift, days.
pub const WINDOW_DAYS: i64 = 180;
/// Most lifts in one pooled fit (the newest included).
pub const MAX_LIFTS: usize = 3;
/// Most force-gauge records in one pooled fit (the newest in the window).
pub const MAX_GAUGES: usize = 2;

/// The model version of a pooled fit of `n` lifts.
pub fn pooled_version(n: usize) -> String {
    format!("{MODEL_VERSION}; lift pooled over {n} tests")
}

/// The model version of a pooled fit of `n` tests under fleet prior version `prior_version`:
/// [`pooled_version`], with `; fleet prior vN` for a stored version N > 0 (version 0, the type
/// file's, is the pool as before priors were versioned).
pub fn pooled_version_under(n: usize, prior_version: Option<i64>) -> String {
    match prior_version.filter(|v| *v > 0) {
        Some(v) => format!("{}; fleet prior v{v}", pooled_version(n)),
        None => pooled_version(n),
    }
}

/// Fit the lifts of `trace_id`'s pantograph in the window ending at it, with its force-gauge
/// records there, when there are 2 lifts or more (or a gauge record besides the lift), and store
/// the result as its fit, under `prior` (the lift's own fit's, recorded); then run the alert
/// rules on it. `Ok(None)`: nothing
/// to pool. CPU work runs off the async runtime, under `limits` like a job's fit: past them
/// the pooled fit is stopped and dropped (logged; the lift's own fit stands).
pub async fn after_lift(
    store: &Store,
    trace_id: &str,
    thresholds: DriftThresholds,
    alerts_opts: &AlertOptions,
    limits: FitLimits,
    prior: Option<&FitPrior>,
) -> Result<Option<i64>, StoreError> {
    let Some(meta) = store.get_trace(trace_id).await? else {
        return Ok(None);
    };
    let Some(serial) = meta.serial.clone() else {
        return Ok(None);
    };
    if meta.kind != "lift" {
        return Ok(None);
    }
    let from = meta.recorded_at - TimeDelta::days(WINDOW_DAYS);
    let mut ids: Vec<String> = store
        .serial_history(&serial)
        .await?
        .into_iter()
        .filter(|p| p.recorded_at >= from && p.recorded_at <= meta.recorded_at)
        .map(|p| p.trace_id)
        .collect();
    ids.dedup();
    // A lift whose own fit withheld its joints (the model missed something: a sensor fault, an
    // unmodelled effect) is not pooled, nor pools others: its error would spread to the pool.
    // Nor one whose fit named an effect (a drag, an H delay or offset, a Stribeck friction):
    // the pooled fit is the plain model, so the effect would land in the shared friction —
    // measured, an H delay lift and an H offset lift pooled with a clean one raised a J1+J3
    // watch alert (`api a_sensor_delay_is_a_sensor_finding_not_a_joint_alarm`).
    let withheld = |f: Option<crate::store::FitRecord>| -> Result<bool, StoreError> {
        let Some(f) = f else { return Ok(false) };
        let r = f.result()?.residual;
        Ok(r.joints_withheld.is_some() || !r.effects.is_empty())
    };
    if withheld(store.get_fit(trace_id).await?)? {
        return Ok(None);
    }
    let mut lifts: Vec<(crate::store::TraceMeta, _)> = Vec::new();
    let mut gauges: Vec<(crate::store::TraceMeta, _)> = Vec::new();
    for id in ids.iter().rev() {
        if lifts.len() == MAX_LIFTS && gauges.len() == MAX_GAUGES {
            break;
        }
        let Some(m) = store.get_trace(id).await? else {
            continue;
        };
        let gauge = m.kind == crate::trace::STATIC_FORCE;
        let (taken, max) = if gauge {
            (&gauges, MAX_GAUGES)
        } else {
            (&lifts, MAX_LIFTS)
        };
        if (!gauge && m.kind != "lift")
            || taken.len() == max
            || taken.iter().any(|(t, _)| t.trace_id == m.trace_id)
        {
            continue;
        }
        if withheld(store.get_fit(id).await?)? {
            continue;
        }
        let Some(channels) = store.get_samples(id).await? else {
            continue;
        };
        if gauge {
            gauges.push((m, channels));
        } else {
            lifts.push((m, channels));
        }
    }
    // Newest first, the triggering lift at the head (a late fit of an older lift pools the
    // window ending at it).
    lifts.sort_by_key(|l| std::cmp::Reverse(l.0.recorded_at));
    if let Some(i) = lifts.iter().position(|(m, _)| m.trace_id == trace_id) {
        let own = lifts.remove(i);
        lifts.insert(0, own);
    }
    lifts.truncate(MAX_LIFTS);
    gauges.sort_by_key(|g| std::cmp::Reverse(g.0.recorded_at));
    let least = if gauges.is_empty() { 2 } else { 1 };
    if lifts.len() < least || lifts[0].0.trace_id != trace_id {
        return Ok(None);
    }
    let n = lifts.len() + gauges.len();
    let version = pooled_version_under(n, prior.map(|p| p.used.version));
    let friction_prior = prior.map(|p| p.friction_prior.clone()).unwrap_or_default();
    let used = prior.map(|p| p.used.clone());
    let ids: Vec<String> = lifts.iter().map(|(m, _)| m.trace_id.clone()).collect();
    let gauge_ids: Vec<String> = gauges.iter().map(|(m, _)| m.trace_id.clone()).collect();
    let docs = lifts
        .into_iter()
        .map(|(m, c)| stored_doc(&m, c))
        .collect::<Result<Vec<_>, String>>()
        .map_err(StoreError::Invalid)?;
    let gauge_docs = gauges
        .into_iter()
        .map(|(m, c)| stored_doc(&m, c))
        .collect::<Result<Vec<_>, String>>()
        .map_err(StoreError::Invalid)?;
    let budget = Budget::new(limits.max_evaluations);
    let stop = budget.canceller();
    let spent = budget.clone();
    let t0 = std::time::Instant::now();
    let task = tokio::task::spawn_blocking(move || {
        let channels = docs
            .iter()
            .map(|d| d.lift_channels().map_err(|e| e.to_string()))
            .collect::<Result<Vec<_>, String>>()?;
        let gauge_channels = gauge_docs
            .iter()
            .map(|d| {
                d.static_force_channels()
                    .map(|g| GaugeChannels {
                        strip_height_m: g.strip_height_m,
                        force_n: g.force_n,
                        resolution_n: g.gauge_resolution_n,
                    })
                    .map_err(|e| e.to_string())
            })
            .collect::<Result<Vec<_>, String>>()?;
        pantowatch_models::budget::run(&budget, || {
            fit_pooled_lift_and_gauge_traces_with(
                &channels,
                &ids,
                &gauge_channels,
                &gauge_ids,
                WINDOW_DAYS as f64,
                &thresholds,
                &friction_prior,
            )
            .map(|r| {
                let mut result = r.result;
                result.fit.prior = used;
                result
            })
            .map_err(|e| e.to_string())
        })
        .unwrap_or_else(|e| Err(format!("{e} (the worker's fit limits)")))
    });
    let fitted = within_wall(&limits, stop, task).await?;
    // Timed like a job's fit, under its own kind.
    metrics::histogram!("pantowatch_fit_duration_seconds", "kind" => "lift_pooled")
        .record(t0.elapsed().as_secs_f64());
    metrics::histogram!("pantowatch_fit_evaluations", "kind" => "lift_pooled")
        .record(spent.evaluations() as f64);
    let result = match fitted {
        Ok(r) => r,
        Err(e) => {
            tracing::info!(trace = %trace_id, error = %e, "pooled lift fit did not converge or ran past its limits; the lift's own fit stands");
            return Ok(None);
        }
    };
    let fit = NewFit::from_result(result);
    let w = store.insert_fit(trace_id, &version, &fit).await?;
    if w.created {
        tracing::info!(trace = %trace_id, fit_id = w.fit_id, tests = n, "pooled lift fit written");
        if let Err(e) = alerts::after_fit(store, trace_id, w.fit_id, &fit.result, alerts_opts).await
        {
            tracing::error!(trace = %trace_id, error = %e, "alert rules failed after the pooled fit");
        }
    }
    Ok(Some(w.fit_id))
}

/// Most recordings in one pooled rig fit (the newest, the triggering one included).
pub const MAX_RIG_RECORDINGS: usize = 4;
use crate::ingest::RIG_SCAN;

/// The model version of a pooled rig fit over `ids` (sorted; a short hash tells sets apart).
pub fn rig_version(rig_id: &str, ids: &[String]) -> String {
    use sha2::{Digest, Sha256};
    let mut sorted = ids.to_vec();
    sorted.sort();
    let h = Sha256::digest(sorted.join("\n").as_bytes());
    let tag: String = h.iter().take(4).map(|b| format!("{b:02x}")).collect();
    format!(
        "{MODEL_VERSION}; rig {rig_id} pooled over {} recordings {tag}",
        ids.len()
    )
}

/// After a single-joint trace's own fit: when it states `test.rig_id` and the pantograph has
/// another recording of that rig (same kind, joint and stated rig), the newest
/// [`MAX_RIG_RECORDINGS`] are fitted pooled (`models::residual::pooled`: one set of physical
/// parameters, the pooled residual loop) and the result stored as this trace's fit, with
/// `pooled_rig` naming every recording; then the alert rules run on it. CPU work runs off the
/// async runtime under `limits`, like a job's fit; past them, or when the pooled fit fails, it
/// is logged and the trace's own fit stands. `Ok(None)`: nothing to pool.
pub async fn after_rig(
    store: &Store,
    trace_id: &str,
    thresholds: DriftThresholds,
    alerts_opts: &AlertOptions,
    limits: FitLimits,
) -> Result<Option<i64>, StoreError> {
    let Some(meta) = store.get_trace(trace_id).await? else {
        return Ok(None);
    };
    let (Some(serial), Some((rig_id, rig))) =
        (meta.serial.clone(), crate::ingest::rig_of(&meta.test_json))
    else {
        return Ok(None);
    };
    let mut pool = vec![meta.clone()];
    for m in store.traces_of_kind(&serial, &meta.kind, RIG_SCAN).await? {
        if pool.len() == MAX_RIG_RECORDINGS {
            break;
        }
        if m.trace_id == meta.trace_id || m.joint != meta.joint {
            continue;
        }
        if crate::ingest::rig_of(&m.test_json).is_some_and(|(id, r)| id == rig_id && r == rig) {
            pool.push(m);
        }
    }
    if pool.len() < 2 {
        return Ok(None);
    }
    let ids: Vec<String> = pool.iter().map(|m| m.trace_id.clone()).collect();
    let mut docs = Vec::new();
    for m in &pool {
        let Some(channels) = store.get_samples(&m.trace_id).await? else {
            return Ok(None);
        };
        docs.push(crate::ingest::stored_doc_as_sent(m, channels).map_err(StoreError::Invalid)?);
    }
    let version = rig_version(&rig_id, &ids);
    let budget = Budget::new(limits.max_evaluations);
    let stop = budget.canceller();
    let t0 = std::time::Instant::now();
    let task_ids = ids.clone();
    let task = tokio::task::spawn_blocking(move || {
        let mut tests = Vec::new();
        let mut baseline = None;
        for d in docs {
            let d = d.typed().map_err(|e| format!("{}: {e}", e.field))?;
            let (t, b) = d.joint_test().map_err(|e| e.to_string())?;
            baseline.get_or_insert(b);
            tests.push(t);
        }
        let baseline = baseline.ok_or("no recording")?;
        pantowatch_models::budget::run(&budget, || {
            let refs: Vec<_> = tests.iter().collect();
            let finding = pantowatch_models::residual::pooled::analyse_pooled(
                &refs,
                &pantowatch_models::identify::FitOptions::default(),
            )
            .map_err(|e| e.to_string())?;
            pantowatch_models::residual::pooled::pooled_result(
                &refs,
                &finding,
                0,
                &task_ids,
                &rig_id,
                &baseline,
                &thresholds,
            )
            .map_err(|e| e.to_string())
        })
        .unwrap_or_else(|e| Err(format!("{e} (the worker's fit limits)")))
    });
    let fitted = within_wall(&limits, stop, task).await?;
    metrics::histogram!("pantowatch_fit_duration_seconds", "kind" => "rig_pooled")
        .record(t0.elapsed().as_secs_f64());
    let result = match fitted {
        Ok(r) => r,
        Err(e) => {
            tracing::info!(trace = %trace_id, error = %e, "pooled rig fit failed or ran past its limits; the trace's own fit stands");
            return Ok(None);
        }
    };
    let fit = NewFit::from_result(result);
    let w = store.insert_fit(trace_id, &version, &fit).await?;
    if w.created {
        tracing::info!(trace = %trace_id, fit_id = w.fit_id, recordings = ids.len(), "pooled rig fit written");
        if let Err(e) = alerts::after_fit(store, trace_id, w.fit_id, &fit.result, alerts_opts).await
        {
            tracing::error!(trace = %trace_id, error = %e, "alert rules failed after the pooled rig fit");
        }
    }
    Ok(Some(w.fit_id))
}

/// The pooled fit's answer, or — past `worker.fit_budget_secs` — the fit cancelled and said so.
async fn within_wall<T>(
    limits: &FitLimits,
    stop: pantowatch_models::budget::Canceller,
    task: tokio::task::JoinHandle<Result<T, String>>,
) -> Result<Result<T, String>, StoreError> {
    match tokio::time::timeout(limits.wall, task).await {
        Ok(joined) => joined.map_err(|e| StoreError::Task(e.to_string())),
        Err(_) => {
            stop.cancel();
            Ok(Err(format!(
                "ran past worker.fit_budget_secs ({} s) and was stopped",
                limits.wall.as_secs_f64()
            )))
        }
    }
}

//! Issue 19, point 1: the fit result is typed from the fit to the store, and a stored result
//! reads back as the same type. Every kind of result the service stores — pendulum, slider,
//! quadrangle swing, lift (with a named effect, with an `unexplained` verdict), pooled lift and
//! gauge, static force (with a named effect) — goes typed → stored JSON → typed → stored JSON
//! byte for byte, and the contract's own field order (`fit --json`) round-trips too.

use std::path::Path;

use pantowatch_models::drift::DriftThresholds;
use pantowatch_models::lift::report::fit_pooled_lift_and_gauge_traces;
use pantowatch_models::report::FitResult;
use serde_json::json;

use super::NewFit;
use crate::cli::simulate::{SimulateArgs, simulate_doc};
use crate::fitting::fit_document;
use crate::trace::TraceDoc;

/// `result` written as the store writes it, read back typed and written again: the same
/// bytes; and in the contract's field order the same. Returns the stored text.
fn round_trips(label: &str, result: &FitResult) -> String {
    let stored = NewFit::from_result(result.clone())
        .result_json()
        .expect("stored json");
    let back: FitResult =
        serde_json::from_str(&stored).unwrap_or_else(|e| panic!("{label}: reading back: {e}"));
    let again = NewFit::from_result(back.clone())
        .result_json()
        .expect("stored json");
    assert_eq!(again, stored, "{label}: stored → typed → stored");
    let direct = serde_json::to_string(result).expect("json");
    let back_direct: FitResult =
        serde_json::from_str(&direct).unwrap_or_else(|e| panic!("{label}: reading back: {e}"));
    assert_eq!(
        serde_json::to_string(&back_direct).expect("json"),
        direct,
        "{label}: contract order"
    );
    assert_eq!(
        serde_json::to_string(&back).expect("json"),
        direct,
        "{label}: read from the store, written in the contract's order"
    );
    stored
}

fn simulated(kind: &str, seed: u64, set: impl FnOnce(&mut SimulateArgs)) -> TraceDoc {
    let mut a = SimulateArgs {
        kind: kind.into(),
        seed,
        ..crate::cli::simulate::docs::simulate_defaults().expect("defaults")
    };
    if kind == "lift" {
        a.protocol = "raise-and-lower".into();
        a.sensor_noise = 1.0;
        a.h_noise_mm = 0.0;
    }
    set(&mut a);
    simulate_doc(&a).expect("simulated")
}

#[test]
fn every_kind_of_stored_result_reads_back_as_the_same_json() {
    let th = DriftThresholds::default();
    let fit = |label: &str, doc: &TraceDoc| {
        fit_document(doc, &th).unwrap_or_else(|e| panic!("{label}: {e}"))
    };
    let mut results: Vec<(String, FitResult)> = Vec::new();
    // The shipped pendulum and slider examples (baselines, drifted, with effects).
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/examples");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .expect("../shared/data/examples")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension().is_some_and(|x| x == "json")
                && p.file_name().is_some_and(|n| n != "truth.json")
        })
        .collect();
    files.sort();
    assert!(files.len() >= 10, "{files:?}");
    for p in &files {
        let doc = crate::cli::read_trace(p).expect("example");
        let label = p.display().to_string();
        results.push((label.clone(), fit(&label, &doc)));
    }
    // The simulators: a quadrangle swing, lifts, force-gauge records.
    let swing = simulated(crate::trace::QUADRANGLE_SWING, 3, |_| {});
    results.push(("quadrangle".into(), fit("quadrangle", &swing)));
    let lifts: Vec<TraceDoc> = (0..2)
        .map(|k| {
            simulated("lift", 40 + k, |a| {
                a.trace_id = Some(format!("lift-{k}"));
                a.recorded_at = format!("2026-0{}-05T06:00:00Z", k + 1);
            })
        })
        .collect();
    results.push(("lift".into(), fit("lift", &lifts[0])));
    let delayed = simulated("lift", 31, |a| {
        a.effects = vec!["sensor_delay:delay_s=0.02".into()]
    });
    results.push(("lift, sensor delay".into(), fit("delay", &delayed)));
    // A lift whose H channel reads 5 % high: structure no candidate explains.
    let mut v = simulated("lift", 23, |_| {}).to_value();
    let h: Vec<f64> = v["channels"]["H_m"]
        .as_array()
        .expect("H_m")
        .iter()
        .filter_map(serde_json::Value::as_f64)
        .map(|x| x * 1.05)
        .collect();
    v["channels"]["H_m"] = json!(h);
    let gain = TraceDoc::from_value(&v).expect("lift");
    results.push(("lift, H gain".into(), fit("gain", &gain)));
    let gauge = simulated(crate::trace::STATIC_FORCE, 7, |a| {
        a.trace_id = Some("gauge".into())
    });
    results.push(("static force".into(), fit("gauge", &gauge)));
    let offset = simulated(crate::trace::STATIC_FORCE, 5, |a| {
        a.effects = vec!["sensor_offset:offset=3".into()]
    });
    results.push(("static force, offset".into(), fit("offset", &offset)));
    // A pooled fit: both lifts (newest first) and the gauge record.
    let channels: Vec<_> = lifts
        .iter()
        .rev()
        .map(|d| d.lift_channels().expect("channels"))
        .collect();
    let g = gauge.static_force_channels().expect("gauge channels");
    let gauges = [pantowatch_models::lift::gauge::report::GaugeChannels {
        strip_height_m: g.strip_height_m,
        force_n: g.force_n,
        resolution_n: g.gauge_resolution_n,
    }];
    let pooled = fit_pooled_lift_and_gauge_traces(
        &channels,
        &["lift-1".into(), "lift-0".into()],
        &gauges,
        &["gauge".into()],
        crate::pooled::WINDOW_DAYS as f64,
        &th,
    )
    .expect("pooled fit")
    .result;
    results.push(("pooled".into(), pooled));
    // Every field a result may carry, non-finite numbers among them (written `null`).
    let mut full = results
        .iter()
        .find(|(l, _)| l == "lift")
        .expect("lift")
        .1
        .clone();
    full.residual.verdict = Some("unexplained".into());
    full.residual.correlates_with = vec![("T_nm".into(), 0.4), ("v".into(), f64::NAN)];
    full.residual.excess_ratio = Some(f64::NAN);
    full.residual.joints_withheld = Some("the residual is 4 × the sensor noise".into());
    full.residual.holdout_note = Some("segment too short".into());
    full.residual.autocorrelation = vec![(0.1, 0.5), (0.2, f64::INFINITY)];
    full.fit.viscous_dry_correlation = f64::NAN;
    full.fit.sensor_offset_ci95 = Some([f64::NAN, 1.0]);
    full.fit.input_offset = Some(pantowatch_models::report::Quantity {
        value: f64::NAN,
        unit: "N".into(),
    });
    full.fit.input_offset_ci95 = Some([f64::NAN; 2]);
    full.joints[0].viscous.value = f64::NAN;
    full.joints[0].viscous.ci95 = [f64::NAN; 2];
    full.joints[0].viscous.baseline = None;
    full.fit.body_uncertainty = Some(pantowatch_models::report::BodyUncertaintyResult {
        propagated: [("mass_kg".to_string(), 0.02)].into_iter().collect(),
        not_propagated: [("inertia_kgm2".to_string(), 0.001)].into_iter().collect(),
    });
    results.push(("every field".into(), full));

    for (label, r) in &results {
        round_trips(label, r);
    }
    // The cases cover what the issue names: effects, a verdict, combinations, a pool.
    let any = |f: fn(&FitResult) -> bool| results.iter().any(|(_, r)| f(r));
    assert!(any(|r| !r.residual.effects.is_empty()), "an effect named");
    assert!(any(|r| r
        .residual
        .effects
        .iter()
        .any(|e| e.name == "sensor_offset")));
    assert!(any(|r| r.residual.verdict.is_some()), "a verdict");
    assert!(any(|r| !r.combinations.is_empty()), "combinations");
    assert!(any(|r| r.pooled.is_some()), "a pooled fit");
    assert!(any(|r| !r.residual.autocorrelation_before.is_empty()));
    let natural = results.iter().filter(|(l, _)| l != "every field");
    assert!(
        natural.clone().any(|(_, r)| r.residual.verdict.is_some()),
        "a natural verdict"
    );
}

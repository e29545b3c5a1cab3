//! Pooled lift fits on realistic-noise lifts (issue 15, point 4): sets of three raise-and-lower
//! lifts of one pantograph, one joint's friction drifted (0.4–3×, `COVERAGE_DRIFTS`) or none,
//! each lift with its own sensor noise, fitted together as the service fits them (each lift its
//! own J8 dry, the pooled intervals' calibrated widening); `PW_SHARED=1`: every coefficient
//! shared with JᵀJ intervals, as before; `PW_PER_TRACE` (e.g. `J8:dry:0.3`) sets the per-lift
//! coefficients.
//! Prints per set the pooled H RMSE of each lift, J5 dry's estimate, the entries whose 95 %
//! interval misses the truth and any flag on an undrifted entry; then coverage over the set.
//!
//! `cargo run --release -p pantowatch-models --example lift_pooled_coverage -- [SETS] [K] [FIRST]`
use pantowatch_models::drift::Status;
use pantowatch_models::lift::dynamics::LiftModel;
use pantowatch_models::lift::geometry::builtin_160ec;
use pantowatch_models::lift::identify::{
    LiftFitOptions, LiftTrace, POOLED_INTERVAL_SCALE, POOLED_PER_TRACE, fit_map,
};
use pantowatch_models::lift::protocol::{LiftProtocol, record};
use pantowatch_models::lift::sensitivity::LiftParam;
use pantowatch_models::lift::sensors::LiftSensorNoise;
use pantowatch_models::lift::simulate::SimOptions;

fn main() {
    let mut args = std::env::args().skip(1);
    let sets: u64 = args.next().and_then(|s| s.parse().ok()).unwrap_or(2);
    let k: f64 = args.next().and_then(|s| s.parse().ok()).unwrap_or(1.0);
    let first: u64 = args.next().and_then(|s| s.parse().ok()).unwrap_or(0);
    let g = builtin_160ec();
    let base = LiftModel::new(g);
    let protocol = LiftProtocol::raise_and_lower(&base, g).unwrap();
    // The service's pooled fit (`lift::report::fit_pooled_lift_and_gauge_traces`); `PW_SHARED=1`:
    // every coefficient shared and JᵀJ intervals (before session 15).
    let mut opts = LiftFitOptions {
        per_trace: POOLED_PER_TRACE.to_vec(),
        param_interval_scale: POOLED_INTERVAL_SCALE.to_vec(),
        ..LiftFitOptions::default()
    };
    if std::env::var("PW_SHARED").is_ok_and(|s| s == "1") {
        opts.per_trace.clear();
        opts.param_interval_scale.clear();
    }
    if let Ok(spec) = std::env::var("PW_PER_TRACE") {
        opts.per_trace = spec
            .split(',')
            .filter(|s| !s.is_empty())
            .map(|s| {
                let v: Vec<&str> = s.split(':').collect();
                (LiftParam::named(v[0], v[1]).unwrap(), v[2].parse().unwrap())
            })
            .collect();
    }
    let j5 = LiftParam::named("J5", "dry").unwrap();
    let (mut n, mut hit, mut false_flags, mut rms_worst) = (0, 0, 0, 0.0f64);
    for set in first..first + sets {
        for d in &pantowatch_models::lift::input_noise::COVERAGE_DRIFTS {
            let mut m = base.clone();
            let drifted = d.map(|(j, kind, f)| {
                let p = LiftParam::named(j, kind).unwrap();
                let mut off = 0.0;
                p.set(&mut m, &mut off, p.get(&base, 0.0) * f);
                p
            });
            let clean = record(&m, &protocol, &SimOptions::default()).unwrap();
            let recs: Vec<_> = (0..3)
                .map(|i| {
                    LiftSensorNoise::realistic()
                        .scaled(k)
                        .apply(&clean, 5000 + 3 * set + i)
                })
                .collect();
            let traces: Vec<LiftTrace> = recs.iter().map(|r| r.trace()).collect();
            let fit = match fit_map(&base, &traces, &opts) {
                Ok(f) => f,
                Err(e) => {
                    println!("{d:?} set {set}: fit failed {e}");
                    continue;
                }
            };
            let relative = |p: LiftParam| p.get(&m, 0.0) / p.get(&base, 0.0);
            let mut misses = Vec::new();
            for e in fit.params.iter().filter(|e| e.informed) {
                let truth = e.param.get(&m, 0.0);
                n += 1;
                if e.ci95[0] <= truth && truth <= e.ci95[1] {
                    hit += 1;
                } else {
                    misses.push(format!(
                        "{}.{} {:.3} [{:.3}, {:.3}] truth {:.3}",
                        e.param.joint(),
                        e.param.kind(),
                        e.value / e.baseline,
                        e.ci95[0] / e.baseline,
                        e.ci95[1] / e.baseline,
                        truth / e.baseline
                    ));
                }
                if matches!(e.status, Status::Watch | Status::Alarm) && Some(e.param) != drifted {
                    false_flags += 1;
                    misses.push(format!(
                        "FALSE FLAG {}.{} {:?}",
                        e.param.joint(),
                        e.param.kind(),
                        e.status
                    ));
                }
            }
            for c in fit.combinations.iter().filter(|c| c.informed) {
                let truth = c.level_of(relative);
                n += 1;
                if c.ci95[0] <= truth && truth <= c.ci95[1] {
                    hit += 1;
                } else {
                    misses.push(format!(
                        "{} {:.3} [{:.3}, {:.3}] truth {:.3}",
                        c.label(),
                        c.value,
                        c.ci95[0],
                        c.ci95[1],
                        truth
                    ));
                }
                if matches!(c.status, Status::Watch | Status::Alarm)
                    && drifted.is_none_or(|p| !c.params.contains(&p))
                {
                    false_flags += 1;
                    misses.push(format!("FALSE FLAG {} {:?}", c.label(), c.status));
                }
            }
            let e5 = fit.params.iter().find(|e| e.param == j5).unwrap();
            let shown: Vec<String> = fit
                .params
                .iter()
                .filter(|e| e.informed)
                .map(|e| {
                    format!(
                        "{}.{} {:.2}",
                        e.param.joint(),
                        e.param.kind(),
                        e.value / e.baseline
                    )
                })
                .chain(fit.combinations.iter().filter(|c| c.informed).map(|c| {
                    format!(
                        "{} {:.3} [{:.3}, {:.3}]",
                        c.label(),
                        c.value,
                        c.ci95[0],
                        c.ci95[1]
                    )
                }))
                .collect();
            rms_worst = fit.rmse_m.iter().fold(rms_worst, |a, &b| a.max(b));
            println!(
                "{:<26} set {set}: rmse {:?} mm  J5 dry {:.2} (truth {:.2}, informed {})  shown {shown:?}  evals {}  misses {misses:?}",
                format!("{d:?}"),
                fit.rmse_m
                    .iter()
                    .map(|v| (v * 1e4).round() / 10.0)
                    .collect::<Vec<_>>(),
                e5.map_value / e5.baseline,
                relative(j5),
                e5.informed,
                fit.evaluations,
            );
        }
    }
    println!(
        "coverage {hit}/{n} = {:.1} %, false flags {false_flags}, worst RMSE {:.2} mm",
        100.0 * hit as f64 / n.max(1) as f64,
        rms_worst * 1e3
    );
}

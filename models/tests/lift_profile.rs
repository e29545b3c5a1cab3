//! The profiling harness of docs/PROFILE.md: one lift fit of a trace document given by
//! `PANTOWATCH_PROFILE_TRACE` (a `pantowatch simulate --kind lift` file), run under callgrind:
//!
//! ```text
//! cargo test --release -p pantowatch-models --test lift_profile --no-run
//! PANTOWATCH_PROFILE_TRACE=rl.json valgrind --tool=callgrind target/release/deps/lift_profile-* --exact profile_one_lift_fit --nocapture
//! ```
//!
//! Without the variable it fits a short simulated raise instead, so the harness stays tested.

use pantowatch_models::drift::DriftThresholds;
use pantowatch_models::lift::dynamics::LiftModel;
use pantowatch_models::lift::geometry::builtin_160ec;
use pantowatch_models::lift::protocol::{LiftProtocol, record};
use pantowatch_models::lift::report::{LiftChannels, fit_lift_trace};
use pantowatch_models::lift::simulate::SimOptions;

fn channel(doc: &serde_json::Value, name: &str) -> Vec<f64> {
    doc["channels"][name]
        .as_array()
        .map(|a| a.iter().filter_map(serde_json::Value::as_f64).collect())
        .unwrap_or_default()
}

#[test]
fn profile_one_lift_fit() {
    let (t, h, tq, fs, fm) = match std::env::var("PANTOWATCH_PROFILE_TRACE") {
        Ok(path) => {
            let text = std::fs::read_to_string(&path).expect("trace file");
            let doc: serde_json::Value = serde_json::from_str(&text).expect("JSON");
            (
                channel(&doc, "t_s"),
                channel(&doc, "H_m"),
                channel(&doc, "T_Nm"),
                channel(&doc, "Fs_N"),
                channel(&doc, "Fm_N"),
            )
        }
        Err(_) => {
            let g = builtin_160ec();
            let p = LiftProtocol {
                t_end_s: 1.0,
                sample_hz: 250.0,
                ..LiftProtocol::reference(g)
            };
            let r = record(&LiftModel::new(g), &p, &SimOptions::default()).unwrap();
            (r.t_s, r.strip_height_m, r.torque_nm, r.fs_n, r.fm_n)
        }
    };
    let ch = LiftChannels {
        t_s: &t,
        strip_height_m: &h,
        torque_nm: &tq,
        fs_n: &fs,
        fm_n: &fm,
    };
    let clock = std::time::Instant::now();
    let rep = fit_lift_trace(&ch, &DriftThresholds::default(), "profile").unwrap();
    eprintln!(
        "fit {:?}: {} evaluations, {} iterations, {:?}, rmse {:.4e} m",
        clock.elapsed(),
        rep.fit.evaluations,
        rep.fit.iterations,
        rep.fit.termination,
        rep.fit.rmse_m[0]
    );
    for e in rep.fit.params.iter().filter(|e| e.informed) {
        eprintln!(
            "  {}.{} = {:.5} ± {:.5}",
            e.param.joint(),
            e.param.kind(),
            e.map_value,
            e.posterior_sd
        );
    }
    assert!(rep.fit.rmse_m[0] < 2e-3, "rmse {}", rep.fit.rmse_m[0]);
}

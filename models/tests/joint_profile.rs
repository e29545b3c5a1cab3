//! The profiling harness of issue 38: one identification of a measured-like input-driven axis
//! record ([`DrivenAxis`]: EMPS-like, 8 kg… a stated mass, viscous 204 N·s/m, Coulomb 20.4 N,
//! the force sensor's zero −3.2 N, 0.2 N force noise, 0.05 mm position noise, logger steps),
//! run under callgrind:
//!
//! ```text
//! cargo test --release -p pantowatch-models --test joint_profile --no-run
//! PANTOWATCH_PROFILE_SECONDS=25 PANTOWATCH_PROFILE_HZ=1000 PANTOWATCH_PROFILE_LOOP=1 \
//!   valgrind --tool=callgrind target/release/deps/joint_profile-* --exact profile_one_driven_fit --nocapture
//! ```
//!
//! Without the variables it fits a 2 s record at 500 Hz (base fit only), so the harness stays
//! tested.

use pantowatch_models::drift::DriftThresholds;
use pantowatch_models::identify::{FitOptions, Param, fit_base};
use pantowatch_models::synth::DrivenAxis;
use pantowatch_models::testspec::Baseline;

fn env(name: &str, default: f64) -> f64 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

#[test]
fn profile_one_driven_fit() {
    let axis = DrivenAxis {
        moving_mass_kg: env("PANTOWATCH_PROFILE_MASS", 8.0),
        viscous: 204.0,
        normal_force_n: 40.8,
        dry: 0.5,
        input_offset_n: -3.2,
        force_n: 150.0,
        fs_hz: env("PANTOWATCH_PROFILE_HZ", 500.0),
        duration_s: env("PANTOWATCH_PROFILE_SECONDS", 2.0),
        force_noise_n: env("PANTOWATCH_PROFILE_FORCE_NOISE", 0.2),
        force_step_n: 0.05,
        position_noise_mm: env("PANTOWATCH_PROFILE_POS_NOISE", 0.05),
        position_step_mm: 0.01,
        seed: env("PANTOWATCH_PROFILE_SEED", 1.0) as u64,
    };
    let test = axis.record().unwrap();
    let opts = FitOptions::default();
    let clock = std::time::Instant::now();
    if env("PANTOWATCH_PROFILE_LOOP", 0.0) > 0.0 {
        let b = Baseline {
            joint: "custom".into(),
            viscous: None,
            dry: None,
            viscous_unit: "N·s/m",
        };
        let (r, fit, finding) = pantowatch_models::fit_joint_test_with_finding(
            &test,
            &b,
            &DriftThresholds::default(),
            "profile",
            &opts,
        )
        .unwrap();
        eprintln!(
            "residual loop {:?}: rmse {:.4} mm, effects {:?}, {} candidates; viscous {:?}",
            clock.elapsed(),
            r.rmse.value,
            finding.effects,
            finding.candidates.len(),
            fit.get(Param::Dyn(pantowatch_models::friction::DynParam::Viscous))
        );
    } else {
        let fit = fit_base(&test, &opts).unwrap();
        eprintln!(
            "fit {:?}: {} samples, {} evaluations, {} iterations, {:?}, rmse {:.4} mm, {} rhs, {} steps, {} events",
            clock.elapsed(),
            test.t_s.len(),
            fit.evaluations,
            fit.iterations,
            fit.termination,
            fit.rmse,
            fit.trajectory.n_rhs,
            fit.trajectory.n_steps,
            fit.trajectory.events.len()
        );
        for (p, v, s) in fit
            .spec_params
            .iter()
            .zip(&fit.values)
            .zip(&fit.std)
            .map(|((p, v), s)| (p, v, s))
        {
            eprintln!("  {p:?} = {v:.6} ± {s:.3e}");
        }
        assert!(fit.rmse.is_finite());
    }
}

/// Experiment (issue 38): what the restart grid of `fit_base` finds on a driven record.
#[test]
#[ignore]
fn grid_experiment() {
    use pantowatch_models::identify::{FitSpec, fit_window, initial::inverse_dynamics};
    let axis = DrivenAxis {
        moving_mass_kg: env("PANTOWATCH_PROFILE_MASS", 8.0),
        viscous: 204.0,
        normal_force_n: 40.8,
        dry: 0.5,
        input_offset_n: -3.2,
        force_n: 150.0,
        fs_hz: env("PANTOWATCH_PROFILE_HZ", 500.0),
        duration_s: env("PANTOWATCH_PROFILE_SECONDS", 2.0),
        force_noise_n: env("PANTOWATCH_PROFILE_FORCE_NOISE", 0.2),
        force_step_n: 0.05,
        position_noise_mm: env("PANTOWATCH_PROFILE_POS_NOISE", 0.05),
        position_step_mm: 0.01,
        seed: env("PANTOWATCH_PROFILE_SEED", 1.0) as u64,
    };
    let test = axis.record().unwrap();
    let opts = FitOptions::default();
    let init = inverse_dynamics(&test.dof, &test.t_s, &test.y, test.scale, 0, None, false);
    let mut spec = FitSpec::base(init.viscous, init.dry, false);
    spec.input_offset = Some(0.0);
    let n = test.t_s.len();
    let c = std::time::Instant::now();
    let first = fit_window(&test, 0, n, &spec, &init, &opts).unwrap();
    eprintln!(
        "init {init:?}\nfirst {:?}: rmse {:.6} white {} sigma {:.5} values {:?} std {:?} evals {}",
        c.elapsed(),
        first.rmse,
        pantowatch_models::stats::is_white(&first.residual),
        pantowatch_models::stats::noise_sigma(&first.residual),
        first.values,
        first.std,
        first.evaluations
    );
    for fv in [0.6, 0.8, 1.25, 1.6] {
        for fd in [0.9, 1.1, 1.25] {
            let mut s = init;
            s.viscous = (init.viscous * fv).max(1e-9);
            s.dry = (init.dry * fd).max(1e-9);
            let f = fit_window(&test, 0, n, &spec, &s, &opts).unwrap();
            eprintln!(
                "{fv} {fd}: rmse {:.6} ({:+.2e}) values {:?} evals {}",
                f.rmse,
                f.rmse / first.rmse - 1.0,
                f.values,
                f.evaluations
            );
        }
    }
}

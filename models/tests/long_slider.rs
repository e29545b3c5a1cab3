//! Issue 38: a slider record much longer than its motion (J8 moves for ~3 s, then rests) is
//! fitted in the right stick–slip piece. Before the first estimate was taken over the motion
//! alone, every 30 s record of this set landed elsewhere (viscous 0 to 9.9 N·s/m, μ 0.29 to
//! 0.93 against 3.99 and 0.5; docs/PERFORMANCE.md "Session 20").

use pantowatch_models::dynamics::{Dof, Mechanism};
use pantowatch_models::friction::FrictionLaw;
use pantowatch_models::identify::{FitOptions, JointTest, Readout, fit_base};
use pantowatch_models::rig::SliderRig;
use pantowatch_models::synth::{Sensor, Truth, grid, measure_truth};

/// The J8 rig of the paper's head test as the type file states it (10.5 kg, one 4 N/mm spring,
/// Fn 4.05 N), Table 4's friction (viscous 3.99 N·s/m, μ 0.5), released from 18.33 mm; the
/// stand's 0.05 mm noise and the logger's 0.01 mm steps.
fn record(fs_hz: f64, duration_s: f64, seed: u64) -> JointTest {
    record_with(
        fs_hz,
        duration_s,
        seed,
        FrictionLaw::base(3.99, 0.5),
        0.01833,
    )
}

/// As [`record`], with the friction `law` and the release deflection `q0_m` given.
fn record_with(fs_hz: f64, duration_s: f64, seed: u64, law: FrictionLaw, q0_m: f64) -> JointTest {
    let t = grid(duration_s, fs_hz);
    let dof = Dof {
        mech: Mechanism::Slider(SliderRig {
            moving_mass_kg: 10.5,
            stiffness_n_per_m: 4000.0,
            normal_force_n: 4.05,
        }),
        input: None,
        torsion: 0.0,
    };
    let truth = Truth {
        law,
        readout: Readout::default(),
        dry_fade: 0.0,
    };
    let sensor = Sensor {
        scale: 1000.0,
        noise_sigma: 0.05,
        quantum: 0.01,
        offset: 0.0,
        seed,
    };
    let y = measure_truth(&dof, &truth, q0_m, 0.0, &t, &sensor).unwrap();
    JointTest {
        dof,
        t_s: t,
        y,
        scale: 1000.0,
        unit: "mm",
        initial_rate: None,
        release_t_s: None,
        body_sd: vec![],
    }
}

#[test]
fn a_30_s_slider_record_lands_in_the_right_piece_on_every_seed() {
    for fs in [500.0, 1000.0] {
        for seed in 1..=4 {
            let fit = fit_base(&record(fs, 30.0, seed), &FitOptions::default()).unwrap();
            assert!(
                (fit.law.viscous / 3.99 - 1.0).abs() < 0.05
                    && (fit.law.dry / 0.5 - 1.0).abs() < 0.02,
                "{fs} Hz seed {seed}: viscous {} μ {} rmse {}",
                fit.law.viscous,
                fit.law.dry,
                fit.rmse
            );
            // At the noise: the right piece leaves nothing but the sensor's noise.
            assert!(fit.rmse < 0.052, "{fs} Hz seed {seed}: rmse {}", fit.rmse);
        }
    }
}

/// Issue 38, point 1: a J8 slider's first fit, from its energy-balance start
/// (`initial::energy_balance`), lands in the right stick–slip piece, so no restart runs
/// (`FitOutcome::restarts` is 0), and at the truth within its interval: 200 Hz to 2 kHz, 4 to
/// 30 s, four noise seeds each, Table 4's friction released from 18.33 mm and viscous 0.7×,
/// μ 1.2× it released from 25 mm, with the stand's 0.05 mm noise and the logger's 0.01 mm
/// steps. Before, the inverse-dynamics start sent many of these records' first fits to the
/// neighbouring piece (viscous ~4.5, μ ~0.48; 500 Hz 4 s seed 2 beyond what the restarts
/// reach). Not covered (docs/PERFORMANCE.md, session 21): a record whose last swing barely
/// sticks (viscous 1.4×, μ 0.8× from 12 mm), where the neighbouring piece's residual is also
/// white at the noise.
#[test]
fn the_first_fit_lands_at_the_truth_without_a_restart() {
    let cases = [(3.99, 0.5, 0.01833), (3.99 * 0.7, 0.5 * 1.2, 0.025)];
    let (mut covered, mut total) = (0, 0);
    let mut worst: f64 = 0.0;
    for (viscous, dry, q0) in cases {
        for fs in [200.0, 500.0, 1000.0, 2000.0] {
            for duration in [4.0, 10.0, 30.0] {
                for seed in 1..=4 {
                    let law = FrictionLaw::base(viscous, dry);
                    let test = record_with(fs, duration, seed, law, q0);
                    let fit = fit_base(&test, &FitOptions::default()).unwrap();
                    let name = format!("{viscous}/{dry} from {q0} m, {fs} Hz {duration} s #{seed}");
                    assert_eq!(fit.restarts, 0, "{name}: rmse {}", fit.rmse);
                    for (i, truth) in [viscous, dry].into_iter().enumerate() {
                        let z = (fit.values[i] - truth) / fit.std[i];
                        worst = worst.max(z.abs());
                        assert!(z.abs() < 3.5, "{name}: parameter {i} at {z:.2} sd");
                        total += 1;
                        if fit.ci95[i][0] <= truth && truth <= fit.ci95[i][1] {
                            covered += 1;
                        }
                    }
                }
            }
        }
    }
    let rate = covered as f64 / total as f64;
    assert!(
        rate >= 0.88,
        "95 % intervals cover {rate:.3} (worst {worst:.2} sd)"
    );
    eprintln!("covered {covered} of {total}, worst {worst:.2} sd");
}

//! Probe (issue 38): fit a single-joint trace document (a pendulum with its body written out, or
//! a slider) `--repeat` times and print time, estimates, evaluations and whether the restarts ran.
//! `cargo run --release -p pantowatch-models --example joint_fit_probe -- FILE... [--repeat N]`
//! (the file is read here, in the example, not in the library).

use std::time::Instant;

use pantowatch_models::dynamics::{Dof, Input, Mechanism};
use pantowatch_models::identify::{FitOptions, JointTest, fit_base};
use pantowatch_models::rig::{PendulumRig, SliderRig};
use serde_json::Value;

fn load(path: &str) -> JointTest {
    let doc: Value = serde_json::from_slice(&std::fs::read(path).expect("read")).expect("json");
    let test = &doc["test"];
    let rig = &test["rig"];
    let ch = &doc["channels"];
    let v = |x: &Value| -> Vec<f64> {
        x.as_array()
            .unwrap()
            .iter()
            .map(|a| a.as_f64().unwrap())
            .collect()
    };
    let f = |x: &Value, d: f64| x.as_f64().unwrap_or(d);
    let t = v(&ch["t_s"]);
    if test["kind"] == "pendulum" {
        let b = &rig["body"];
        let (mut m, mut j) = (f(&b["mass_kg"], 0.0), f(&b["inertia_kgm2"], 0.0));
        let mut mom = m * f(&b["com_distance_m"], 0.0);
        for a in rig["attachments"].as_array().cloned().unwrap_or_default() {
            let ma = f(&a["mass_kg"], 0.0);
            if a["kind"] == "point" {
                let da = f(&a["distance_m"], 0.0);
                m += ma;
                j += ma * da * da;
                mom += ma * da;
            } else {
                let l = f(&a["length_m"], 0.0);
                m += ma;
                j += ma * l * l / 3.0;
                mom += ma * l / 2.0;
            }
        }
        let mech = Mechanism::Pendulum(PendulumRig {
            mass_kg: m,
            inertia_kgm2: j,
            com_distance_m: mom / m,
            pin_radius_m: f(&rig["pin_radius_m"], 0.0),
            gravity_m_s2: f(&rig["gravity_m_s2"], 9.81),
        });
        JointTest {
            dof: Dof {
                mech,
                input: None,
                torsion: 0.0,
            },
            y: v(&ch["alpha_deg"]),
            t_s: t,
            scale: 180.0 / std::f64::consts::PI,
            unit: "deg",
            initial_rate: None,
            release_t_s: None,
            body_sd: vec![],
        }
    } else {
        let springs = f(&rig["springs"], 1.0);
        let mech = Mechanism::Slider(SliderRig {
            moving_mass_kg: f(&rig["moving_mass_kg"], 10.5),
            stiffness_n_per_m: springs * f(&rig["spring_stiffness_n_per_mm"], 4.0) * 1000.0,
            normal_force_n: f(&rig["normal_force_n"], 4.05),
        });
        let input = ch.get("F_N").map(|x| Input {
            t_s: t.clone(),
            value: v(x),
        });
        JointTest {
            dof: Dof {
                mech,
                input,
                torsion: 0.0,
            },
            y: v(&ch["h_mm"]),
            t_s: t,
            scale: 1000.0,
            unit: "mm",
            initial_rate: None,
            release_t_s: None,
            body_sd: vec![],
        }
    }
}

/// A measured-like set (issue 38): J8 sliders released from 18.33 mm (10.5 kg, 4 N/mm, Fn
/// 4.05 N; viscous 3.99 N·s/m, μ 0.5), 0.05 mm noise and 0.01 mm logger steps, at 500 Hz and
/// 1 kHz over 4, 10 and 30 s, seeds 1–4; and input-driven axes (`synth::DrivenAxis`, the
/// bench's: 0.2 N force noise with 0.05 N steps, 0.05 mm / 0.01 mm position) at 1 and 5 kHz over
/// 5 and 20 s, seeds 1–2. One line per record: its name, the values and standard errors.
fn measured_like() {
    use pantowatch_models::friction::FrictionLaw;
    use pantowatch_models::identify::Readout;
    use pantowatch_models::synth::{DrivenAxis, Sensor, Truth, grid, measure_truth};
    let opts = FitOptions::default();
    let report = |name: String, test: &JointTest| {
        let t0 = Instant::now();
        match fit_base(test, &opts) {
            Ok(f) => println!(
                "{name:<28} viscous {:.6} ± {:.3e}  dry {:.6} ± {:.3e}  rmse {:.5}  restarts {}  {:.1} ms",
                f.law.viscous,
                f.std[0],
                f.law.dry,
                f.std[1],
                f.rmse,
                f.restarts,
                1e3 * t0.elapsed().as_secs_f64()
            ),
            Err(e) => println!("{name:<28} failed: {e}"),
        }
    };
    for fs in [500.0, 1000.0] {
        for dur in [4.0, 10.0, 30.0] {
            for seed in 1..=4u64 {
                let t = grid(dur, fs);
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
                    law: FrictionLaw::base(3.99, 0.5),
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
                let y = measure_truth(&dof, &truth, 0.01833, 0.0, &t, &sensor).expect("sim");
                let test = JointTest {
                    dof,
                    t_s: t,
                    y,
                    scale: 1000.0,
                    unit: "mm",
                    initial_rate: None,
                    release_t_s: None,
                    body_sd: vec![],
                };
                report(format!("slider {fs} Hz {dur} s #{seed}"), &test);
            }
        }
    }
    for fs in [1000.0, 5000.0] {
        for dur in [5.0, 20.0] {
            for seed in 1..=2u64 {
                let axis = DrivenAxis {
                    moving_mass_kg: 8.0,
                    viscous: 204.0,
                    normal_force_n: 40.8,
                    dry: 0.5,
                    input_offset_n: -3.2,
                    force_n: 150.0,
                    fs_hz: fs,
                    duration_s: dur,
                    force_noise_n: 0.2,
                    force_step_n: 0.05,
                    position_noise_mm: 0.05,
                    position_step_mm: 0.01,
                    seed,
                };
                report(
                    format!("driven {fs} Hz {dur} s #{seed}"),
                    &axis.record().expect("record"),
                );
            }
        }
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.first().map(String::as_str) == Some("--slider") {
        // --slider FS DURATION SEED: one J8 record of the measured-like set, with its first fit.
        use pantowatch_models::friction::FrictionLaw;
        use pantowatch_models::identify::Readout;
        use pantowatch_models::synth::{Sensor, Truth, grid, measure_truth};
        let num = |i: usize| args[i].parse::<f64>().unwrap();
        let t = grid(num(2), num(1));
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
            law: FrictionLaw::base(3.99, 0.5),
            readout: Readout::default(),
            dry_fade: 0.0,
        };
        let sensor = Sensor {
            scale: 1000.0,
            noise_sigma: 0.05,
            quantum: 0.01,
            offset: 0.0,
            seed: num(3) as u64,
        };
        let y = measure_truth(&dof, &truth, 0.01833, 0.0, &t, &sensor).unwrap();
        let test = JointTest {
            dof,
            t_s: t,
            y,
            scale: 1000.0,
            unit: "mm",
            initial_rate: None,
            release_t_s: None,
            body_sd: vec![],
        };
        use pantowatch_models::identify::{FitSpec, fit_window, initial, offset_identifiable};
        let fo = offset_identifiable(&test.dof);
        let init = initial::first_estimate(&test.dof, &test.t_s, &test.y, test.scale, 0, None, fo);
        let first = fit_window(
            &test,
            0,
            test.t_s.len(),
            &FitSpec::base(init.viscous, init.dry, fo),
            &init,
            &FitOptions::default(),
        )
        .unwrap();
        let r = &first.residual;
        println!(
            "first viscous {:.5} dry {:.5} rmse {:.5} LB {:.1} rmse/noise {:.4}",
            first.law.viscous,
            first.law.dry,
            first.rmse,
            pantowatch_models::stats::ljung_box(r, pantowatch_models::stats::LB_LAGS),
            first.rmse / pantowatch_models::stats::noise_sigma(r)
        );
        let t0 = Instant::now();
        let fit = fit_base(&test, &FitOptions::default()).unwrap();
        println!(
            "init viscous {:.5} dry {:.5}\nfit_base viscous {:.5} dry {:.5} rmse {:.5} restarts {} {:.1} ms",
            init.viscous,
            init.dry,
            fit.law.viscous,
            fit.law.dry,
            fit.rmse,
            fit.restarts,
            1e3 * t0.elapsed().as_secs_f64()
        );
        return;
    }
    if args.first().map(String::as_str) == Some("--driven") {
        // --driven SAMPLES: the bench's input-driven axis (`bench::scaling::driven_axis`, seed
        // 38) of that length, identified and then fitted with the residual loop.
        let samples: usize = args[1].parse().unwrap();
        let axis = pantowatch_models::synth::DrivenAxis {
            moving_mass_kg: 8.0,
            viscous: 204.0,
            normal_force_n: 40.8,
            dry: 0.5,
            input_offset_n: -3.2,
            force_n: 150.0,
            fs_hz: 1000.0,
            duration_s: (samples.max(2) - 1) as f64 / 1000.0,
            force_noise_n: 0.2,
            force_step_n: 0.05,
            position_noise_mm: 0.05,
            position_step_mm: 0.01,
            seed: 38,
        };
        let test = axis.record().unwrap();
        let opts = FitOptions::default();
        let t0 = Instant::now();
        let base = fit_base(&test, &opts).unwrap();
        let t_id = t0.elapsed().as_secs_f64();
        let b = pantowatch_models::testspec::Baseline {
            joint: "custom".into(),
            viscous: None,
            dry: None,
            viscous_unit: "N·s/m",
        };
        let t0 = Instant::now();
        let (result, fit, finding) = pantowatch_models::fit_joint_test_with_finding(
            &test,
            &b,
            &pantowatch_models::drift::DriftThresholds::default(),
            "probe",
            &opts,
        )
        .unwrap();
        let t_loop = t0.elapsed().as_secs_f64();
        println!(
            "identification {:.1} ms (viscous {:.6}, dry {:.6}, ev {}); with the loop {:.1} ms",
            1e3 * t_id,
            base.law.viscous,
            base.law.dry,
            base.evaluations,
            1e3 * t_loop
        );
        println!(
            "reported viscous {:.6} ± {:.3e} dry {:.6} ± {:.3e}; verdict {:?}",
            fit.law.viscous, fit.std[0], fit.law.dry, fit.std[1], result.residual
        );
        for c in &finding.candidates {
            println!(
                "  {:?} score {:?} rmse {:.6} holdout {:.6} accepted {} ({})",
                c.effects, c.score, c.rmse_fit, c.rmse_holdout, c.accepted, c.reason
            );
        }
        return;
    }
    if args.first().map(String::as_str) == Some("--measured-like") {
        measured_like();
        return;
    }
    let mut repeat = 5;
    let mut files = vec![];
    let mut i = 0;
    while i < args.len() {
        if args[i] == "--repeat" {
            repeat = args[i + 1].parse().unwrap();
            i += 2;
        } else {
            files.push(args[i].clone());
            i += 1;
        }
    }
    for p in files {
        let test = load(&p);
        let opts = FitOptions::default();
        let mut times = vec![];
        let mut last = None;
        for _ in 0..repeat {
            let t0 = Instant::now();
            let fit = fit_base(&test, &opts).expect("fit");
            times.push(t0.elapsed().as_secs_f64());
            last = Some(fit);
        }
        times.sort_by(f64::total_cmp);
        let fit = last.unwrap();
        let name = p.rsplit('/').next().unwrap();
        if std::env::var("PROBE_FIRST").is_ok() {
            use pantowatch_models::identify::{
                FitSpec, fit_window, initial, offset_identifiable, release_of,
            };
            let start = release_of(&test).unwrap().index;
            let fo = offset_identifiable(&test.dof);
            let init = initial::first_estimate(
                &test.dof,
                &test.t_s,
                &test.y,
                test.scale,
                start,
                test.initial_rate,
                fo,
            );
            let spec = FitSpec::base(init.viscous, init.dry, fo);
            let first =
                fit_window(&test, start, test.t_s.len() - start, &spec, &init, &opts).unwrap();
            println!(
                "   init {init:?}\n   first viscous {:.5} dry {:.5} rmse {:.5} ev {}",
                first.law.viscous, first.law.dry, first.rmse, first.evaluations
            );
        }
        if std::env::var("PROBE_FULL").is_ok() {
            println!("   full {:?} {:?} {}", fit.values, fit.std, fit.rmse);
        }
        let r = &fit.residual;
        println!(
            "   steps {} rhs {} events {} (last {:?}) LB {:.1} (critical {:.1}) rmse/noise {:.3}",
            fit.trajectory.n_steps,
            fit.trajectory.n_rhs,
            fit.trajectory.events.len(),
            fit.trajectory.events.last(),
            pantowatch_models::stats::ljung_box(r, pantowatch_models::stats::LB_LAGS),
            pantowatch_models::stats::whiteness_critical(),
            fit.rmse / pantowatch_models::stats::noise_sigma(r)
        );
        println!(
            "{name:<24} {:>8.2} ms  n {:>6} start {:>5}  viscous {:.6} ± {:.2e}  dry {:.6} ± {:.2e}  rmse {:.5}  it {} ev {} restarts {} {:?}",
            1e3 * times[times.len() / 2],
            test.t_s.len(),
            fit.start,
            fit.law.viscous,
            fit.std[0],
            fit.law.dry,
            fit.std[1],
            fit.rmse,
            fit.iterations,
            fit.evaluations,
            fit.restarts,
            fit.termination
        );
    }
}

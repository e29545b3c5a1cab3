//! Issue 36, point 2: the lift loop (`fit_lift_trace`: plain fit, the absorption check of
//! `lift::absorbed`, the vocabulary, the held-out test) on every protocol the service accepts,
//! with the stand's realistic sensor noise on every channel (× K), many seeds. One TSV line per
//! lift; `docs/VALIDATION.md` ("The lift loop on every protocol") states how the lines are
//! summed.
//!
//! `cargo run --release -p pantowatch-models --example lift_loop_probe -- PROTOCOL K FIRST SEEDS [CASE…]`
//!
//! PROTOCOL: `raise` (the paper's, `LiftProtocol::reference`), `rl` (raise and lower), `design`
//! (`design-test`'s moves: `design::rounds_of_moves` at 1.424 / 1.216 m, τ 1 s, dwell 2 s, one
//! round — the designed protocol of `lift::design::tests`). Noise seeds FIRST..FIRST+SEEDS.
//!
//! Cases (default: all). Clean: `clean`, `drift:J5.dry*1.4` (a joint drifted within the watch
//! band). In the vocabulary (`lift::effects`): `drag:<c_a>`, `delay:<ms>`, `offset:<mm>`,
//! `stribeck:<e>` at J3, `compliance:<k>` (c 50 N·m·s/rad, J_d 3 kg·m²). Outside it — physics
//! the vocabulary lacks; truth-only, made here or by the simulator's truth-only terms
//! (`LiftModel::friction_band`, `mass_kg`, `j9_stiffness_n_per_m_each`), never fitted:
//! - `band:<f>`: J3 dry × f over the middle third of the swept α range (position-dependent);
//! - `fade:<f>`: J3 dry × f over the upper half of the range (on a raise: friction fading
//!   during the test; on the other protocols position- not time-dependent);
//! - `headmass:<f>`: the head's mass × f (a head heavier than the type file states);
//! - `tgain:<%>`: the recorded drive torque reads % high (a torque-sensor gain error);
//! - `fsgain:<%>`: the recorded strip-spring force reads % high;
//! - `hback:<mm>`: H seen through a dead band of ± mm (play between strip and sensor);
//! - `j9stiff:<f>`: the head springs f × stiffer than the file (an elastic joint off its
//!   stated stiffness);
//! - `offj1:<mm>`: an H zero offset of mm together with a J1 dry ×2 drift.
//!
//! Columns: protocol k case class seed verdict named fired ratio plain_ratio flags level lo hi
//! truth secs final_ratio t1 t2 hlo hhi up down params check_phase evaluations steps work
//! (class: clean / vocab:<name> / oov; level: the J1+J3 level when reported; t1…down: the
//! reported model's H residual over the noise in the record's first and second half, below and
//! above the middle of its H range, rising and falling; params: the named effects' parameters,
//! JSON; then the absorption check's worst phase and its ratio; evaluations and integrator steps
//! of the whole loop, then per loop step `step=evaluations/steps`: `report::LiftReport::work`;
//! last, the candidates tried ahead on another thread and not judged, `spare:<effect>=…`, left
//! out of the totals). `lift_loop_compare.py BEFORE AFTER` compares two runs' decisions and work.
use pantowatch_models::drift::{DriftThresholds, Status};
use pantowatch_models::lift::dynamics::{DriveCompliance, FrictionBand, LiftModel};
use pantowatch_models::lift::geometry::builtin_160ec;
use pantowatch_models::lift::protocol::{LiftProtocol, record};
use pantowatch_models::lift::report::{LiftChannels, fit_lift_trace};
use pantowatch_models::lift::sensitivity::LiftParam;
use pantowatch_models::lift::sensors::LiftSensorNoise;
use pantowatch_models::lift::simulate::SimOptions;
use pantowatch_models::numerics::stats::noise_sigma;

const DEFAULT_CASES: [&str; 17] = [
    "clean",
    "drift:J5.dry*1.4",
    "drift:J2.dry*0.7",
    "drift:J1.dry*1.4",
    "drag:4",
    "delay:20",
    "offset:10",
    "stribeck:0.5",
    "compliance:8000",
    "band:1.3",
    "fade:0.7",
    "headmass:1.02",
    "tgain:2",
    "fsgain:2",
    "hback:2",
    "j9stiff:3",
    "offj1:5",
];

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let proto_name = args.first().cloned().unwrap_or_else(|| "rl".into());
    let k: f64 = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(1.0);
    let first: u64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(0);
    let seeds: u64 = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(2);
    let cases: Vec<String> = if args.len() > 4 {
        args[4..].to_vec()
    } else {
        DEFAULT_CASES.iter().map(|s| s.to_string()).collect()
    };
    let g = builtin_160ec();
    let base = LiftModel::new(g);
    let protocol = match proto_name.as_str() {
        "raise" => LiftProtocol::reference(g),
        "rl" => LiftProtocol::raise_and_lower(&base, g).unwrap(),
        "design" => {
            pantowatch_models::lift::design::rounds_of_moves(&base, g, &[1.424, 1.216], 1.0, 2.0, 1)
                .unwrap()
        }
        other => panic!("protocol {other}: raise, rl or design"),
    };
    // The α range the clean protocol sweeps (for `band` and `fade`).
    let (alo, ahi) = {
        let rec = record(&base, &protocol, &SimOptions::default()).unwrap();
        let (hmin, hmax) = rec
            .strip_height_m
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), h| {
                (a.min(*h), b.max(*h))
            });
        let a = |h: f64| {
            pantowatch_models::lift::statics::alpha_at_height(&base, h, 0.0, base.alpha_range_rad)
                .unwrap_or(0.0)
        };
        let (x, y) = (a(hmin), a(hmax));
        (x.min(y), x.max(y))
    };
    for case in &cases {
        let (name, arg) = case.split_once(':').unwrap_or((case.as_str(), "0"));
        let size: f64 = arg.parse().unwrap_or(0.0);
        let class = match name {
            "clean" | "drift" => "clean".to_string(),
            "drag" => "vocab:quadratic_drag".into(),
            "delay" => "vocab:sensor_delay".into(),
            "offset" => "vocab:sensor_offset".into(),
            "stribeck" => "vocab:stribeck".into(),
            "compliance" => "vocab:drive_compliance".into(),
            _ => "oov".into(),
        };
        let mut m = base.clone();
        // Truth factors of the J1 and J3 dry friction, for the J1+J3 level.
        let (mut j1, mut j3) = (1.0, 1.0);
        match name {
            "drift" => {
                let (jk, f) = arg.split_once('*').unwrap();
                let (j, kind) = jk.split_once('.').unwrap();
                let f: f64 = f.parse().unwrap();
                let p = LiftParam::named(j, kind).unwrap();
                let mut off = 0.0;
                p.set(&mut m, &mut off, p.get(&base, 0.0) * f);
                if kind == "dry" && j == "J1" {
                    j1 = f;
                }
                if kind == "dry" && j == "J3" {
                    j3 = f;
                }
            }
            "offj1" => {
                let p = LiftParam::named("J1", "dry").unwrap();
                let mut off = 0.0;
                p.set(&mut m, &mut off, p.get(&base, 0.0) * 2.0);
                j1 = 2.0;
            }
            "drag" => m.head_drag_ns2_per_m2 = size,
            "band" => {
                m.friction_band = Some(FrictionBand {
                    joint_index: 3,
                    alpha_lo_rad: alo + (ahi - alo) / 3.0,
                    alpha_hi_rad: alo + 2.0 * (ahi - alo) / 3.0,
                    factor: size,
                });
                j3 = f64::NAN;
            }
            "fade" => {
                m.friction_band = Some(FrictionBand {
                    joint_index: 3,
                    alpha_lo_rad: alo + (ahi - alo) / 2.0,
                    alpha_hi_rad: ahi + 1.0,
                    factor: size,
                });
                j3 = f64::NAN;
            }
            "compliance" => {
                m.drive_compliance = Some(DriveCompliance {
                    stiffness_nm_per_rad: size,
                    damping_nms_per_rad: 50.0,
                    inertia_kgm2: 3.0,
                })
            }
            "stribeck" => m.stribeck_excess[3] = size,
            "headmass" => m.mass_kg[6] *= size,
            "j9stiff" => m.j9_stiffness_n_per_m_each *= size,
            _ => {}
        }
        let clean = match record(&m, &protocol, &SimOptions::default()) {
            Ok(r) => r,
            Err(e) => {
                eprintln!("{case}: not simulated: {e}");
                continue;
            }
        };
        for seed in first..first + seeds {
            let mut rec = LiftSensorNoise::realistic()
                .scaled(k)
                .apply(&clean, 36_000 + seed);
            match name {
                "offset" | "offj1" => rec
                    .strip_height_m
                    .iter_mut()
                    .for_each(|h| *h += size * 1e-3),
                "delay" => {
                    let lag = (size * 1e-3 * protocol.sample_hz).round() as usize;
                    let h = rec.strip_height_m.clone();
                    for i in 0..h.len() {
                        rec.strip_height_m[i] = h[i.saturating_sub(lag)];
                    }
                }
                "tgain" => rec
                    .torque_nm
                    .iter_mut()
                    .for_each(|t| *t *= 1.0 + size / 100.0),
                "fsgain" => rec.fs_n.iter_mut().for_each(|f| *f *= 1.0 + size / 100.0),
                "hback" => {
                    // A play operator on the noise-free height, the sensor noise added after.
                    let b = size * 1e-3;
                    let mut out = clean.strip_height_m[0];
                    for (i, &h) in clean.strip_height_m.iter().enumerate() {
                        if h > out + b {
                            out = h - b;
                        } else if h < out - b {
                            out = h + b;
                        }
                        rec.strip_height_m[i] += out - h;
                    }
                }
                _ => {}
            }
            let ch = LiftChannels::from(&rec);
            let t0 = std::time::Instant::now();
            let rep = match fit_lift_trace(&ch, &DriftThresholds::default(), "probe") {
                Ok(r) => r,
                Err(e) => {
                    println!("{proto_name}\t{k}\t{case}\t{class}\t{seed}\terror\t{e}");
                    continue;
                }
            };
            let secs = t0.elapsed().as_secs_f64();
            let r = &rep.result;
            let verdict = if !r.residual.effects.is_empty() {
                "named"
            } else if r.residual.verdict.is_some() {
                "unexplained"
            } else {
                "clean"
            };
            let named: Vec<&str> = r.residual.effects.iter().map(|e| e.name.as_str()).collect();
            let flags: Vec<String> = r
                .joints
                .iter()
                .filter(|j| matches!(j.status, Status::Watch | Status::Alarm))
                .map(|j| format!("{}:{:?}", j.joint, j.status))
                .collect();
            for j in r
                .joints
                .iter()
                .filter(|j| matches!(j.status, Status::Watch | Status::Alarm))
            {
                eprintln!(
                    "{proto_name} {k} {case} {seed}: flagged {}; check free {:?}",
                    serde_json::to_string(j).unwrap_or_default(),
                    r.fit.absorption.as_ref().map(|a| &a.free)
                );
            }
            let check_phase = r.fit.absorption.as_ref().map_or("-\tNaN".to_string(), |a| {
                format!(
                    "{}\t{:.2}",
                    a.worst_phase.as_deref().unwrap_or("-").replace(' ', "_"),
                    a.worst_phase_ratio.unwrap_or(f64::NAN)
                )
            });
            let (fired, ratio, plain) = r
                .fit
                .absorption
                .as_ref()
                .map_or((false, f64::NAN, f64::NAN), |a| {
                    (a.fired, a.ratio, a.plain_ratio)
                });
            let level = r
                .combinations
                .iter()
                .find(|c| c.label == "J1+J3 dry" && c.identifiable);
            let (lv, lo, hi, truth) = match level {
                Some(c) => {
                    let truth: f64 = c
                        .members
                        .iter()
                        .map(|mb| {
                            mb.weight
                                * match mb.joint.as_str() {
                                    "J1" => j1,
                                    "J3" => j3,
                                    _ => 1.0,
                                }
                        })
                        .sum();
                    (c.value, c.ci95[0], c.ci95[1], truth)
                }
                None => (f64::NAN, f64::NAN, f64::NAN, f64::NAN),
            };
            // The reported model's residual by phase (over the noise, first differences,
            // floored at 0.7 mm): time halves, H below / above the swept range's middle, rising /
            // falling strip (the fitted H's speed).
            let phases = {
                let h = &rec.strip_height_m;
                let f = &rep.fitted_height_m;
                if f.len() == h.len() && h.len() > 4 {
                    let r: Vec<f64> = h.iter().zip(f).map(|(a, b)| a - b).collect();
                    let s = noise_sigma(&r).max(0.7e-3);
                    let n = r.len();
                    let (hmin, hmax) = f
                        .iter()
                        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                            (a.min(*v), b.max(*v))
                        });
                    let hmid = 0.5 * (hmin + hmax);
                    let v = pantowatch_models::lift::residual::speed(&rec.t_s, f);
                    let part = |sel: &dyn Fn(usize) -> bool| {
                        let (ss, c) = (0..n)
                            .filter(|&i| sel(i))
                            .fold((0.0, 0usize), |(ss, c), i| (ss + r[i] * r[i], c + 1));
                        if c < 50 {
                            f64::NAN
                        } else {
                            (ss / c as f64).sqrt() / s
                        }
                    };
                    format!(
                        "{:.2}\t{:.2}\t{:.2}\t{:.2}\t{:.2}\t{:.2}",
                        part(&|i| i < n / 2),
                        part(&|i| i >= n / 2),
                        part(&|i| f[i] < hmid),
                        part(&|i| f[i] >= hmid),
                        part(&|i| v[i] > 0.01),
                        part(&|i| v[i] < -0.01),
                    )
                } else {
                    "nan\tnan\tnan\tnan\tnan\tnan".into()
                }
            };
            let params = serde_json::to_string(
                &r.residual
                    .effects
                    .iter()
                    .map(|e| &e.params)
                    .collect::<Vec<_>>(),
            )
            .unwrap_or_default();
            // The loop's work (deterministic): evaluations, integrator steps, per step.
            // Candidates tried ahead on another thread and not judged (`spare:<effect>`) are
            // left out of the totals and listed last: the loop's own work is deterministic.
            let (spare, own): (Vec<_>, Vec<_>) =
                rep.work.iter().partition(|w| w.step.starts_with("spare:"));
            let evals: usize = own.iter().map(|w| w.work.evaluations).sum();
            let steps: usize = own.iter().map(|w| w.work.steps).sum();
            let per_step: Vec<String> = own
                .iter()
                .map(|w| format!("{}={}/{}", w.step, w.work.evaluations, w.work.steps))
                .collect();
            let spare: Vec<String> = spare
                .iter()
                .map(|w| format!("{}={}/{}", w.step, w.work.evaluations, w.work.steps))
                .collect();
            println!(
                "{proto_name}\t{k}\t{case}\t{class}\t{seed}\t{verdict}\t{}\t{fired}\t{ratio:.3}\t{plain:.3}\t{}\t{lv:.4}\t{lo:.4}\t{hi:.4}\t{truth:.4}\t{secs:.3}\t{:.3}\t{phases}\t{params}\t{check_phase}\t{evals}\t{steps}\t{}\t{}",
                if named.is_empty() {
                    "-".to_string()
                } else {
                    named.join(",")
                },
                if flags.is_empty() {
                    "-".to_string()
                } else {
                    flags.join(",")
                },
                r.residual.excess_ratio.unwrap_or(f64::NAN),
                per_step.join(";"),
                if spare.is_empty() {
                    "-".to_string()
                } else {
                    spare.join(";")
                },
            );
        }
    }
}

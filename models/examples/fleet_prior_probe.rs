//! What a fleet prior learned from workshop fits does to lift fits (issue 37, point 3).
//!
//! A fleet whose coefficients differ from Table 4: every friction coefficient's fleet mean is
//! Table 4 × exp(0.3 z) (z standard normal, fixed seed 5), each unit's Table 4 × mean × exp(τ z),
//! τ = `PW_SPREAD` (0.15 by default). The workshop has swung `PW_WORKSHOP` (30) other units:
//! each coefficient's estimate is its truth + N(0, 0.1²) in Table 4 units, its sd 0.1 (a
//! pendulum fit's interval; the lift does not enter). `lift::fleet_prior::learn` turns them into
//! the prior. Then SEEDS units are lifted (raise and lower, `LiftSensorNoise::realistic`: the
//! stand's noise on every channel) and fitted twice, under Table 4's prior and the learned
//! one: the J1+J3 level's coverage (its 95 % interval holds the unit's true level), false flags
//! (an informed entry or combination flagged watch/alarm while its truth is inside the watch
//! band), and the RMS error of the entries the lift does not inform (MAP / truth − 1: what the
//! unreported joints absorb). With `PW_DRAG` (N/(m/s)², default 0: none) every lifted unit
//! carries an undeclared head drag the fit does not model. `PW_PRIOR_SD_SCALE` (default 1)
//! widens every learned sd by that factor.
//!
//! `PW_SERVICE=1`: each lift is fitted as the service fits it (`report::fit_lift_trace_with`:
//! the residual loop and the reported-only absorption check after the plain fit), the learned
//! prior as the service hands it over (`FleetPrior::for_fit` with `[fleet_prior] fit_sd_scale`,
//! so `PW_PRIOR_SD_SCALE` is not used); the level, its coverage and the flags are read from the
//! contract's result (a withheld level counts as not reported), the unreported entries' error
//! from the plain fit, and the mean of `fit.absorption.ratio` (the refit with only the
//! reported parameters free, over the noise) with how often it fired.
//!
//! `cargo run --release -p pantowatch-models --example fleet_prior_probe -- [SEEDS] [FIRST]`

use pantowatch_models::data::builtin_160ec as type_160ec;
use pantowatch_models::drift::Status;
use pantowatch_models::lift::dynamics::LiftModel;
use pantowatch_models::lift::fleet_prior::{WorkshopEstimate, learn, prior_params};
use pantowatch_models::lift::geometry::builtin_160ec;
use pantowatch_models::lift::identify::{LiftFit, LiftFitOptions, fit_map};
use pantowatch_models::lift::protocol::{LiftProtocol, record};
use pantowatch_models::lift::report::{LiftChannels, fit_lift_trace_with};
use pantowatch_models::lift::sensitivity::LiftParam;
use pantowatch_models::lift::sensors::LiftSensorNoise;
use pantowatch_models::lift::simulate::SimOptions;
use pantowatch_models::lift::topology::RevJoint;
use pantowatch_models::numerics::noise::Noise;
use pantowatch_models::report::CombinationResult;

fn env_f(name: &str, default: f64) -> f64 {
    std::env::var(name)
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(default)
}

/// Running totals for one prior.
#[derive(Default)]
struct Tally {
    level_n: usize,
    level_hit: usize,
    level_half_width: f64,
    level_err_sq: f64,
    false_flags: usize,
    uninformed_sq: f64,
    uninformed_n: usize,
    failed: usize,
    /// `fit.absorption.ratio` (service path): sum, count, fired.
    absorption_sum: f64,
    absorption_n: usize,
    absorption_fired: usize,
    /// Lifts whose level was withheld or not reported (service path).
    level_missing: usize,
}

fn main() {
    let mut args = std::env::args().skip(1);
    let seeds: u64 = args.next().and_then(|s| s.parse().ok()).unwrap_or(20);
    let first: u64 = args.next().and_then(|s| s.parse().ok()).unwrap_or(0);
    let spread = env_f("PW_SPREAD", 0.15);
    let n_workshop = env_f("PW_WORKSHOP", 30.0) as usize;
    let drag = env_f("PW_DRAG", 0.0);
    let g = builtin_160ec();
    let base = LiftModel::new(g);
    let params = prior_params();
    let mut rng = Noise::new(5);
    let fleet_mean: Vec<f64> = params.iter().map(|_| (0.3 * rng.normal()).exp()).collect();
    let unit = |rng: &mut Noise| -> Vec<f64> {
        fleet_mean
            .iter()
            .map(|m| m * (spread * rng.normal()).exp())
            .collect()
    };
    // The workshop's fits of other units.
    let mut rng = Noise::new(50_000);
    let mut est = Vec::new();
    for _ in 0..n_workshop {
        let theta = unit(&mut rng);
        for (p, t) in params.iter().zip(&theta) {
            est.push(WorkshopEstimate {
                param: *p,
                ratio: t + 0.1 * rng.normal(),
                sd_ratio: 0.1,
            });
        }
    }
    let mut prior = learn(&est, type_160ec().fleet_prior());
    // `PW_PRIOR_SD_SCALE` (default 1): every learned sd multiplied by this (a wider prior).
    let sd_scale = env_f("PW_PRIOR_SD_SCALE", 1.0);
    for p in &mut prior.params {
        p.sd_ratio *= sd_scale;
    }
    let service = std::env::var("PW_SERVICE").is_ok_and(|v| v == "1");
    // The service's prior: learned sds × `fit_sd_scale`, floored ones as they are (learned
    // before the probe's own widening, which the service path does not use).
    let service_prior = {
        let unscaled = learn(&est, type_160ec().fleet_prior());
        unscaled.for_fit(type_160ec().fleet_prior().fit_sd_scale)
    };
    let plain = LiftFitOptions::default();
    let learned = LiftFitOptions::default().with_fleet_prior(&prior);
    let protocol = LiftProtocol::raise_and_lower(&base, g).unwrap();
    let w = plain.thresholds.watch;
    let inside = |level: f64| w[0] < level && level < w[1];
    let flagged = |s: Status| matches!(s, Status::Watch | Status::Alarm);
    let mut tallies = [Tally::default(), Tally::default()];
    for seed in first..first + seeds {
        let mut rng = Noise::new(90_000 + seed);
        let theta = unit(&mut rng);
        let mut m = base.clone();
        for (p, t) in params.iter().zip(&theta) {
            let mut off = 0.0;
            let v = p.get(&base, 0.0) * t;
            p.set(&mut m, &mut off, v);
        }
        m.head_drag_ns2_per_m2 = drag;
        let relative = |p: LiftParam| p.get(&m, 0.0) / p.get(&base, 0.0);
        let clean = record(&m, &protocol, &SimOptions::default()).unwrap();
        let rec = LiftSensorNoise::realistic().apply(&clean, 1000 + seed);
        if service {
            let channels = LiftChannels::from(&rec);
            for (tally, fp) in tallies.iter_mut().zip([&[][..], &service_prior[..]]) {
                let rep = match fit_lift_trace_with(&channels, &plain.thresholds, "probe", fp) {
                    Ok(r) => r,
                    Err(e) => {
                        println!("seed {seed}: fit failed {e:?}");
                        tally.failed += 1;
                        continue;
                    }
                };
                let r = &rep.result;
                if let Some(a) = &r.fit.absorption {
                    tally.absorption_sum += a.ratio;
                    tally.absorption_n += 1;
                    tally.absorption_fired += usize::from(a.fired);
                }
                let is_level = |c: &CombinationResult| {
                    ["J1", "J3"]
                        .iter()
                        .all(|j| c.members.iter().any(|m| m.joint == *j && m.kind == "dry"))
                };
                let truth_of = |c: &CombinationResult| -> f64 {
                    c.members
                        .iter()
                        .filter_map(|m| {
                            LiftParam::named(&m.joint, &m.kind).map(|p| m.weight * relative(p))
                        })
                        .sum()
                };
                let mut level_seen = false;
                for c in r.combinations.iter().filter(|c| c.identifiable) {
                    let truth = truth_of(c);
                    if is_level(c) {
                        level_seen = true;
                        tally.level_n += 1;
                        tally.level_half_width += 0.5 * (c.ci95[1] - c.ci95[0]);
                        tally.level_err_sq += (c.value - truth).powi(2);
                        if c.ci95[0] <= truth && truth <= c.ci95[1] {
                            tally.level_hit += 1;
                        }
                    }
                    if flagged(c.status) && inside(truth) {
                        tally.false_flags += 1;
                    }
                }
                tally.level_missing += usize::from(!level_seen);
                for j in &r.joints {
                    for (kind, p) in [("viscous", &j.viscous), ("dry", &j.dry)] {
                        let Some(q) = LiftParam::named(&j.joint, kind) else {
                            continue;
                        };
                        if p.identifiable
                            && p.combination.is_none()
                            && flagged(p.status)
                            && inside(relative(q))
                        {
                            tally.false_flags += 1;
                        }
                    }
                }
                for e in rep.fit.params.iter().filter(|e| !e.informed) {
                    if params.contains(&e.param) {
                        let err = e.map_value / e.param.get(&m, 0.0) - 1.0;
                        tally.uninformed_sq += err * err;
                        tally.uninformed_n += 1;
                    }
                }
            }
            continue;
        }
        for (tally, opts) in tallies.iter_mut().zip([&plain, &learned]) {
            let fit: LiftFit = match fit_map(&base, &[rec.trace()], opts) {
                Ok(f) => f,
                Err(e) => {
                    println!("seed {seed}: fit failed {e:?}");
                    tally.failed += 1;
                    continue;
                }
            };
            let j13 = [LiftParam::Dry(RevJoint::J1), LiftParam::Dry(RevJoint::J3)];
            for c in fit.combinations.iter().filter(|c| c.informed) {
                let truth = c.level_of(relative);
                if j13.iter().all(|p| c.params.contains(p)) {
                    tally.level_n += 1;
                    tally.level_half_width += 0.5 * (c.ci95[1] - c.ci95[0]);
                    tally.level_err_sq += (c.value - truth).powi(2);
                    if c.ci95[0] <= truth && truth <= c.ci95[1] {
                        tally.level_hit += 1;
                    }
                }
                if flagged(c.status) && inside(truth) {
                    tally.false_flags += 1;
                }
            }
            for e in &fit.params {
                if e.informed {
                    if flagged(e.status) && inside(relative(e.param)) {
                        tally.false_flags += 1;
                    }
                } else if params.contains(&e.param) {
                    let err = e.map_value / e.param.get(&m, 0.0) - 1.0;
                    tally.uninformed_sq += err * err;
                    tally.uninformed_n += 1;
                }
            }
        }
    }
    println!(
        "fleet: {} coefficients, spread {spread}, workshop {n_workshop} units; lifts {seeds} from seed {first}; head drag {drag}, learned sd × {}{}",
        params.len(),
        if service {
            type_160ec().fleet_prior().fit_sd_scale
        } else {
            sd_scale
        },
        if service {
            " (service path: fit_lift_trace_with)"
        } else {
            ""
        }
    );
    for (name, t) in ["Table 4 prior", "learned prior"].iter().zip(&tallies) {
        println!(
            "{name:<14} J1+J3 level coverage {}/{} = {:.1} % (mean half-width {:.3}, RMS error {:.3}), false flags {}, uninformed RMS error {:.3} (Table 4 units, {} entries), failed {}",
            t.level_hit,
            t.level_n,
            100.0 * t.level_hit as f64 / t.level_n.max(1) as f64,
            t.level_half_width / t.level_n.max(1) as f64,
            (t.level_err_sq / t.level_n.max(1) as f64).sqrt(),
            t.false_flags,
            (t.uninformed_sq / t.uninformed_n.max(1) as f64).sqrt(),
            t.uninformed_n,
            t.failed
        );
        if service {
            println!(
                "{:<14} absorption ratio mean {:.3} over {} lifts, fired {}; level withheld or not reported {}",
                "",
                t.absorption_sum / t.absorption_n.max(1) as f64,
                t.absorption_n,
                t.absorption_fired,
                t.level_missing
            );
        }
    }
}

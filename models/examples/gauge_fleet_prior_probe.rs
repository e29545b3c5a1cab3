//! What a fleet prior learned from workshop fits does to force-gauge fits (issue 37, point 3):
//! the gauge analogue of `fleet_prior_probe`.
//!
//! The fleet is `fleet_prior_probe`'s (the same draws): every friction coefficient's fleet mean
//! is Table 4 × exp(0.3 z) (z standard normal, seed 5), each unit's Table 4 × mean × exp(τ z),
//! τ = `PW_SPREAD` (0.15); the workshop has swung `PW_WORKSHOP` (30) other units, each
//! coefficient's estimate its truth + N(0, 0.1²) in Table 4 units with sd 0.1. The learned prior
//! is handed over as the service does (`FleetPrior::for_fit` with `[fleet_prior] fit_sd_scale`).
//! Then SEEDS units are measured with the force gauge (15 readings up and 15 down the working
//! range, `GaugeSimOptions::default()`: 0.2 N white noise, 0.1 N resolution) and each record is
//! fitted as the service fits it (`fit_gauge_trace_with`: the residual loop, the contract
//! result), under Table 4's prior and the learned one. Tallied: the coverage of the reported
//! level holding J1 and J3 (its 95 % interval holds the unit's true level, Σ w_j θ_j/θ_j⁰ over
//! its members), its mean half-width and RMS error, false flags (an identifiable entry or
//! combination flagged watch or alarm while its truth is inside the watch band), and the RMS
//! error of the dry μ the record does not inform (MAP / truth − 1: what those joints absorb).
//! `PW_RATE` (default 1): every unit's drive slope × this (a spring rate the fit does not know;
//! the residual loop may name it); `PW_OFFSET_N` (default 0): a gauge zero error, N.
//!
//! `cargo run --release -p pantowatch-models --example gauge_fleet_prior_probe -- [SEEDS] [FIRST]`

use pantowatch_models::data::builtin_160ec as type_160ec;
use pantowatch_models::drift::{DriftThresholds, Status};
use pantowatch_models::lift::dynamics::LiftModel;
use pantowatch_models::lift::fleet_prior::{WorkshopEstimate, learn, prior_params};
use pantowatch_models::lift::gauge::fit::FITTED_JOINTS;
use pantowatch_models::lift::gauge::{
    DriveLine, GaugeChannels, GaugeSimOptions, fit_gauge_trace_with, reading_heights,
    simulate_gauge,
};
use pantowatch_models::lift::geometry::builtin_160ec;
use pantowatch_models::lift::sensitivity::LiftParam;
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
    /// Records whose level was withheld or not reported.
    level_missing: usize,
    /// Records whose residual loop named an effect.
    named: usize,
    /// Per fitted joint (`FITTED_JOINTS` order): Σ (MAP / truth − 1)² and count, uninformed.
    per_joint: [(f64, usize); 7],
}

fn main() {
    let mut args = std::env::args().skip(1);
    let seeds: u64 = args.next().and_then(|s| s.parse().ok()).unwrap_or(50);
    let first: u64 = args.next().and_then(|s| s.parse().ok()).unwrap_or(0);
    let spread = env_f("PW_SPREAD", 0.15);
    let n_workshop = env_f("PW_WORKSHOP", 30.0) as usize;
    let rate = env_f("PW_RATE", 1.0);
    let offset_n = env_f("PW_OFFSET_N", 0.0);
    let g = builtin_160ec();
    let base = LiftModel::new(g);
    let drive = DriveLine::from_lift_test(g);
    let ar = (g.alpha_min_rad, g.alpha_max_rad);
    let params = prior_params();
    // The fleet and the workshop exactly as `fleet_prior_probe` draws them.
    let mut rng = Noise::new(5);
    let fleet_mean: Vec<f64> = params.iter().map(|_| (0.3 * rng.normal()).exp()).collect();
    let unit = |rng: &mut Noise| -> Vec<f64> {
        fleet_mean
            .iter()
            .map(|m| m * (spread * rng.normal()).exp())
            .collect()
    };
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
    let settings = type_160ec().fleet_prior();
    let learned = learn(&est, settings).for_fit(settings.fit_sd_scale);
    let thresholds = DriftThresholds::default();
    let w = thresholds.watch;
    let inside = |level: f64| w[0] < level && level < w[1];
    let flagged = |s: Status| matches!(s, Status::Watch | Status::Alarm);
    let heights = reading_heights(15);
    let mut tallies = [Tally::default(), Tally::default()];
    for seed in first..first + seeds {
        // The lift probe's unit draws (its seeds 90 000 + seed): the same units.
        let mut rng = Noise::new(90_000 + seed);
        let theta = unit(&mut rng);
        let mut m = base.clone();
        for (p, t) in params.iter().zip(&theta) {
            let mut off = 0.0;
            let v = p.get(&base, 0.0) * t;
            p.set(&mut m, &mut off, v);
        }
        let relative = |p: LiftParam| p.get(&m, 0.0) / p.get(&base, 0.0);
        let opts = GaugeSimOptions {
            seed: 3000 + seed,
            offset_n,
            spring_rate_factor: rate,
            ..GaugeSimOptions::default()
        };
        let rec = match simulate_gauge(&m, ar, &drive, &heights, &opts) {
            Ok(r) => r,
            Err(e) => {
                println!("seed {seed}: record not simulated: {e}");
                continue;
            }
        };
        let channels = GaugeChannels {
            strip_height_m: &rec.heights_m,
            force_n: &rec.forces_n,
            resolution_n: rec.resolution_n,
        };
        for (tally, fp) in tallies.iter_mut().zip([&[][..], &learned[..]]) {
            let rep = match fit_gauge_trace_with(&channels, &thresholds, "probe", fp) {
                Ok(r) => r,
                Err(e) => {
                    println!("seed {seed}: fit failed {e:?}");
                    tally.failed += 1;
                    continue;
                }
            };
            let r = &rep.result;
            tally.named += usize::from(!r.residual.effects.is_empty());
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
                let Some(q) = LiftParam::named(&j.joint, "dry") else {
                    continue;
                };
                let p = &j.dry;
                if p.identifiable
                    && p.combination.is_none()
                    && flagged(p.status)
                    && inside(relative(q))
                {
                    tally.false_flags += 1;
                }
            }
            for (i, e) in rep
                .fit
                .params
                .iter()
                .enumerate()
                .filter(|(_, e)| !e.informed)
            {
                let err = e.map_value / e.param.get(&m, 0.0) - 1.0;
                tally.uninformed_sq += err * err;
                tally.uninformed_n += 1;
                tally.per_joint[i].0 += err * err;
                tally.per_joint[i].1 += 1;
            }
        }
    }
    println!(
        "fleet: {} coefficients, spread {spread}, workshop {n_workshop} units; gauge records {seeds} from seed {first}; spring rate × {rate}, gauge zero {offset_n} N; learned sd × {} (service path: fit_gauge_trace_with)",
        params.len(),
        settings.fit_sd_scale
    );
    for (name, t) in ["Table 4 prior", "learned prior"].iter().zip(&tallies) {
        println!(
            "{name:<14} J1+J3 level coverage {}/{} = {:.1} % (mean half-width {:.3}, RMS error {:.3}), false flags {}, uninformed RMS error {:.3} (Table 4 units, {} entries), level withheld or not reported {}, effect named {}, failed {}",
            t.level_hit,
            t.level_n,
            100.0 * t.level_hit as f64 / t.level_n.max(1) as f64,
            t.level_half_width / t.level_n.max(1) as f64,
            (t.level_err_sq / t.level_n.max(1) as f64).sqrt(),
            t.false_flags,
            (t.uninformed_sq / t.uninformed_n.max(1) as f64).sqrt(),
            t.uninformed_n,
            t.level_missing,
            t.named,
            t.failed
        );
        let per: Vec<String> = FITTED_JOINTS
            .iter()
            .zip(&t.per_joint)
            .map(|(j, (sq, n))| format!("{} {:.3}", j.name(), (sq / (*n).max(1) as f64).sqrt()))
            .collect();
        println!(
            "{:<14} uninformed RMS error per joint: {}",
            "",
            per.join(", ")
        );
    }
}

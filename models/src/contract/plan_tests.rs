//! The plan's ranking against the truth of a simulated fleet (issue 37, point 2).
//!
//! The fleet (parameter level, not traces): every joint parameter of the built-in 160EC's Table 4
//! on `n` pantographs; one in ten wears linearly at 0.5–2.5 × baseline per year (up) from 0–182 days
//! before its last test, the rest stay at baseline — a mixture, not the plan's normal rate model. Each parameter's last
//! workshop test is 0–365 days old and read it with noise sd `MEAS_REL` × baseline (95 %
//! interval ± 1.96 sd). A swing of a joint informs both its parameters as that test did. Truth:
//! a parameter its last test judged `ok` now past the watch band (crossed unseen).

use super::*;
use crate::contract::drift::Status;
use crate::contract::evidence::{Belief, WearRate};
use crate::data::builtin_160ec;
use crate::numerics::noise::Noise;

/// A workshop test's sd, relative to baseline [assumed for this simulation].
const MEAS_REL: f64 = 0.05;
/// The fleet rate the plan assumes: the data file's `fleet_wear_sd_per_year`.
fn fleet_sd_per_year() -> f64 {
    builtin_160ec()
        .test_plan
        .as_ref()
        .expect("[test_plan]")
        .fleet_wear_sd_per_year
}

struct Sim {
    /// Per candidate (pantograph, joint): options and params, truth, age.
    options: Vec<(usize, TestOption)>,
    params: Vec<Vec<ParamNow>>,
    crossed: Vec<(usize, String)>,
    oldest: Vec<(usize, String, f64)>,
}

fn simulate(n: usize, seed: u64) -> Sim {
    let th = DriftThresholds::default();
    let data = builtin_160ec();
    let mut rng = Noise::new(seed);
    let mut sim = Sim {
        options: Vec::new(),
        params: Vec::new(),
        crossed: Vec::new(),
        oldest: Vec::new(),
    };
    for k in 0..n {
        let mut params = Vec::new();
        for (name, j) in &data.joints {
            let mut informs = Vec::new();
            let mut crossed = false;
            let mut age_max: f64 = 0.0;
            for (param, b) in [("viscous", j.viscous_baseline()), ("dry", j.dry_mu)] {
                let rate_per_day = if rng.uniform() < 0.1 {
                    (0.5 + 2.0 * rng.uniform()) * b / 365.25
                } else {
                    0.0
                };
                let age = 365.0 * rng.uniform();
                // Up to half a year of wear before the test: the value then.
                let then = b + rate_per_day * 182.0 * rng.uniform();
                let now = then + rate_per_day * age;
                let sd = MEAS_REL * b;
                let read = then + sd * rng.normal();
                let belief =
                    Belief::new(read, sd).widened(age, &WearRate::fleet(b, fleet_sd_per_year()));
                // What the test showed then (the drift thresholds' verdict on its interval).
                let seen = th
                    .judge([read - 1.96 * sd, read + 1.96 * sd], read, Some(b))
                    .status;
                // Truth: crossed since, unseen (past watch now, not shown as such then).
                crossed |= seen == Status::Ok && (now > th.watch[1] * b || now < th.watch[0] * b);
                age_max = age_max.max(age);
                params.push(ParamNow {
                    joint: name.clone(),
                    param: param.into(),
                    baseline: b,
                    belief,
                    seen,
                });
                informs.push(Informs {
                    joint: name.clone(),
                    param: param.into(),
                    info: 1.0 / (sd * sd),
                });
            }
            if crossed {
                sim.crossed.push((k, name.clone()));
            }
            sim.oldest.push((k, name.clone(), age_max));
            sim.options.push((
                k,
                TestOption {
                    kind: "pendulum".into(),
                    joint: Some(name.clone()),
                    informs,
                },
            ));
        }
        sim.params.push(params);
    }
    sim
}

/// Precision at k (k = the number truly crossed) of the plan's fleet ranking and of
/// "oldest evidence first".
fn precision(sim: &Sim) -> (f64, f64, usize) {
    let th = DriftThresholds::default();
    let mut ranked: Vec<(usize, PlanItem)> = sim
        .options
        .iter()
        .flat_map(|(k, o)| {
            rank(&sim.params[*k], std::slice::from_ref(o), &th)
                .into_iter()
                .map(move |i| (*k, i))
        })
        .collect();
    ranked.sort_by(|a, b| b.1.buys.total_cmp(&a.1.buys));
    let k = sim.crossed.len();
    let hit = |s: usize, j: &str| sim.crossed.iter().any(|(c, cj)| *c == s && cj == j);
    let plan_hits = ranked
        .iter()
        .take(k)
        .filter(|(s, i)| hit(*s, i.joint.as_deref().unwrap_or("")))
        .count();
    let mut oldest = sim.oldest.clone();
    oldest.sort_by(|a, b| b.2.total_cmp(&a.2));
    let old_hits = oldest.iter().take(k).filter(|(s, j, _)| hit(*s, j)).count();
    (plan_hits as f64 / k as f64, old_hits as f64 / k as f64, k)
}

#[test]
fn the_plan_finds_the_joints_that_crossed_unseen_better_than_oldest_first() {
    // 5 seeds × 200 pantographs × 8 joints.
    let mut worst_plan: f64 = 1.0;
    for seed in 1..=5 {
        let sim = simulate(200, seed);
        let (plan, oldest, k) = precision(&sim);
        let base = k as f64 / sim.oldest.len() as f64;
        eprintln!(
            "seed {seed}: {k} crossed ({base:.3}); top-k precision plan {plan:.3}, oldest-first {oldest:.3}"
        );
        assert!(k > 20, "{k}");
        assert!(
            plan > oldest + 0.1,
            "seed {seed}: plan {plan:.3} oldest {oldest:.3}"
        );
        assert!(
            plan > 2.0 * base,
            "seed {seed}: plan {plan:.3} base rate {base:.3}"
        );
        worst_plan = worst_plan.min(plan);
    }
    assert!(worst_plan >= 0.2, "{worst_plan}");
}

#[test]
fn a_test_that_cannot_see_the_joint_or_a_joint_that_cannot_have_crossed_buys_nothing() {
    let th = DriftThresholds::default();
    let p = |joint: &str, mean: f64, sd: f64| ParamNow {
        joint: joint.into(),
        param: "dry".into(),
        baseline: 1.0,
        belief: Belief::new(mean, sd),
        seen: Status::Ok,
    };
    let params = vec![p("J5", 1.45, 0.1), p("J1", 1.0, 0.02), p("J3", 1.0, 0.3)];
    let swing = |j: &str, info: f64| TestOption {
        kind: "pendulum".into(),
        joint: Some(j.into()),
        informs: vec![Informs {
            joint: j.into(),
            param: "dry".into(),
            info,
        }],
    };
    let ranked = rank(
        &params,
        &[
            swing("J1", 2500.0),
            swing("J3", 400.0),
            swing("J5", 400.0),
            swing("J7", 1.0),
        ],
        &th,
    );
    let order: Vec<_> = ranked
        .iter()
        .map(|i| i.joint.clone().unwrap_or_default())
        .collect();
    // J5 near its watch band first; J3 (wide, could be anywhere) next; J1 (tight at baseline)
    // last; J7 is not a parameter here and is left out.
    assert_eq!(order, ["J5", "J3", "J1"]);
    assert!(ranked[2].buys < 1e-6, "{}", ranked[2].buys);
    assert!(
        ranked[0].p_watch > 0.3 && ranked[0].p_alarm < 0.01,
        "{:?}",
        ranked[0]
    );
    assert!(ranked.iter().all(|i| i.info_bits > 0.0));
    // A joint whose last test already showed `alarm` has nothing unseen to find.
    let mut shown = params.clone();
    shown[0].seen = Status::Alarm;
    let r = rank(&shown, &[swing("J5", 400.0)], &th);
    assert!(r[0].buys == 0.0 && r[0].p_watch > 0.3, "{:?}", r[0]);
    // A test with no information on what it names buys nothing and is left out.
    assert!(rank(&params, &[swing("J5", 0.0)], &th).is_empty());
}

#[test]
fn the_one_band_p_unseen_is_the_two_band_one_bit_for_bit() {
    let th = DriftThresholds::default();
    let mut checked = 0;
    for seen in [Status::Unknown, Status::Ok, Status::Watch, Status::Alarm] {
        for mean in [0.0, 0.5, 0.9, 1.0, 1.2, 1.6, 2.5, f64::NAN] {
            for sd in [0.0, 1e-3, 0.05, 0.3, 2.0, f64::NAN] {
                let baseline = 0.2;
                let b = Belief::new(mean * baseline, sd * baseline);
                let two = p_unseen_of(seen, p_past(&b, baseline, &th));
                let one = p_unseen_at(&b, baseline, seen, &th);
                assert_eq!(
                    one.to_bits(),
                    two.to_bits(),
                    "{seen:?} {b:?}: {one} against {two}"
                );
                checked += 1;
            }
        }
    }
    assert_eq!(checked, 4 * 8 * 6);
    // Not a constant: a parameter at the watch band's edge is past it about half the time.
    let edge = Belief::new(th.watch[1] * 0.2, 0.01);
    assert!((p_unseen_at(&edge, 0.2, Status::Ok, &th) - 0.5).abs() < 1e-9);
}

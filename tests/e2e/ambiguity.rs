//! Issue 36, point 3: the single-joint loop says ambiguity. A restoring torque beside gravity (a
//! torsion spring in the joint: outside the vocabulary) shifts a pendulum's period like an
//! inertia error at small swings and differently at large ones; the loop must not name it
//! `inertia_error` with confidence (it says `unexplained`, or `ambiguous` with both explanations
//! and the test that separates them), while a true inertia error is still named. Simulated
//! pendulums at the stand's noise (0.05° white plus the logger's 0.01° steps), many seeds.

use pantowatch_models::data::builtin_160ec;
use pantowatch_models::drift::Status;
use pantowatch_models::identify::Readout;
use pantowatch_models::report::FitResult;
use pantowatch_models::rig::PendulumRig;
use pantowatch_models::synth::Truth;

use crate::residual::{base, fit, names, pendulum_test_with_inertia};

/// m·g·d of the paper's rig for `joint`, N·m.
fn mgd(joint: &str) -> f64 {
    let r = PendulumRig::paper_default(builtin_160ec(), joint).unwrap();
    r.mass_kg * r.gravity_m_s2 * r.com_distance_m
}

#[derive(Debug, PartialEq)]
enum Outcome {
    Named(Vec<String>),
    Ambiguous(Vec<String>),
    Unexplained,
    Clean,
}

fn outcome(r: &FitResult) -> Outcome {
    match r.residual.verdict.as_deref() {
        Some("ambiguous") => {
            let a = r.residual.ambiguity.as_ref().expect("ambiguity block");
            assert!(a.explanations.len() >= 2, "{a:?}");
            assert!(!a.separating_test.is_empty(), "{a:?}");
            Outcome::Ambiguous(a.explanations.iter().map(|e| e.name.clone()).collect())
        }
        Some(v) => {
            assert_eq!(v, "unexplained");
            // What the loop cannot name is no wear finding: every status withheld.
            assert!(r.residual.joints_withheld.is_some(), "{:?}", r.residual);
            for j in &r.joints {
                assert_eq!(j.status, Status::Unknown, "{}: {j:?}", j.joint);
                assert!(!j.identifiable && !j.viscous.identifiable && !j.dry.identifiable);
            }
            Outcome::Unexplained
        }
        None => {
            let n: Vec<String> = names(r)
                .into_iter()
                .filter(|n| n != "sensor_offset")
                .collect();
            if n.is_empty() {
                Outcome::Clean
            } else {
                Outcome::Named(n)
            }
        }
    }
}

/// One simulated release: `spring` × m·g·d of torsion, inertia × `inertia`.
fn run(joint: &str, release_deg: f64, spring: f64, inertia: f64, seed: u64) -> FitResult {
    let truth = Truth {
        law: base(joint),
        readout: Readout::default(),
        dry_fade: 0.0,
    };
    let (test, b) = pendulum_test_with_inertia(
        joint,
        &truth,
        release_deg,
        spring * mgd(joint),
        inertia,
        seed,
    );
    fit(&test, &b)
}

/// The measurement behind docs/VALIDATION.md's ambiguity table (run by hand:
/// `cargo test -p pantowatch-e2e --test e2e probe_ambiguity_rates -- --ignored --nocapture`).
#[test]
#[ignore]
fn probe_ambiguity_rates() {
    let seeds: u64 = std::env::var("SEEDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(4);
    let mut tally = std::collections::BTreeMap::<String, [usize; 5]>::new();
    let cases: Vec<(&str, f64, f64, f64)> = [
        ("J1", 0.01),
        ("J3", 0.02),
        ("J5", 0.05),
        ("J3", 0.05),
        ("J1", 0.10),
    ]
    .into_iter()
    .flat_map(|(j, k)| [30.0, 60.0, 90.0].map(move |a| (j, a, k, 1.0)))
    .chain(
        [("J1", 1.02), ("J3", 0.98), ("J5", 1.03), ("J3", 1.01)]
            .into_iter()
            .flat_map(|(j, r)| [30.0, 60.0, 90.0].map(move |a| (j, a, 0.0, r))),
    )
    .collect();
    for (i, (joint, angle, spring, inertia)) in cases.into_iter().enumerate() {
        let kind = if spring > 0.0 {
            format!("spring {spring}×mgd")
        } else {
            "inertia".to_owned()
        };
        for s in 0..seeds {
            let r = run(joint, angle, spring, inertia, 1000 + 37 * i as u64 + s);
            let o = outcome(&r);
            eprintln!(
                "{kind} {joint} {angle}° r {inertia} seed {s}: {o:?} rmse {:.4} -> {:.4} halves {:?}",
                r.residual.rmse_before,
                r.residual.rmse_after,
                r.residual.halves.as_ref().map(|h| (
                    h.early_explained_share,
                    h.late_explained_share,
                    h.holds
                ))
            );
            let t = tally.entry(kind.clone()).or_default();
            let inertia_named =
                matches!(&o, Outcome::Named(n) if n.iter().any(|x| x == "inertia_error"));
            match o {
                _ if inertia_named => t[0] += 1,
                Outcome::Named(_) => t[1] += 1,
                Outcome::Ambiguous(_) => t[2] += 1,
                Outcome::Unexplained => t[3] += 1,
                Outcome::Clean => t[4] += 1,
            }
        }
    }
    for (k, t) in &tally {
        eprintln!(
            "{k}: inertia_error named {}, other named {}, ambiguous {}, unexplained {}, clean {}",
            t[0], t[1], t[2], t[3], t[4]
        );
    }
}

/// A torsion spring of 2–10 % of the rig's gravitational stiffness on J1, J3 and J5, released
/// from 30° to 90°, 3 seeds each (J5 at 30° with 5 %: the case a coarse stiffness search named
/// `inertia_error`): never `inertia_error` with confidence; when ambiguous, the
/// restoring torque is one of the explanations and the separating test names another angle.
#[test]
fn a_restoring_torque_is_never_named_inertia_error_with_confidence() {
    let mut wrong = Vec::new();
    let mut seen = Vec::new();
    for (i, (joint, angle, spring)) in [
        ("J1", 30.0, 0.02),
        ("J3", 60.0, 0.05),
        ("J5", 90.0, 0.10),
        ("J3", 90.0, 0.02),
        ("J5", 30.0, 0.05),
    ]
    .into_iter()
    .enumerate()
    {
        for s in 0..3u64 {
            let r = run(joint, angle, spring, 1.0, 500 + 10 * i as u64 + s);
            let o = outcome(&r);
            if let Outcome::Ambiguous(n) = &o {
                assert!(n.iter().any(|x| x == "restoring_torque"), "{n:?}");
                let a = r.residual.ambiguity.as_ref().unwrap();
                assert!(a.separating_test.contains("Release the same rig"), "{a:?}");
            }
            if let Outcome::Named(n) = &o {
                wrong.push(format!(
                    "{joint} {angle}° {spring}×mgd seed {s}: named {n:?}"
                ));
            }
            seen.push(format!("{joint} {angle}° {spring}: {o:?}"));
        }
    }
    assert!(wrong.is_empty(), "{wrong:#?}\nall: {seen:#?}");
    // The withholding `outcome` checks is exercised here, not only allowed.
    let unexplained = seen.iter().filter(|s| s.ends_with("Unexplained")).count();
    assert!(
        unexplained >= 3,
        "unexplained {unexplained} of 15: {seen:#?}"
    );
}

/// A true inertia error of 2–3 % on J1, J3, J5 from 30° to 90°, 3 seeds each, is still named
/// `inertia_error` — at least 10 of 12, the rest ambiguous with the restoring torque, never
/// another effect named.
#[test]
fn a_true_inertia_error_is_still_named() {
    let (mut named, mut other) = (0, Vec::new());
    for (i, (joint, angle, ratio)) in [
        ("J1", 60.0, 1.02),
        ("J3", 30.0, 0.98),
        ("J5", 90.0, 1.03),
        ("J3", 90.0, 1.02),
    ]
    .into_iter()
    .enumerate()
    {
        for s in 0..3u64 {
            let r = run(joint, angle, 0.0, ratio, 700 + 10 * i as u64 + s);
            match outcome(&r) {
                Outcome::Named(n) if n == ["inertia_error"] => named += 1,
                Outcome::Ambiguous(n) if n.iter().any(|x| x == "inertia_error") => {}
                o => other.push(format!("{joint} {angle}° ×{ratio} seed {s}: {o:?}")),
            }
        }
    }
    assert!(other.is_empty(), "{other:#?}");
    assert!(named >= 10, "named in {named} of 12");
}

/// The pooled loop's ties (issue 36, point 3, across recordings): models that pass every rule
/// with pooled BICs within 10 of each other tie and none is named; one standing 10 or more
/// below the next, or failing a rule, does not tie.
#[test]
fn pooled_models_that_pass_with_equal_bic_tie() {
    use pantowatch_models::residual::Effect;
    use pantowatch_models::residual::pooled::{PooledCandidate, tied};
    let c = |e: Effect, delta_bic: f64, accepted: bool| PooledCandidate {
        effects: vec![e],
        delta_bic,
        rmse: vec![0.05, 0.05],
        explained_share: vec![0.99, 0.99],
        remainder_over_noise: vec![1.0, 1.0],
        plausible: true,
        accepted,
        reason: String::new(),
    };
    let cands = vec![
        c(Effect::Stribeck, -400.0, true),
        c(Effect::PositionFriction, -395.0, true),
        c(Effect::QuadraticDrag, -390.0, true),
        c(Effect::InertiaError, -399.0, false),
    ];
    assert_eq!(tied(&cands), [0, 1]);
    let alone = vec![
        c(Effect::Stribeck, -400.0, true),
        c(Effect::PositionFriction, -389.0, true),
    ];
    assert!(tied(&alone).is_empty());
    assert!(tied(&[c(Effect::Stribeck, -400.0, true)]).is_empty());
    assert!(tied(&[]).is_empty());
}

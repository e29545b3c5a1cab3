use super::*;
use crate::lift::geometry::builtin_160ec;
use crate::lift::protocol::{LiftProtocol, LiftRecord, record};
use crate::numerics::noise::Noise;

fn noisy(rec: &LiftRecord, seed: u64) -> Vec<f64> {
    let mut rng = Noise::new(seed);
    rec.strip_height_m
        .iter()
        .map(|h| h + 1e-3 * rng.normal())
        .collect()
}

fn sd_of(fit: &LiftFit, p: LiftParam) -> (f64, bool) {
    let e = fit.params.iter().find(|e| e.param == p).unwrap();
    (e.posterior_sd, e.informed)
}

/// Issue 5: several lift tests of one pantograph fitted together narrow the intervals.
/// Three raise-and-lower tests (independent 1 mm noise) against one: the data part of the
/// Fisher information triples, so a data-dominated parameter's sd shrinks by up to √3; the
/// prior (sd 0.5 × baseline) holds the shrinkage below that for the weakly informed ones.
#[test]
fn pooled_raise_and_lower_tests_narrow_the_intervals() {
    let g = builtin_160ec();
    let m = LiftModel::new(g);
    let mut worn = m.clone();
    worn.friction.dry_mu[RevJoint::J3.index()] *= 1.8;
    let p = LiftProtocol::raise_and_lower(&m, g).unwrap();
    let rec = record(&worn, &p, &SimOptions::default()).unwrap();
    let hs: Vec<Vec<f64>> = (0..3).map(|s| noisy(&rec, 11 + s)).collect();
    let traces: Vec<LiftTrace> = hs
        .iter()
        .map(|h| LiftTrace {
            inputs: rec.inputs(),
            strip_height_m: h,
        })
        .collect();
    let opts = LiftFitOptions::default();
    let one = fit_map(&m, &traces[..1], &opts).unwrap();
    let clock = std::time::Instant::now();
    let three = fit_map(&m, &traces, &opts).unwrap();
    eprintln!("pooled fit of 3: {:?}", clock.elapsed());
    for e in &three.params {
        let (sd1, i1) = sd_of(&one, e.param);
        eprintln!(
            "{:>3}.{:<7} sd 1 test {:.3e} ({}) 3 tests {:.3e} ({}) ratio {:.3}",
            e.param.joint(),
            e.param.kind(),
            sd1,
            if i1 { "informed" } else { "-" },
            e.posterior_sd,
            if e.informed { "informed" } else { "-" },
            sd1 / e.posterior_sd
        );
    }
    // Data-dominated parameters narrow by close to √3.
    for param in [LiftParam::Dry(RevJoint::J5), LiftParam::J8Dry] {
        let ((sd1, i1), (sd3, i3)) = (sd_of(&one, param), sd_of(&three, param));
        let prior = three
            .params
            .iter()
            .find(|e| e.param == param)
            .unwrap()
            .prior_sd;
        assert!(
            sd1 < prior / 2.0 && sd3 < prior / 2.0,
            "{param:?} contracted by one test and by three"
        );
        let _ = (i1, i3);
        assert!(
            sd1 / sd3 >= 2f64.sqrt() * 0.8,
            "{param:?}: sd {sd1} with one test, {sd3} with three"
        );
    }
    // J1 and J3 dry move H alike (correlation ≈ −1): repeating the same test pins their
    // combination harder, but each one's marginal sd is held by the prior on the other.
    for param in [LiftParam::Dry(RevJoint::J1), LiftParam::Dry(RevJoint::J3)] {
        let ((sd1, _), (sd3, _)) = (sd_of(&one, param), sd_of(&three, param));
        assert!(
            sd3 < sd1,
            "{param:?}: sd {sd1} with one test, {sd3} with three"
        );
    }
    // The best-determined combination of the friction parameters (scaled by baseline):
    // its sd shrinks by ≈ √3.
    let best = |f: &LiftFit| {
        let n = f.params.len();
        let cov = DMatrix::from_fn(n, n, |i, j| {
            let (a, b) = (&f.params[i], &f.params[j]);
            f.posterior_correlation[(i, j)] * a.posterior_sd * b.posterior_sd
                / (a.baseline * b.baseline)
        });
        cov.symmetric_eigenvalues().min().sqrt()
    };
    let (b1, b3) = (best(&one), best(&three));
    eprintln!(
        "best-determined combination: sd {b1:.3e} → {b3:.3e}, ratio {:.3}",
        b1 / b3
    );
    assert!(b1 / b3 >= 3f64.sqrt() * 0.9, "{b1} → {b3}");
    // No posterior widens with more data.
    for e in &three.params {
        assert!(
            e.posterior_sd <= sd_of(&one, e.param).0 * 1.02,
            "{:?}",
            e.param
        );
    }
    // J3 dry ×1.8 is flagged in the entry holding it (alone or J1+J3) by one
    // raise-and-lower test and by three, and no other joint is.
    for fit in [&one, &three] {
        let shown = fit
            .shown_in(LiftParam::Dry(RevJoint::J3))
            .expect("J3 dry shown");
        assert!(shown.flagged(), "{shown:?}");
        for j in fit.joints.iter().filter(|j| j.joint != "J3") {
            assert!(!j.flagged(), "{} flagged: {:?}", j.joint, j.status);
        }
    }
}

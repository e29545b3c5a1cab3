//! Tests of issue 39, point 5 (beside `tests`, whose helpers they use): the gauge's level
//! interval against its spread over noise draws, and a named spring rate in the static-force
//! prediction from the record's fit result.

use super::effects::fit_with_effects;
use super::fit::FITTED_JOINTS;
use super::tests::{drifted, record, setup, true_level};
use super::*;
use crate::contract::drift::DriftThresholds;
use crate::lift::geometry::builtin_160ec;
use crate::lift::static_force::MuEstimate;
use crate::lift::topology::RevJoint;

/// Issue 39, point 5: the level's interval is calibrated — over 120 noise draws at the stated
/// gauge (σ 0.2 N, 0.1 N steps; seeds 1000–1119), its reported sd is within 25 % of the level's
/// spread and its interval holds the truth on 90–98 % of the records, at Table 4 and with J5 ×2
/// (a joint the J1+J3 level of old left out, whose prior made the interval 2.9× the spread:
/// `fit::level_min_share`). The members are the same on every record. Measured: Table 4 spread
/// 0.0024, sd 0.0027 (ratio 1.14), 116/120; J5 ×2 ratio 1.13, 116/120; the rest of the
/// excess is the noise floor (κ 1.04 on average: σ̂ is floored at σ₀) and t at ~27 dof (2.05).
#[test]
fn the_level_interval_matches_its_spread_over_noise_draws() {
    let (base, drive, ar) = setup();
    for drift in [vec![], vec![(RevJoint::J5, 2.0)]] {
        let truth = drifted(&base, &drift);
        let opts = GaugeFitOptions::default();
        let (mut rel, mut sd, mut covered) = (Vec::new(), Vec::new(), 0);
        let mut labels = std::collections::BTreeSet::new();
        for seed in 1000..1120 {
            let rec = record(&truth, seed, 0.0, 1.0);
            let lp = fit_with_effects(&base, ar, &drive, &rec, &opts).unwrap();
            assert_eq!(lp.verdict, GaugeVerdict::None, "{drift:?} seed {seed}");
            assert_eq!(lp.fit.combinations.len(), 1, "{drift:?} seed {seed}");
            let c = &lp.fit.combinations[0];
            let level = true_level(c, &truth, &base);
            labels.insert(c.label());
            rel.push(c.value / level);
            sd.push(c.posterior_sd / level);
            covered += usize::from(c.ci95[0] <= level && level <= c.ci95[1]);
        }
        let n = rel.len() as f64;
        let mean = rel.iter().sum::<f64>() / n;
        let spread = (rel.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        let reported = sd.iter().sum::<f64>() / n;
        let coverage = covered as f64 / n;
        eprintln!(
            "{drift:?} {labels:?}: level/truth {mean:.4}, spread {spread:.4}, reported sd \
             {reported:.4} (ratio {:.2}), coverage {covered}/{n}",
            reported / spread
        );
        assert_eq!(labels.len(), 1, "{drift:?}: {labels:?}");
        assert!(
            (reported / spread - 1.0).abs() <= 0.25,
            "{drift:?}: reported sd {reported:.4} against spread {spread:.4}"
        );
        assert!(
            (0.90..=0.98).contains(&coverage),
            "{drift:?}: coverage {covered}/{n}"
        );
        assert!(
            (mean - 1.0).abs() < 2.0 * spread,
            "{drift:?}: biased {mean}"
        );
    }
}

/// Measurement probe (ignored; issue 39): the old J1+J3 level's variance at Table 4 split into
/// what the data leave of it with the other joints known and what the other joints' prior adds,
/// against the level along the whole direction. Measured (seed 1000): J1+J3 posterior sd 0.0364,
/// others known 0.0028, the MAP's spread over noise 0.0118; the whole direction's sd and spread
/// both 0.0025.
#[test]
#[ignore]
fn probe_level_variance_parts() {
    use nalgebra::{DMatrix, DVector};
    let (base, drive, ar) = setup();
    let rec = record(&base, 1000, 0.0, 1.0);
    let f0 = predicted_forces_n(&base, ar, &drive, &rec).unwrap();
    let n = rec.len();
    let pf = FITTED_JOINTS.len();
    let sigma = 0.2;
    let mut g = DMatrix::zeros(n, pf + 1);
    for (i, j) in FITTED_JOINTS.iter().enumerate() {
        let mut m = base.clone();
        m.friction.dry_mu[j.index()] *= 1.0 + 1e-4;
        let f = predicted_forces_n(&m, ar, &drive, &rec).unwrap();
        for k in 0..n {
            g[(k, i)] = (f[k] - f0[k]) / 1e-4 / sigma;
        }
    }
    for k in 0..n {
        g[(k, pf)] = 1.0 / sigma;
    }
    let a = g.tr_mul(&g);
    let s = 0.5;
    let mut post = a.clone();
    for i in 0..pf {
        post[(i, i)] += 1.0 / (s * s);
    }
    post[(pf, pf)] += 1.0 / 100.0;
    let cov = post.clone().try_inverse().unwrap();
    // The data's information on the friction, b marginalised, and its leading direction.
    let ff = cov
        .view((0, 0), (pf, pf))
        .into_owned()
        .try_inverse()
        .unwrap()
        - DMatrix::identity(pf, pf) / (s * s);
    let eig = ff.clone().symmetric_eigen();
    let k = eig.eigenvalues.imax();
    let v = eig.eigenvectors.column(k).into_owned();
    eprintln!(
        "leading direction {:?}, eigenvalue {:.1} (sd {:.4})",
        v.as_slice(),
        eig.eigenvalues[k],
        1.0 / eig.eigenvalues[k].sqrt()
    );
    let (i1, i3) = (0, 3);
    let sum = v[i1] + v[i3];
    let w = [v[i1] / sum, v[i3] / sum];
    let mut wv = DVector::zeros(pf + 1);
    wv[i1] = w[0];
    wv[i3] = w[1];
    let full = (wv.transpose() * &cov * &wv)[(0, 0)].sqrt();
    // The others known: only J1, J3 and b fitted.
    let idx = [i1, i3, pf];
    let sub = DMatrix::from_fn(3, 3, |r, c| post[(idx[r], idx[c])]);
    let subc = sub.try_inverse().unwrap();
    let w3 = DVector::from_vec(vec![w[0], w[1], 0.0]);
    let known = (w3.transpose() * &subc * &w3)[(0, 0)].sqrt();
    // The MAP's spread over noise at the truth = the prior mean: Σ A Σ.
    let spread = (wv.transpose() * (&cov * &a * &cov) * &wv)[(0, 0)].sqrt();
    // The whole direction's level (all seven weights) and its posterior sd.
    let vsum: f64 = v.iter().sum();
    let mut wall = DVector::zeros(pf + 1);
    for i in 0..pf {
        wall[i] = v[i] / vsum;
    }
    let all_sd = (wall.transpose() * &cov * &wall)[(0, 0)].sqrt();
    let all_spread = (wall.transpose() * (&cov * &a * &cov) * &wall)[(0, 0)].sqrt();
    eprintln!(
        "J1+J3 weights {w:?}: posterior sd {full:.4}, others known {known:.4}, MAP spread over noise {spread:.4}; all-joint level weights {:?}: sd {all_sd:.4}, spread {all_spread:.4}",
        wall.as_slice()
    );
}

/// Each revolute joint's dry μ as the service takes it from one fit result
/// (`services::static_force::current_mu`): an informed combination moves its members to level ×
/// Table 4 with the level's interval, a separately identified joint takes its own.
fn mu_of(
    result: &crate::contract::report::FitResult,
) -> [MuEstimate; crate::lift::topology::N_REV] {
    let g = builtin_160ec();
    let mut mu: [MuEstimate; crate::lift::topology::N_REV] = std::array::from_fn(|i| MuEstimate {
        value: g.revolute[i].dry_mu,
        ci95: None,
    });
    for j in result.joints.iter().filter(|j| j.dry.identifiable) {
        let members: Vec<RevJoint> = j
            .joint
            .split('+')
            .filter_map(|n| RevJoint::ALL.into_iter().find(|r| r.name() == n))
            .collect();
        for r in &members {
            let b = g.revolute[r.index()].dry_mu;
            let k = if members.len() > 1 { b } else { 1.0 };
            mu[r.index()] = MuEstimate {
                value: j.dry.value * k,
                ci95: Some([j.dry.ci95[0] * k, j.dry.ci95[1] * k]),
            };
        }
    }
    mu
}

/// Issue 39, point 5: a gauge record of a spring 0.85× the type's rate (seeds 700–702) names
/// `spring_rate`, and the static-force prediction from its fit result takes it: the true curve
/// (Table 4 friction, k 0.85) lies inside the predicted band at ≥ 90 % of the 28 heights ×
/// branches (measured 28/28, worst 0.03–0.15 N). With the type's spring (what it did before)
/// the truth is inside at 2 of 28, 7.0 N off (6 of 28 in the issue, with the wider J1+J3 band).
#[test]
fn a_named_spring_rate_flows_into_the_static_force_prediction() {
    use crate::lift::static_force::{RateEstimate, predict_rated};
    let g = builtin_160ec();
    let data = crate::data::builtin_160ec().static_force.as_ref().unwrap();
    let (base, _, _) = setup();
    let table4: [MuEstimate; crate::lift::topology::N_REV] = std::array::from_fn(|i| MuEstimate {
        value: g.revolute[i].dry_mu,
        ci95: None,
    });
    let truth = predict_rated(
        g,
        data,
        &table4,
        &RateEstimate {
            factor: 0.85,
            ci95: None,
        },
    )
    .unwrap()
    .curve;
    let inside = |p: &crate::lift::static_force::StaticForceCurve| {
        (0..truth.heights_m.len())
            .map(|i| {
                usize::from(
                    p.raise_lo_n[i] <= truth.raise_n[i] && truth.raise_n[i] <= p.raise_hi_n[i],
                ) + usize::from(
                    p.lower_lo_n[i] <= truth.lower_n[i] && truth.lower_n[i] <= p.lower_hi_n[i],
                )
            })
            .sum::<usize>()
    };
    let n = 2 * truth.heights_m.len();
    for seed in 700..703 {
        let rec = record(&base, seed, 0.0, 0.85);
        let report = fit_gauge_trace(
            &GaugeChannels {
                strip_height_m: &rec.heights_m,
                force_n: &rec.forces_n,
                resolution_n: rec.resolution_n,
            },
            &DriftThresholds::default(),
            "spring",
        )
        .unwrap();
        let rate = spring_rate_of(&report.result).expect("spring_rate named");
        let mu = mu_of(&report.result);
        let rated = predict_rated(g, data, &mu, &rate).unwrap().curve;
        let typed = predict_rated(g, data, &mu, &RateEstimate::TYPE)
            .unwrap()
            .curve;
        let worst = (0..truth.heights_m.len())
            .map(|i| {
                (rated.raise_n[i] - truth.raise_n[i])
                    .abs()
                    .max((rated.lower_n[i] - truth.lower_n[i]).abs())
            })
            .fold(0.0, f64::max);
        let worst_typed = (0..truth.heights_m.len())
            .map(|i| (typed.raise_n[i] - truth.raise_n[i]).abs())
            .fold(0.0, f64::max);
        eprintln!(
            "seed {seed}: k {:.4} {:?}; truth inside {}/{n} (type's spring {}/{n}); worst {worst:.2} N (type's {worst_typed:.2} N)",
            rate.factor,
            rate.ci95,
            inside(&rated),
            inside(&typed)
        );
        assert!(
            rate.ci95.is_some_and(|[lo, hi]| lo <= 0.85 && 0.85 <= hi),
            "seed {seed}: {rate:?}"
        );
        assert!(
            10 * inside(&rated) >= 9 * n,
            "seed {seed}: {}/{n}",
            inside(&rated)
        );
        assert!(
            2 * inside(&typed) < n,
            "seed {seed}: the type's spring fits too"
        );
        assert!(worst < 1.0 && worst_typed > 3.0, "seed {seed}");
    }
}

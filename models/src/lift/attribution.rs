//! What a lift separates and what it only informs together (issue 15, point 2): friction
//! parameters a test cannot tell apart are reported as the combination the data pin down.
//!
//! A joint's friction enters H through its reaction force and rate ratio, and several joints'
//! dry coefficients move H almost alike (J1 and J3 at the lower arm). With a Table 4 prior the
//! MAP then puts a drift of the less visible joint into the more visible one, with a narrow
//! interval that holds only if the other joint is at baseline: a J1 ×3 drift read as J3 +25 %.
//!
//! Rule (stated), in scaled units (each coefficient over its Table 4 baseline; prior sd
//! `prior_sd[i]` per parameter — alike for all in a lift fit, the fleet's per joint in a gauge
//! fit; along a unit direction v the prior's sd is √Σ v_i² prior_sd_i²):
//! - the directions the data pin are the eigenvectors v of the data's information on the
//!   friction parameters with the torque offsets marginalised, Λ = (Σ_ff)⁻¹ − P⁻¹, from the
//!   posterior of the H data alone (deterministic given the inputs; the input-noise draws only
//!   widen intervals). A direction is informed when its eigenvalue gives a posterior sd of at
//!   most prior sd / `informed_factor` along it;
//! - a parameter with a squared component of at least [`AttributionOptions::min_share`] in an
//!   informed direction that has another such member is *not separately identified*: it is
//!   reported at baseline with the prior's interval, `unknown`, never flagged, and named in the
//!   direction's [`Combination`] — the level wᵀx with w = v/Σv (1 = every member at baseline),
//!   its interval log-normal from the full posterior (input noise included), informed when its
//!   relative sd is under ‖w‖·prior sd / `informed_factor`, judged against 1 by the drift bands.
//!   A drift of any member shows in the level by its weight;
//! - a parameter alone in its informed direction is separately identified if its own
//!   contraction test passes (`lift::identify`);
//! - a direction whose components differ in sign is a contrast, no level a depot can judge: its
//!   members stay not separately identified and no combination is reported;
//! - what a test informs is a property of the test at the prior's mean, not only of the
//!   estimate ([`AtTable4`]): where the fit ran the model at Table 4 (its first evaluation, no
//!   extra cost), a direction or a single parameter counts as informed only if the data's
//!   information there informs it too. Where that run failed (the recorded torque drives the
//!   Table 4 model into a stiff corner: a lift far from baseline), nothing beyond the
//!   best-informed direction — the friction level that moved the lift, which every raise and
//!   lower informs at Table 4 (`lift::design`: J3 dry Fisher sd 0.032) — is reported as
//!   informed. Measured (issue 15, point 2, `examples/lift_coverage`): on J3 dry ×0.4 lifts,
//!   whose Table 4 run fails, a viscous direction (J2, J2′, J3, J5 viscous with J4 dry),
//!   uninformed at Table 4, read anywhere in 0–3.5 × baseline from seed to seed (two basins)
//!   with a linearised interval of ±8–12 %: false watches and alarms at σ_H 0.5–0.6 mm. The
//!   cost: a drift that a test informs only once it has happened stays `unknown`, never a flag.

use nalgebra::DMatrix;

use super::dynamics::LiftModel;
pub use super::fit::{AttributionOptions, Combination};
use super::fit::{LiftFit, ParamEstimate};
use super::sensitivity::LiftParam;
use crate::contract::drift::{DriftThresholds, Status};
use crate::numerics::stats::Z95;

/// What the fit knows of the data's information at Table 4 and zero offsets (module doc).
#[derive(Debug, Clone, Copy)]
pub enum AtTable4<'a> {
    /// The posterior covariance from the H data there and the prior (scaled units, the
    /// friction block first, like `cov_h`).
    Posterior(&'a DMatrix<f64>),
    /// The model did not run there: only the best-informed direction may be reported.
    RunFailed,
    /// Not evaluated (a refit from a given start; a gauge fit): the estimate's alone decides.
    NotEvaluated,
}

/// The outcome: per parameter whether it is separately identified, and the combinations.
#[derive(Debug, Clone, PartialEq)]
pub struct Attribution {
    /// Per friction parameter (fit order): contracted and uncorrelated.
    pub separate: Vec<bool>,
    /// Per friction parameter: the index of its combination, if it is in one.
    pub group: Vec<Option<usize>>,
    pub combinations: Vec<Combination>,
}

/// Attribute a fit's friction parameters. `x` are the MAP values, `cov_h` the posterior
/// covariance from the H data and the prior alone (its friction block's directions are
/// deterministic given the inputs) and `cov` the full one (input noise added, for the
/// intervals), all in scaled units with the friction block first (`params.len()` rows);
/// `table4` what is known of the information at Table 4; `contracted[i]` is the contraction
/// test on `cov`; `prior_sd` each friction parameter's scaled prior sd (fit order).
#[allow(clippy::too_many_arguments)]
pub fn attribute(
    params: &[LiftParam],
    x: &[f64],
    cov_h: &DMatrix<f64>,
    table4: AtTable4,
    cov: &DMatrix<f64>,
    contracted: &[bool],
    prior_sd: &[f64],
    informed_factor: f64,
    thresholds: &DriftThresholds,
    opts: &AttributionOptions,
) -> Attribution {
    let p = params.len();
    // Informed at Table 4 too (module doc): a single parameter by the contraction test there
    // (scaled units: the estimate is 1), a direction by the data's information along it.
    let (cov4, lambda4) = match table4 {
        AtTable4::Posterior(c) => (Some(c), data_information(c, p, prior_sd)),
        _ => (None, None),
    };
    let failed = matches!(table4, AtTable4::RunFailed);
    let at_table4 =
        |i: usize| cov4.is_none_or(|c| c[(i, i)].sqrt() < prior_sd[i] / informed_factor);
    let mut separate: Vec<bool> = (0..p).map(|i| contracted[i] && at_table4(i)).collect();
    let mut group = vec![None; p];
    let mut combinations = Vec::new();
    // The data's information on the friction parameters, the torque offsets marginalised:
    // Λ = (Σ_ff)⁻¹ − P⁻¹. Its eigenvectors are the directions the data pin.
    let Some(lambda) = data_information(cov_h, p, prior_sd) else {
        return Attribution {
            separate,
            group,
            combinations,
        };
    };
    // No friction parameter free (a refit with only the offsets: `absorbed::judge`): nothing to
    // attribute, and nalgebra's eigen-decomposition panics on an empty matrix.
    if lambda.nrows() == 0 {
        return Attribution {
            separate,
            group,
            combinations,
        };
    }
    let eig = lambda.symmetric_eigen();
    let mut order: Vec<usize> = (0..p).collect();
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    // Informed along v: the data's information there (eigenvalue, H noise only) at least
    // that of a posterior sd of prior sd / factor — (factor² − 1)/prior sd² along v.
    let needed =
        |v: &nalgebra::DVector<f64>| (informed_factor.powi(2) - 1.0) / prior_var(v, prior_sd);
    if let Some(&k0) = order.first().filter(|_| failed) {
        // Only the best-informed direction's members may stay separately identified.
        let lead = eig.eigenvectors.column(k0);
        for (i, s) in separate.iter_mut().enumerate() {
            *s &= lead[i] * lead[i] >= opts.min_share;
        }
    }
    for (rank, k) in order.into_iter().enumerate() {
        let v = eig.eigenvectors.column(k).into_owned();
        let members: Vec<usize> = (0..p).filter(|&i| v[i] * v[i] >= opts.min_share).collect();
        let needed = needed(&v);
        if eig.eigenvalues[k].is_nan() || eig.eigenvalues[k] < needed {
            continue;
        }
        let uninformed_at_table4 = match &lambda4 {
            // NaN counts as uninformed.
            Some(l4) => v
                .dot(&(l4 * &v))
                .partial_cmp(&needed)
                .is_none_or(|o| o.is_lt()),
            None => failed && rank > 0,
        };
        if uninformed_at_table4 {
            // Informed only at the estimate: no combination; its members keep their own
            // (gated) tests.
            continue;
        }
        if members.len() < 2 {
            continue; // one parameter alone: its own contraction test decides
        }
        for &i in &members {
            separate[i] = false;
        }
        if members.iter().any(|&i| group[i].is_some()) {
            continue; // already reported in a better-informed combination
        }
        let sum: f64 = members.iter().map(|&i| v[i]).sum();
        let w: Vec<f64> = members.iter().map(|&i| v[i] / sum).collect();
        if !sum.is_finite() || sum.abs() < 1e-9 || w.iter().any(|c| *c < 0.0) {
            // A contrast (one member up, another down) is no level a depot can judge: the
            // members stay not separately identified, and no combination is invented.
            continue;
        }
        let level: f64 = members.iter().zip(&w).map(|(&i, wi)| wi * x[i]).sum();
        let var: f64 = members
            .iter()
            .zip(&w)
            .map(|(&a, wa)| {
                members
                    .iter()
                    .zip(&w)
                    .map(|(&b, wb)| wa * cov[(a, b)] * wb)
                    .sum::<f64>()
            })
            .sum();
        let post_sd = var.max(0.0).sqrt();
        let prior = match uniform(prior_sd) {
            Some(s) => w.iter().map(|c| c * c).sum::<f64>().sqrt() * s,
            None => members
                .iter()
                .zip(&w)
                .map(|(&i, c)| (c * prior_sd[i]).powi(2))
                .sum::<f64>()
                .sqrt(),
        };
        // As for a single coefficient (`identify::fit_map_in`): contracted both in Table 4
        // units and on ln(level), sd < prior sd / factor × min(level, 1). A level pushed to
        // several times its baseline with a relative sd that looks small is not informed.
        let informed = level > 0.0 && post_sd < prior / informed_factor * level.min(1.0);
        let ci95 = if level > 0.0 {
            let rel = post_sd / level;
            [level * (-Z95 * rel).exp(), level * (Z95 * rel).exp()]
        } else {
            // Every member at the zero bound: a level is never negative, so the interval
            // starts at 0 (it is not informed: `level > 0` fails above).
            [0.0, level.max(0.0) + Z95 * post_sd]
        };
        let status = if informed {
            thresholds.judge(ci95, level, Some(1.0)).status
        } else {
            Status::Unknown
        };
        for &i in &members {
            group[i] = Some(combinations.len());
        }
        combinations.push(Combination {
            params: members.iter().map(|&i| params[i]).collect(),
            weights: w,
            value: level,
            posterior_sd: post_sd,
            prior_sd: prior,
            ci95,
            informed,
            status,
        });
    }
    Attribution {
        separate,
        group,
        combinations,
    }
}

/// The prior sd when every parameter has the same (a lift fit's): the rules then read exactly
/// as with one scalar.
fn uniform(prior_sd: &[f64]) -> Option<f64> {
    let s = *prior_sd.first()?;
    prior_sd.iter().all(|v| *v == s).then_some(s)
}

/// The prior's variance along the unit vector `v`: Σ v_i² prior_sd_i² (prior_sd² when uniform).
fn prior_var(v: &nalgebra::DVector<f64>, prior_sd: &[f64]) -> f64 {
    match uniform(prior_sd) {
        Some(s) => s * s,
        None => v.iter().zip(prior_sd).map(|(c, s)| (c * s).powi(2)).sum(),
    }
}

/// The data's information on the first `p` (friction) parameters of a posterior covariance
/// with the prior sd `prior_sd[i]` on each: Λ = (Σ_ff)⁻¹ − P⁻¹, symmetrised; `None` if singular.
fn data_information(cov: &DMatrix<f64>, p: usize, prior_sd: &[f64]) -> Option<DMatrix<f64>> {
    let mut lambda = cov.view((0, 0), (p, p)).into_owned().try_inverse()?;
    for i in 0..p {
        lambda[(i, i)] -= 1.0 / (prior_sd[i] * prior_sd[i]);
    }
    Some((&lambda + lambda.transpose()) * 0.5)
}

impl LiftFit {
    /// The entry a parameter's drift shows in (issue 15): the parameter itself when separately
    /// identified, else the informed combination it is a member of; `None` when neither.
    pub fn shown_in(&self, param: LiftParam) -> Option<Shown<'_>> {
        let e = self.params.iter().find(|e| e.param == param)?;
        if e.informed {
            return Some(Shown::Alone(e));
        }
        let c = self.combinations.get(e.combination?)?;
        c.informed.then_some(Shown::In(c))
    }
}

/// Where a parameter's drift shows: see [`LiftFit::shown_in`].
#[derive(Debug, Clone, Copy)]
pub enum Shown<'a> {
    Alone(&'a ParamEstimate),
    In(&'a Combination),
}

impl Shown<'_> {
    pub fn status(&self) -> Status {
        match self {
            Shown::Alone(e) => e.status,
            Shown::In(c) => c.status,
        }
    }

    pub fn flagged(&self) -> bool {
        matches!(self.status(), Status::Watch | Status::Alarm)
    }

    /// Whether the 95 % interval holds the truth of a model `truth` (fitted from `base`): the
    /// parameter's value, or the combination's level of `truth`'s members over `base`'s.
    pub fn covers(&self, truth: &LiftModel, base: &LiftModel) -> bool {
        match self {
            Shown::Alone(e) => {
                let v = e.param.get(truth, 0.0);
                e.ci95[0] <= v && v <= e.ci95[1]
            }
            Shown::In(c) => {
                let v = c.level_of(|p| p.get(truth, 0.0) / p.get(base, 0.0));
                c.ci95[0] <= v && v <= c.ci95[1]
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lift::topology::RevJoint;

    /// Two parameters the data pin only as a sum (posterior correlation ≈ −1) form one
    /// combination whose level is the data's weighted mean; a third, well separated, stays
    /// separate; a fourth, at its prior, is neither.
    #[test]
    fn correlated_parameters_are_reported_as_their_combination() {
        // Scaled units, prior sd 0.5. Data: 4·x1 + x3 known to ±0.05 and x8 to ±0.05.
        let prior = 0.5_f64;
        let a = nalgebra::DVector::from_vec(vec![4.0, 1.0, 0.0, 0.0]);
        let mut info = a.clone() * a.transpose() / 0.05_f64.powi(2);
        info[(2, 2)] += 1.0 / 0.05_f64.powi(2);
        for i in 0..4 {
            info[(i, i)] += 1.0 / prior.powi(2);
        }
        let cov = info.try_inverse().unwrap();
        let params = [
            LiftParam::Dry(RevJoint::J3),
            LiftParam::Dry(RevJoint::J1),
            LiftParam::J8Dry,
            LiftParam::Dry(RevJoint::J5),
        ];
        let contracted: Vec<bool> = (0..4).map(|i| cov[(i, i)].sqrt() < prior / 2.0).collect();
        assert_eq!(contracted, [true, false, true, false]);
        // Truth: J1 at 3×, the rest at 1: the data see 4·1 + 3 = 7 → level 0.8·1 + 0.2·3 = 1.4.
        // The MAP puts the excess on the line 4·x3 + x1 = 7 nearest (1, 1).
        let x = [1.0 + 8.0 / 17.0, 1.0 + 2.0 / 17.0, 1.0, 1.0];
        let at = attribute(
            &params,
            &x,
            &cov,
            AtTable4::Posterior(&cov),
            &cov,
            &contracted,
            &[prior; 4],
            2.0,
            &DriftThresholds::default(),
            &AttributionOptions::default(),
        );
        assert_eq!(at.separate, [false, false, true, false]);
        assert_eq!(at.combinations.len(), 1);
        let c = &at.combinations[0];
        assert_eq!(c.label(), "J3+J1 dry");
        assert_eq!(at.group, [Some(0), Some(0), None, None]);
        // The least-variance direction is the data's (4, 1), normalised to Σ = 1.
        assert!((c.weights[0] - 0.8).abs() < 0.02, "{:?}", c.weights);
        assert!(c.informed);
        let truth = c.level_of(|p| {
            if p == LiftParam::Dry(RevJoint::J1) {
                3.0
            } else {
                1.0
            }
        });
        assert!((truth - 1.4).abs() < 0.02, "{truth}");
        assert!(c.ci95[0] <= truth && truth <= c.ci95[1], "{c:?}");
        assert_ne!(c.status, Status::Unknown);

        // Informed only at the estimate: with a Table 4 posterior that is the prior alone,
        // nothing is informed; with the Table 4 run failed, only the best-informed direction
        // (J3+J1) is reported and J8, alone in a weaker one, is not separately identified.
        let prior_only = DMatrix::<f64>::identity(4, 4) * prior.powi(2);
        let run = |table4| {
            attribute(
                &params,
                &x,
                &cov,
                table4,
                &cov,
                &contracted,
                &[prior; 4],
                2.0,
                &DriftThresholds::default(),
                &AttributionOptions::default(),
            )
        };
        let none = run(AtTable4::Posterior(&prior_only));
        assert_eq!(none.separate, [false; 4]);
        assert!(none.combinations.is_empty(), "{:?}", none.combinations);
        let failed = run(AtTable4::RunFailed);
        assert_eq!(failed.separate, [false; 4]);
        assert_eq!(failed.combinations.len(), 1);
        assert_eq!(failed.combinations[0].label(), "J3+J1 dry");
    }
}

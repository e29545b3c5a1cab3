//! The fleet's prior for every friction parameter, learned from workshop fits (issue 37,
//! point 3): empirical Bayes by the method of moments (DerSimonian–Laird). A lift or gauge fit
//! reports few joints (the J1+J3 dry level, mostly); the rest it fits under a prior. Until now
//! that prior was Table 4 ± `LiftFitOptions::prior_relative_sd`; here it is the fleet's mean and
//! between-unit spread per joint and parameter, measured by the pendulum and swing tests.
//!
//! Model (stated): unit i's coefficient θ_i (Table 4 units, θ/θ₀) is drawn from N(μ, τ²) across
//! the fleet; its workshop fit reports y_i = θ_i + e_i with e_i ~ N(0, v_i), v_i the fit's own
//! variance (its 95 % interval's half-width / 1.96, squared), independent between units. Each
//! unit enters once (the caller passes the latest workshop fit per unit and parameter: an older
//! fit of the same unit is not independent of its newer one). Then
//! - Q = Σ w_i (y_i − ȳ_w)², w_i = 1/v_i, and τ̂² = max(0, (Q − (k − 1)) / (Σw − Σw²/Σw)): the
//!   spread left after each fit's own variance is removed;
//! - μ̂ = Σ w*_i y_i / Σ w*_i with w*_i = 1/(v_i + τ̂²), its variance 1/Σ w*_i;
//! - the prior of a unit not yet fitted is the predictive N(μ̂, τ̂² + var μ̂), its sd no less than
//!   `[fleet_prior] min_relative_sd`.
//!
//! With fewer than `[fleet_prior] min_fits` fits of a parameter the spread is the data file's
//! floor (`floor_relative_sd`) and the mean is Table 4 (1) updated by those fits as if the
//! fleet's spread were the floor: few tests move the mean a little and leave the width alone.
//! No I/O: the store's fits come in as numbers.

use serde::{Deserialize, Serialize};

use super::sensitivity::LiftParam;
use crate::data::FleetPriorData;

/// One workshop fit's estimate of one friction parameter, Table 4 units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorkshopEstimate {
    pub param: LiftParam,
    /// The estimate, θ/θ₀.
    pub ratio: f64,
    /// Its sd, θ/θ₀ (a 95 % interval's half-width / 1.96).
    pub sd_ratio: f64,
}

/// The learned prior of one friction parameter, Table 4 units.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct ParamPrior {
    /// `J1` … `J9`.
    pub joint: String,
    /// `dry` or `viscous`.
    pub kind: String,
    /// Prior mean, θ/θ₀.
    pub mean_ratio: f64,
    /// Prior sd, θ/θ₀: the fleet's spread and the mean's own uncertainty, or the floor.
    pub sd_ratio: f64,
    /// The between-unit spread τ̂ estimated from the fits, θ/θ₀ (0 when none or one).
    pub spread_ratio: f64,
    /// Workshop fits it rests on.
    pub n_fits: usize,
    /// True when `n_fits` ≥ `[fleet_prior] min_fits` (the spread is the fleet's, not the floor).
    pub learned: bool,
}

impl ParamPrior {
    /// The lift parameter this prior is for (`None` for a name no lift fit has).
    pub fn param(&self) -> Option<LiftParam> {
        LiftParam::named(&self.joint, &self.kind)
    }
}

/// The fleet's prior for every friction parameter of a lift fit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct FleetPrior {
    pub params: Vec<ParamPrior>,
}

impl FleetPrior {
    /// The prior of `p`, if it is a friction parameter.
    pub fn get(&self, p: LiftParam) -> Option<&ParamPrior> {
        self.params
            .iter()
            .find(|q| q.joint == p.joint() && q.kind == p.kind())
    }

    /// Workshop estimates the prior rests on, over every parameter.
    pub fn n_fits(&self) -> usize {
        self.params.iter().map(|p| p.n_fits).sum()
    }

    /// `learned` when any parameter's spread is the fleet's (`ParamPrior::learned`), else
    /// `type_file`: every parameter at the data file's floor.
    pub fn source(&self) -> &'static str {
        if self.params.iter().any(|p| p.learned) {
            "learned"
        } else {
            "type_file"
        }
    }

    /// The fit's prior (`LiftFitOptions::friction_prior`): each learned parameter's mean with
    /// its sd × `sd_scale` (`[fleet_prior] fit_sd_scale`, the widening the probe measured the
    /// level's coverage needs), a floored one's mean with the floor as it is (the lift fit's own
    /// Table 4 width, which its intervals were calibrated under). Entries whose mean or sd is
    /// not finite or not > 0 are left out (Table 4's then).
    pub fn for_fit(&self, sd_scale: f64) -> Vec<(LiftParam, f64, f64)> {
        self.params
            .iter()
            .filter_map(|p| {
                let sd = if p.learned {
                    p.sd_ratio * sd_scale
                } else {
                    p.sd_ratio
                };
                let ok =
                    p.mean_ratio.is_finite() && p.mean_ratio > 0.0 && sd.is_finite() && sd > 0.0;
                ok.then(|| p.param().map(|q| (q, p.mean_ratio, sd)))
                    .flatten()
            })
            .collect()
    }

    /// Whether any parameter's mean or sd differs from `other`'s by more than `tol` (Table 4
    /// units), or the two cover different parameters: a new version is due.
    pub fn differs(&self, other: &FleetPrior, tol: f64) -> bool {
        if self.params.len() != other.params.len() {
            return true;
        }
        self.params.iter().any(|a| {
            match other
                .params
                .iter()
                .find(|b| b.joint == a.joint && b.kind == a.kind)
            {
                Some(b) => {
                    (a.mean_ratio - b.mean_ratio).abs() > tol
                        || (a.sd_ratio - b.sd_ratio).abs() > tol
                }
                None => true,
            }
        })
    }
}

/// The friction parameters a fleet prior covers: every lift friction coefficient.
pub fn prior_params() -> Vec<LiftParam> {
    LiftParam::all()
        .into_iter()
        .filter(|p| *p != LiftParam::TorqueOffset)
        .collect()
}

/// Learn the fleet prior from workshop estimates (one per unit and parameter; see the module's
/// model). Estimates with a non-finite value, or a sd not finite and > 0, are left out, as are
/// parameters no lift fit has.
pub fn learn(estimates: &[WorkshopEstimate], settings: &FleetPriorData) -> FleetPrior {
    let params = prior_params()
        .into_iter()
        .map(|p| {
            let (y, v): (Vec<f64>, Vec<f64>) = estimates
                .iter()
                .filter(|e| e.param == p)
                .filter(|e| e.ratio.is_finite() && e.sd_ratio.is_finite() && e.sd_ratio > 0.0)
                .map(|e| (e.ratio, e.sd_ratio * e.sd_ratio))
                .unzip();
            learn_one(p, &y, &v, settings)
        })
        .collect();
    FleetPrior { params }
}

fn learn_one(p: LiftParam, y: &[f64], v: &[f64], s: &FleetPriorData) -> ParamPrior {
    let k = y.len();
    let tau2 = spread2(y, v);
    let (mean, sd, learned) = if k >= s.min_fits.max(1) {
        let w: Vec<f64> = v.iter().map(|vi| 1.0 / (vi + tau2)).collect();
        let sw: f64 = w.iter().sum();
        let mu = w.iter().zip(y).map(|(wi, yi)| wi * yi).sum::<f64>() / sw;
        let sd = (tau2 + 1.0 / sw).sqrt().max(s.min_relative_sd);
        (mu, sd, true)
    } else {
        // Few fits: Table 4 (1) ± floor as the fleet's distribution, updated by the fits.
        let f2 = s.floor_relative_sd * s.floor_relative_sd;
        let w: Vec<f64> = v.iter().map(|vi| 1.0 / (vi + f2)).collect();
        let sw: f64 = w.iter().sum::<f64>() + 1.0 / f2;
        let mu = (w.iter().zip(y).map(|(wi, yi)| wi * yi).sum::<f64>() + 1.0 / f2) / sw;
        (mu, s.floor_relative_sd, false)
    };
    ParamPrior {
        joint: p.joint().to_string(),
        kind: p.kind().to_string(),
        mean_ratio: mean,
        sd_ratio: sd,
        spread_ratio: tau2.sqrt(),
        n_fits: k,
        learned,
    }
}

/// The DerSimonian–Laird between-unit variance τ̂² (0 with fewer than two fits).
fn spread2(y: &[f64], v: &[f64]) -> f64 {
    let k = y.len();
    if k < 2 {
        return 0.0;
    }
    let w: Vec<f64> = v.iter().map(|vi| 1.0 / vi).collect();
    let sw: f64 = w.iter().sum();
    let sw2: f64 = w.iter().map(|x| x * x).sum();
    let ybar = w.iter().zip(y).map(|(wi, yi)| wi * yi).sum::<f64>() / sw;
    let q: f64 = w
        .iter()
        .zip(y)
        .map(|(wi, yi)| wi * (yi - ybar).powi(2))
        .sum();
    let c = sw - sw2 / sw;
    if c > 0.0 {
        ((q - (k as f64 - 1.0)) / c).max(0.0)
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests;

//! MAP fit of a force-gauge record: the revolute joints' dry μ in log space under a per-joint
//! prior (Table 4's or the fleet's), by Levenberg–Marquardt, intervals from the posterior, and
//! the combination it informs.
//!
//! Stated choices:
//! - Parameters: u_j = ln(μ_j/μ_j⁰) for the seven revolute joints that move (J6 is locked),
//!   prior u_j ~ N(ln m_j, (s_j/m_j)²) with (m_j, s_j) the prior's centre and sd in Table 4
//!   units ([`GaugeFitOptions::prior_of`]: the fleet's, `lift::fleet_prior::FleetPrior::for_fit`,
//!   else m_j = 1, s_j = [`LiftFitOptions::default`]'s `prior_relative_sd` 0.5): the lift's
//!   N(m_j μ⁰, (s_j μ⁰)²) to first order (d ln μ = dμ/μ, at the centre), never negative. Where
//!   the scaled units x = μ/μ⁰ need it (the data's information, the attribution, the level's
//!   members) the prior's sd is s_j, as the lift's. Bounds: μ within
//!   [1 %, 10×] of Table 4 (the lift's upper bound). Besides: the gauge's zero b, N, always (a
//!   nuisance, [`GaugeFitOptions::fit_offset`]), and the spring-rate factor k when the residual
//!   loop tries it ([`GaugeEffect`]), each in its own units with its prior.
//! - Residuals (F_model − F_meas)/σ₀ with σ₀ = max(`gauge_noise_n`, resolution/√12); Jacobian by
//!   forward differences (step [`FD_STEP`]; the statics is cheap), an offset's analytically.
//! - Noise: σ̂ = √(RSS/(n − p_eff)), p_eff = tr(A(A + P)⁻¹) the effective number of fitted
//!   parameters (A the data's information, P the prior's), floored at σ₀; the posterior
//!   (A·σ₀²/σ̂² + P)⁻¹. Intervals: the Student-t quantile at n − p_eff degrees of freedom,
//!   log-normal for μ (median the MAP, relative sd the posterior's in u).
//! - Identifiability: as for lifts ([`super::super::attribution`]), in units of Table 4
//!   (x = μ/μ⁰): a parameter is contracted when its posterior sd is under s_j / 2 (× min(x/m_j, 1):
//!   relative to the estimate, the prior's relative sd s_j/m_j);
//!   directions the data pin are the eigenvectors of the data's information; a joint in an
//!   informed direction with others is not separately identified and is reported in that
//!   direction's combination (level Σ w_j x_j, 1 at baseline). Its members: every joint of the
//!   direction until those left out would widen the level's interval by under 1 %
//!   ([`level_min_share`]; the lift's share rule left joints out whose prior tripled it).

use nalgebra::DMatrix;

use super::super::attribution::{AttributionOptions, Combination, attribute};
use super::super::dynamics::LiftModel;
use super::super::fit::{LiftFitOptions, ParamEstimate};
use super::super::fleet_prior::FleetPrior;
use super::super::posterior::{EffectPrior, correlation, inverse_spd};
use super::super::sensitivity::LiftParam;
use super::super::static_force::DriveLine;
use super::super::topology::RevJoint;
use super::simulate::spring_rate_drive;
use super::solve::{Warm, forces_near, warm_starts};
use super::terms::{FD_STEP, GaugeEffect, GaugeEffectEstimate};
use super::{GaugeError, GaugeRecord, gauge_data};
use crate::contract::drift::{DriftThresholds, Status};
use crate::joint::identify::lm::{LmOptions, Problem, Termination, minimize};
use crate::numerics::stats::{Z95, student_t_quantile};

/// The revolute joints a gauge record's friction enters: all but J6 (locked in the plane).
pub const FITTED_JOINTS: [RevJoint; 7] = [
    RevJoint::J1,
    RevJoint::J2,
    RevJoint::J2p,
    RevJoint::J3,
    RevJoint::J4,
    RevJoint::J5,
    RevJoint::J7,
];

/// Lowest μ fitted, × Table 4: a joint with 1 % of its friction is as good as frictionless
/// and keeps ln μ finite.
const MIN_MULTIPLE: f64 = 0.01;
/// Highest μ fitted, × Table 4 (the lift fit's bound).
const MAX_MULTIPLE: f64 = 10.0;

/// Settings of a gauge fit.
#[derive(Debug, Clone)]
pub struct GaugeFitOptions {
    /// Prior sd of ln μ (the lift's relative prior sd): every joint's not in `friction_prior`.
    pub prior_relative_sd: f64,
    /// Joints whose prior is not Table 4 ± `prior_relative_sd`: (`LiftParam::Dry(j)`, centre
    /// m_j, sd s_j), Table 4 units — the fleet's (issue 37, [`GaugeFitOptions::with_fleet_prior`]).
    /// Empty (the default): Table 4 for every joint. Entries for other parameters (viscous,
    /// J8) set the not-estimated parameters' reported prior (`report`).
    pub friction_prior: Vec<(LiftParam, f64, f64)>,
    /// Contracted when posterior sd < prior sd / this (the lift's).
    pub informed_factor: f64,
    pub thresholds: DriftThresholds,
    /// The least noise assumed, N (`[static_force] gauge_noise_n`).
    pub noise_floor_n: f64,
    /// The gauge's zero b fitted with the friction, a nuisance as a lift's torque offset
    /// (default true): measured, a 0.5 N tare error the fit without it cannot see (residual
    /// 1.0–1.5× the noise) moved the J1+J3 level by −0.15 to −0.20 — the mean of the branches
    /// carries friction through the branches' different reactions, and the fit bends the
    /// friction to follow a shifted mean. With b fitted the level moved by < 10⁻⁴ and its sd
    /// stayed 0.038 (`tests::probe_offset_bias`, seeds 600–604).
    pub fit_offset: bool,
    /// An effect fitted besides: `SpringRate` (k); `SensorOffset` is `fit_offset`. `None`: the
    /// plain model.
    pub effect: Option<GaugeEffect>,
    pub lm: LmOptions,
    pub attribution: AttributionOptions,
}

impl Default for GaugeFitOptions {
    fn default() -> Self {
        let lift = LiftFitOptions::default();
        Self {
            prior_relative_sd: lift.prior_relative_sd,
            friction_prior: Vec::new(),
            informed_factor: lift.informed_factor,
            thresholds: lift.thresholds,
            noise_floor_n: gauge_data().gauge_noise_n,
            fit_offset: true,
            effect: None,
            // The statics is smooth and cheap: converge tightly (a step of 10⁻⁸ in ln μ is far
            // inside any posterior sd).
            lm: LmOptions {
                max_iter: 60,
                ftol: 1e-12,
                xtol: 1e-8,
                gtol: 1e-10,
                dtol: 0.0,
                noise_sd: 0.0,
                cliff_sd: 0.0,
                give_up_cost: 0.0,
            },
            attribution: lift.attribution,
        }
    }
}

/// A gauge fit.
#[derive(Debug, Clone)]
pub struct GaugeFit {
    /// Each fitted joint's dry μ ([`FITTED_JOINTS`] order), `LiftParam::Dry(j)`: informed ones
    /// at the MAP with the posterior interval, the others at the prior's centre (Table 4 × m_j)
    /// with the prior's.
    pub params: Vec<ParamEstimate>,
    /// Combinations the record informs together (`lift::attribution`).
    pub combinations: Vec<Combination>,
    /// The gauge's zero b, N, when fitted (`GaugeFitOptions::fit_offset`).
    pub offset: Option<GaugeEffectEstimate>,
    /// The drive characteristic's slope factor k, when fitted.
    pub spring_rate: Option<GaugeEffectEstimate>,
    /// The model's readings at the MAP (effects included), N, reading order.
    pub fitted_n: Vec<f64>,
    pub rmse_n: f64,
    /// The noise scale of the intervals, max(σ̂, σ₀), N.
    pub noise_n: f64,
    /// σ₀ = max(noise floor, resolution/√12), N.
    pub noise_floor_n: f64,
    /// n − p_eff.
    pub dof: f64,
    /// The t quantile the intervals use.
    pub t_quantile: f64,
    /// Posterior correlations (friction in [`FITTED_JOINTS`] order, then b, then k).
    pub posterior_correlation: DMatrix<f64>,
    pub iterations: usize,
    pub evaluations: usize,
    pub termination: Termination,
}

impl GaugeFit {
    /// The friction's MAP in the fit's units (ln μ/μ⁰ per joint): a warm start.
    pub fn friction_start(&self) -> Vec<f64> {
        self.params
            .iter()
            .map(|p| (p.map_value / p.baseline).ln())
            .collect()
    }

    /// The estimate of `effect`, when fitted.
    pub fn estimate(&self, effect: GaugeEffect) -> Option<GaugeEffectEstimate> {
        match effect {
            GaugeEffect::SensorOffset => self.offset,
            GaugeEffect::SpringRate => self.spring_rate,
        }
    }
}

impl GaugeFitOptions {
    /// The prior (centre m, sd s) of friction parameter `p`, θ/θ₀: its `friction_prior` entry,
    /// else Table 4 (1) ± `prior_relative_sd`.
    pub fn prior_of(&self, p: LiftParam) -> (f64, f64) {
        self.friction_prior
            .iter()
            .find(|(q, _, _)| *q == p)
            .map(|&(_, m, s)| (m, s))
            .unwrap_or((1.0, self.prior_relative_sd))
    }

    /// These options with the fit's prior `prior.for_fit(sd_scale)` (the service's: learned sds
    /// × `[fleet_prior] fit_sd_scale`).
    pub fn with_fleet_prior(mut self, prior: &FleetPrior, sd_scale: f64) -> Self {
        self.friction_prior = prior.for_fit(sd_scale);
        self
    }

    /// The parameters fitted besides the friction, in order: b, then k.
    pub fn extras(&self) -> Vec<GaugeEffect> {
        let mut v = Vec::new();
        if self.fit_offset || self.effect == Some(GaugeEffect::SensorOffset) {
            v.push(GaugeEffect::SensorOffset);
        }
        if self.effect == Some(GaugeEffect::SpringRate) {
            v.push(GaugeEffect::SpringRate);
        }
        v
    }
}

struct GaugeProblem<'a> {
    model: &'a LiftModel,
    alpha_range_rad: (f64, f64),
    drive: &'a DriveLine,
    record: &'a GaugeRecord,
    warm: &'a [Warm],
    baseline: [f64; FITTED_JOINTS.len()],
    /// The prior's centre ln m_j and sd s_j/m_j in u, per fitted joint.
    prior_u: [(f64, f64); FITTED_JOINTS.len()],
    /// Parameters besides the friction, in order, with their priors.
    extras: Vec<(GaugeEffect, EffectPrior)>,
    sigma_n: f64,
}

impl GaugeProblem<'_> {
    /// The index of `effect` among the parameters, when fitted.
    fn at(&self, effect: GaugeEffect) -> Option<usize> {
        self.extras
            .iter()
            .position(|(e, _)| *e == effect)
            .map(|k| FITTED_JOINTS.len() + k)
    }

    /// The model's readings at x (ln μ/μ⁰, then b and k as fitted), N.
    fn forces(&self, x: &[f64]) -> Result<Vec<f64>, String> {
        let mut m = self.model.clone();
        for (i, j) in FITTED_JOINTS.iter().enumerate() {
            m.friction.dry_mu[j.index()] = self.baseline[i] * x[i].exp();
        }
        let offset = self.at(GaugeEffect::SensorOffset).map_or(0.0, |i| x[i]);
        let drive = match self.at(GaugeEffect::SpringRate) {
            Some(i) => spring_rate_drive(self.drive, x[i]),
            None => *self.drive,
        };
        let f = forces_near(&m, self.alpha_range_rad, &drive, self.record, self.warm)
            .map_err(|e| e.to_string())?;
        Ok(f.into_iter().map(|v| v + offset).collect())
    }
}

impl Problem for GaugeProblem<'_> {
    fn n_params(&self) -> usize {
        FITTED_JOINTS.len() + self.extras.len()
    }
    fn n_residuals(&self) -> usize {
        self.record.len() + self.n_params()
    }
    fn eval(&mut self, x: &[f64], r: &mut [f64], jac: &mut DMatrix<f64>) -> Result<(), String> {
        let n = self.record.len();
        let p = self.n_params();
        let f = self.forces(x)?;
        for ((rk, fk), mk) in r.iter_mut().zip(&f).zip(&self.record.forces_n) {
            *rk = (fk - mk) / self.sigma_n;
        }
        jac.fill(0.0);
        let offset_at = self.at(GaugeEffect::SensorOffset);
        for i in 0..p {
            if Some(i) == offset_at {
                jac.view_mut((0, i), (n, 1)).fill(1.0 / self.sigma_n);
                continue;
            }
            let mut xi = x.to_vec();
            xi[i] += FD_STEP;
            let fi = self.forces(&xi)?;
            for (k, (a, b)) in fi.iter().zip(&f).enumerate() {
                jac[(k, i)] = (a - b) / (FD_STEP * self.sigma_n);
            }
        }
        for (i, (c, sd)) in self.prior_u.iter().enumerate() {
            r[n + i] = (x[i] - c) / sd;
            jac[(n + i, i)] = 1.0 / sd;
        }
        for (k, (_, pr)) in self.extras.iter().enumerate() {
            let i = FITTED_JOINTS.len() + k;
            r[n + i] = (x[i] - pr.mean) / pr.sd;
            jac[(n + i, i)] = 1.0 / pr.sd;
        }
        Ok(())
    }
    fn lower_bounds(&self) -> Vec<f64> {
        let mut v = vec![MIN_MULTIPLE.ln(); FITTED_JOINTS.len()];
        v.extend(self.extras.iter().map(|(_, p)| p.lower));
        v
    }
    fn upper_bounds(&self) -> Vec<f64> {
        let mut v = vec![MAX_MULTIPLE.ln(); FITTED_JOINTS.len()];
        v.extend(self.extras.iter().map(|(_, p)| p.upper));
        v
    }
}

/// MAP fit of `record` with `model` (its Table 4 friction the baseline, the prior's centre
/// m_j × it) driven by `drive` (module doc), from the prior's centre and b = 0, k = 1.
pub fn fit_gauge(
    model: &LiftModel,
    alpha_range_rad: (f64, f64),
    drive: &DriveLine,
    record: &GaugeRecord,
    opts: &GaugeFitOptions,
) -> Result<GaugeFit, GaugeError> {
    fit_gauge_from(model, alpha_range_rad, drive, record, opts, None)
}

/// [`fit_gauge`] with the friction started at `start` (ln μ/μ⁰ per joint, [`FITTED_JOINTS`]
/// order; b and k start at 0 and 1); `None`: the prior's centre (Table 4 by default).
pub fn fit_gauge_from(
    model: &LiftModel,
    alpha_range_rad: (f64, f64),
    drive: &DriveLine,
    record: &GaugeRecord,
    opts: &GaugeFitOptions,
    start: Option<&[f64]>,
) -> Result<GaugeFit, GaugeError> {
    let baseline: [f64; FITTED_JOINTS.len()] =
        std::array::from_fn(|i| model.friction.dry_mu[FITTED_JOINTS[i].index()]);
    if let Some(b) = baseline.iter().find(|b| !(b.is_finite() && **b > 0.0)) {
        return Err(GaugeError::Model(format!(
            "a dry μ baseline of {b} cannot scale its prior"
        )));
    }
    // Per joint (centre m_j, sd s_j), Table 4 units.
    let prior: [(f64, f64); FITTED_JOINTS.len()] =
        std::array::from_fn(|i| opts.prior_of(LiftParam::Dry(FITTED_JOINTS[i])));
    let positive = |v: f64| v.is_finite() && v > 0.0;
    if !(prior.iter().all(|(m, s)| positive(*m) && positive(*s)) && positive(opts.noise_floor_n)) {
        return Err(GaugeError::Model(
            "prior centre, prior sd and noise floor must be > 0".into(),
        ));
    }
    let prior_u: [(f64, f64); FITTED_JOINTS.len()] =
        std::array::from_fn(|i| (prior[i].0.ln(), prior[i].1 / prior[i].0));
    // The prior's sd in Table 4 units, per joint (the attribution's and the level's).
    let s_x: Vec<f64> = prior.iter().map(|(_, s)| *s).collect();
    let warm = warm_starts(model, alpha_range_rad, drive, record)?;
    let sigma0 = opts.noise_floor_n.max(record.resolution_n / 12f64.sqrt());
    let extras: Vec<(GaugeEffect, EffectPrior)> =
        opts.extras().into_iter().map(|e| (e, e.prior())).collect();
    let mut problem = GaugeProblem {
        model,
        alpha_range_rad,
        drive,
        record,
        warm: &warm,
        baseline,
        prior_u,
        extras: extras.clone(),
        sigma_n: sigma0,
    };
    let p = problem.n_params();
    let pf = FITTED_JOINTS.len();
    let mut x0: Vec<f64> = prior_u.iter().map(|(c, _)| *c).collect();
    if let Some(st) = start.filter(|st| st.len() == pf && st.iter().all(|v| v.is_finite())) {
        x0.copy_from_slice(st);
    }
    x0.extend(extras.iter().map(|(e, _)| e.null_value()));
    let rep = minimize(&mut problem, &x0, &opts.lm);
    if let Termination::EvaluationFailed(e) = &rep.termination {
        return Err(GaugeError::Failed(e.clone()));
    }
    let n = record.len();
    let jd = rep.jacobian.rows(0, n).into_owned();
    // Information in the fit's units (residuals over σ₀) and the prior's precision.
    let a = jd.tr_mul(&jd);
    let prior_prec: Vec<f64> = (0..p)
        .map(|i| {
            if i < pf {
                1.0 / (prior_u[i].1 * prior_u[i].1)
            } else {
                1.0 / extras[i - pf].1.sd.powi(2)
            }
        })
        .collect();
    let mut post0 = a.clone();
    for i in 0..p {
        post0[(i, i)] += prior_prec[i];
    }
    let cov0 = inverse_spd(&post0);
    let p_eff = (&a * &cov0).trace().clamp(0.0, p as f64);
    let dof = (n as f64 - p_eff).max(1.0);
    let rss: f64 = rep.residuals[..n].iter().map(|v| v * v).sum();
    let kappa2 = (rss / dof).max(1.0);
    let mut post = &a / kappa2;
    for i in 0..p {
        post[(i, i)] += prior_prec[i];
    }
    let cov_u = inverse_spd(&post);
    let t = student_t_quantile(0.975, dof.floor() as usize);
    // Every interval at the t quantile: the posterior scaled so that Z95·sd is t·sd.
    let scale = (t / Z95).powi(2);
    // Units of Table 4 (x = μ/μ⁰ = e^u) for the friction, the effect's own.
    let xs: Vec<f64> = (0..p)
        .map(|i| if i < pf { rep.x[i].exp() } else { 1.0 })
        .collect();
    let cov_x = DMatrix::from_fn(p, p, |i, j| cov_u[(i, j)] * xs[i] * xs[j] * scale);
    let mut info_x = DMatrix::from_fn(p, p, |i, j| a[(i, j)] / (kappa2 * xs[i] * xs[j]));
    for i in 0..p {
        info_x[(i, i)] += if i < pf {
            1.0 / (s_x[i] * s_x[i])
        } else {
            prior_prec[i]
        };
    }
    let cov_h = inverse_spd(&info_x);
    let params: Vec<LiftParam> = FITTED_JOINTS.iter().map(|j| LiftParam::Dry(*j)).collect();
    let contracted: Vec<bool> = (0..pf)
        .map(|i| {
            let (m, sd) = prior[i];
            cov_x[(i, i)].max(0.0).sqrt() < sd / opts.informed_factor * (xs[i] / m).min(1.0)
        })
        .collect();
    let attribution = attribute(
        &params,
        &xs[..pf],
        &cov_h,
        super::super::attribution::AtTable4::NotEvaluated,
        &cov_x,
        &contracted,
        &s_x,
        opts.informed_factor,
        &opts.thresholds,
        &AttributionOptions {
            min_share: level_min_share(&cov_h, pf, &s_x).min(opts.attribution.min_share),
        },
    );
    let estimates: Vec<ParamEstimate> = (0..pf)
        .map(|i| {
            let base = baseline[i];
            let (m, sd) = prior[i];
            let informed = attribution.separate[i];
            let sd_u = (cov_u[(i, i)] * scale).max(0.0).sqrt();
            let map_value = base * xs[i];
            let (value, ci95, status) = if informed {
                let ci = [
                    map_value * (-Z95 * sd_u).exp(),
                    map_value * (Z95 * sd_u).exp(),
                ];
                let v = opts.thresholds.judge(ci, map_value, Some(base));
                let st = if v.identifiable {
                    v.status
                } else {
                    Status::Unknown
                };
                (map_value, ci, st)
            } else {
                // At the prior's centre with the prior's interval (log-normal, relative sd
                // s_j/m_j): what the record leaves of this joint is the prior.
                let centre = base * m;
                let rel = sd / m;
                (
                    centre,
                    [centre * (-Z95 * rel).exp(), centre * (Z95 * rel).exp()],
                    Status::Unknown,
                )
            };
            ParamEstimate {
                param: params[i],
                baseline: base,
                prior_sd: sd * base,
                value,
                map_value,
                posterior_sd: sd_u * map_value,
                ci95,
                informed,
                status,
                combination: attribution.group[i],
            }
        })
        .collect();
    let extra_est = |effect: GaugeEffect| {
        let k = extras.iter().position(|(e, _)| *e == effect)?;
        let (i, pr) = (pf + k, extras[k].1);
        let v = rep.x[i];
        let sd = (cov_u[(i, i)] * scale).max(0.0).sqrt();
        Some(GaugeEffectEstimate {
            effect,
            value: v,
            posterior_sd: sd,
            ci95: [(v - Z95 * sd).max(pr.lower), (v + Z95 * sd).min(pr.upper)],
        })
    };
    let fitted_n: Vec<f64> = rep.residuals[..n]
        .iter()
        .zip(&record.forces_n)
        .map(|(r, f)| f + r * sigma0)
        .collect();
    let rmse_n = (rss / n as f64).sqrt() * sigma0;
    Ok(GaugeFit {
        params: estimates,
        combinations: attribution.combinations,
        offset: extra_est(GaugeEffect::SensorOffset),
        spring_rate: extra_est(GaugeEffect::SpringRate),
        fitted_n,
        rmse_n,
        noise_n: sigma0 * kappa2.sqrt(),
        noise_floor_n: sigma0,
        dof,
        t_quantile: t,
        posterior_correlation: correlation(&cov_u),
        iterations: rep.iterations,
        evaluations: rep.evaluations,
        termination: rep.termination,
    })
}

/// How much the joints left out of the level may widen its interval: 1 %, as a share of its
/// variance ([`level_min_share`]). A tenth of what a record can tell of its own width: its
/// noise scale comes from ~27 degrees of freedom (30 readings less the effective parameters),
/// whose relative sd is 1/√54 ≈ 14 %. At Table 4 it falls between J4 (left out it would add
/// 9 % of the data's variance) and J7 (0.4 %), so the members do not change from record to
/// record (`calibration_tests::the_level_interval_matches_its_spread_over_noise_draws`).
pub const LEVEL_WIDENING: f64 = 1.01 * 1.01 - 1.0;

/// The least share (squared component) a joint needs in the best-informed direction to join
/// its level (`AttributionOptions::min_share`): every joint is in, by decreasing share, until
/// the joints left out would add at most [`LEVEL_WIDENING`] of the data's variance to it.
///
/// Why (issue 39, point 5): the data pin the gap, the direction v of their information
/// Λ = (Σ_ff)⁻¹ − P⁻¹ (as `lift::attribution`), with eigenvalue λ: the level along all of v has
/// variance 1/(λ(Σv)²). A level over the members M only, v_M·x/Σ_M v, is that less the joints
/// left out, each unseen apart from it, so it carries their prior: Σ_{j∉M} s_j² v_j²/(Σ_M v)² more
/// (s_j each joint's prior sd, Table 4 units: `prior_sd[j]`; alike, s² Σ v_j²).
/// The lift's rule (`min_share` 0.01) keeps J1 and J3 (v² 0.024 and 0.968 at Table 4) and
/// drops J5, J2′ and J2 (0.0036, 0.0033, 0.0011): with s = 0.5 their prior made the J1+J3
/// interval 2.9 times the level's spread over noise draws (sd 0.038 against 0.013, 120 records
/// at the stated gauge; `calibration_tests::probe_level_variance_parts` splits it) — all of it
/// the dropped joints' prior, none of it the noise. With J2, J2′, J4 and J5 in, J7 (v² 1.6·10⁻⁷) left out adds 0.4 % of
/// the data's variance. A joint whose component has the other sign stops the walk: a level is
/// never a contrast.
pub fn level_min_share(cov_h: &DMatrix<f64>, pf: usize, prior_sd: &[f64]) -> f64 {
    let Some(ff) = cov_h.view((0, 0), (pf, pf)).into_owned().try_inverse() else {
        return f64::INFINITY;
    };
    if prior_sd.len() != pf {
        return f64::INFINITY;
    }
    let mut lambda = (&ff + ff.transpose()) / 2.0;
    for (i, s) in prior_sd.iter().enumerate() {
        lambda[(i, i)] -= 1.0 / (s * s);
    }
    let eig = lambda.symmetric_eigen();
    let k = eig.eigenvalues.imax();
    let (lam, v) = (eig.eigenvalues[k], eig.eigenvectors.column(k).into_owned());
    if !(lam.is_finite() && lam > 0.0) {
        return f64::INFINITY;
    }
    let sign = v.sum().signum();
    let mut order: Vec<usize> = (0..pf).collect();
    order.sort_by(|&a, &b| (v[b] * v[b]).total_cmp(&(v[a] * v[a])));
    // The variance the joints left out add, Σ s_j² v_j², against LEVEL_WIDENING/λ: with one
    // s for all, as before, Σ v_j² against LEVEL_WIDENING/(λ s²) (the same numbers exactly).
    let s0 = prior_sd[0];
    let uniform = prior_sd.iter().all(|s| *s == s0);
    let weight = |i: usize| {
        if uniform {
            1.0
        } else {
            prior_sd[i] * prior_sd[i]
        }
    };
    let budget = if uniform {
        LEVEL_WIDENING / (lam * s0 * s0)
    } else {
        LEVEL_WIDENING / lam
    };
    let mut left_out: f64 = (0..pf).map(|i| v[i] * v[i] * weight(i)).sum();
    let mut share = f64::INFINITY;
    for i in order {
        if left_out <= budget || v[i] * sign <= 0.0 {
            break;
        }
        share = v[i] * v[i];
        left_out -= share * weight(i);
    }
    // Just below the last member's share, so that it passes `>=`.
    share * (1.0 - 1e-9)
}

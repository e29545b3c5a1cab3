//! Joint friction from a quadrangle swing: MAP fit of J1, J2, J2′, J3 (viscous and dry) with
//! Table 4 as a Gaussian prior, the release state and the two sensor zeros as nuisances.
//!
//! Stated choices:
//! - Prior: every friction coefficient ~ N(baseline, (0.5·baseline)²), as the lift fit; each
//!   angle sensor's zero ~ N(0, (1°)²) (an inclinometer-set zero); the release angle and rate
//!   have no prior (the data pin them).
//! - Noise: σ = 0.05° on both angle channels (a stated sensor resolution), inflated to the
//!   residual RMS when the fit is worse than that, which widens every interval alike.
//! - A friction parameter is *informed* when its posterior sd is below its prior sd / 2; an
//!   uninformed one is reported at baseline with the prior's interval and is never flagged.
//! - Fitted window: from release until the measured α has settled (its last departure of more
//!   than 10 σ from its final level) plus 10 %: once stuck, the record says nothing more about
//!   friction, and a long stuck tail would weigh the rest angle alone. Continuation: fits over
//!   the first 25 % and 50 % of that window come first (the first swings pin the dry-friction
//!   sum nearly linearly; the whole window, with its reversals and final stop, is far from
//!   quadratic around Table 4).
//! - The Jacobian is by central differences of the stick–slip simulation (tolerance 10⁻¹⁰, so
//!   difference noise ~10⁻⁷ of a step of 10⁻³ baseline); the sensor zeros' columns are exact.

use nalgebra::DMatrix;

use super::model::{QJoint, Quadrangle};
use super::simulate::{SwingError, SwingOptions, simulate_swing};
use crate::contract::drift::{DriftThresholds, Status};
use crate::joint::identify::lm::{LmOptions, Problem, Termination, minimize};
use crate::lift::identify::inverse_spd;
use crate::numerics::stats::Z95;

/// A friction parameter of the quadrangle.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum QuadParam {
    Viscous(QJoint),
    Dry(QJoint),
}

impl QuadParam {
    /// Every friction parameter: each joint's viscous then dry, [`QJoint`] order.
    pub fn all() -> Vec<QuadParam> {
        QJoint::ALL
            .iter()
            .flat_map(|j| [QuadParam::Viscous(*j), QuadParam::Dry(*j)])
            .collect()
    }
    pub fn joint(self) -> QJoint {
        match self {
            QuadParam::Viscous(j) | QuadParam::Dry(j) => j,
        }
    }
    pub fn kind(self) -> &'static str {
        match self {
            QuadParam::Viscous(_) => "viscous",
            QuadParam::Dry(_) => "dry",
        }
    }
    pub fn get(self, m: &Quadrangle) -> f64 {
        match self {
            QuadParam::Viscous(j) => m.friction.viscous_nms_per_rad[j.index()],
            QuadParam::Dry(j) => m.friction.dry_mu[j.index()],
        }
    }
    pub fn set(self, m: &mut Quadrangle, v: f64) {
        match self {
            QuadParam::Viscous(j) => m.friction.viscous_nms_per_rad[j.index()] = v,
            QuadParam::Dry(j) => m.friction.dry_mu[j.index()] = v,
        }
    }
}

/// One recorded swing: sample times and both angle channels, rad.
#[derive(Debug, Clone, Copy)]
pub struct SwingTrace<'a> {
    pub t_s: &'a [f64],
    pub alpha_rad: &'a [f64],
    pub beta_rad: &'a [f64],
}

/// Settings of a quadrangle fit.
#[derive(Debug, Clone)]
pub struct QuadFitOptions {
    pub angle_noise_rad: f64,
    pub prior_relative_sd: f64,
    pub zero_prior_sd_rad: f64,
    pub informed_factor: f64,
    pub thresholds: DriftThresholds,
    pub sim: SwingOptions,
    pub lm: LmOptions,
}

impl Default for QuadFitOptions {
    fn default() -> Self {
        Self {
            angle_noise_rad: 0.05f64.to_radians(),
            prior_relative_sd: 0.5,
            zero_prior_sd_rad: 1f64.to_radians(),
            informed_factor: 2.0,
            thresholds: DriftThresholds::default(),
            sim: SwingOptions::default(),
            // Stop once a step would move the parameters by under 0.1 standard error.
            lm: LmOptions {
                max_iter: 30,
                ftol: 1e-8,
                xtol: 1e-6,
                gtol: 1e-10,
                dtol: 0.1,
                noise_sd: 0.0,
                cliff_sd: 0.0,
                give_up_cost: 0.0,
            },
        }
    }
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum QuadFitError {
    #[error(transparent)]
    Sim(#[from] SwingError),
    #[error("quadrangle fit: {0}")]
    Invalid(String),
    #[error("quadrangle fit failed: {0}")]
    Failed(String),
}

/// One friction parameter's estimate.
#[derive(Debug, Clone, PartialEq)]
pub struct QuadEstimate {
    pub param: QuadParam,
    pub baseline: f64,
    pub prior_sd: f64,
    /// MAP when informed, else the baseline.
    pub value: f64,
    pub map_value: f64,
    pub posterior_sd: f64,
    /// Posterior 95 % interval when informed, else the prior's.
    pub ci95: [f64; 2],
    pub informed: bool,
    pub status: Status,
}

/// A nuisance estimate (value, sd), in the unit its name says.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Nuisance {
    pub value: f64,
    pub sd: f64,
}

/// The fit of one swing.
#[derive(Debug, Clone)]
pub struct QuadFit {
    /// [`QuadParam::all`] order.
    pub params: Vec<QuadEstimate>,
    pub release_alpha_rad: Nuisance,
    pub release_rate_rad_s: Nuisance,
    pub alpha_zero_rad: Nuisance,
    pub beta_zero_rad: Nuisance,
    /// Residual RMS over both channels in the fitted window, rad.
    pub rmse_rad: f64,
    /// Samples fitted (from the first): the window until the swing settled.
    pub samples_fitted: usize,
    /// max(σ, residual RMS), rad.
    pub noise_rad: f64,
    /// Fitted channels (sensor zeros included), rad.
    pub fitted_alpha_rad: Vec<f64>,
    pub fitted_beta_rad: Vec<f64>,
    /// Measured − fitted α, rad.
    pub residual_alpha_rad: Vec<f64>,
    pub iterations: usize,
    pub evaluations: usize,
    pub termination: Termination,
}

impl QuadFit {
    pub fn estimate(&self, p: QuadParam) -> &QuadEstimate {
        self.params
            .iter()
            .find(|e| e.param == p)
            .expect("every parameter is estimated")
    }
    /// A joint's status: the worst of its informed parameters', `Unknown` when none is.
    pub fn joint_status(&self, j: QJoint) -> Status {
        self.params
            .iter()
            .filter(|e| e.param.joint() == j && e.informed)
            .map(|e| e.status)
            .max()
            .unwrap_or(Status::Unknown)
    }
}

/// Number of nuisance parameters: release angle, release rate, α zero, β zero.
const N_NUIS: usize = 4;
/// Upper bound of a friction coefficient, multiple of its baseline.
const MAX_MULTIPLE: f64 = 10.0;

struct SwingProblem<'a> {
    base: &'a Quadrangle,
    trace: &'a SwingTrace<'a>,
    fric: Vec<QuadParam>,
    baseline: Vec<f64>,
    opts: &'a QuadFitOptions,
}

impl SwingProblem<'_> {
    fn n_fric(&self) -> usize {
        self.fric.len()
    }
    fn model_at(&self, x: &[f64]) -> Quadrangle {
        let mut m = self.base.clone();
        for (i, p) in self.fric.iter().enumerate() {
            p.set(&mut m, x[i] * self.baseline[i]);
        }
        m
    }
    /// Simulated (α, β) at x, sensor zeros not applied.
    fn sim(&self, x: &[f64]) -> Result<(Vec<f64>, Vec<f64>), String> {
        let pf = self.n_fric();
        let run = simulate_swing(
            &self.model_at(x),
            self.trace.t_s,
            x[pf],
            x[pf + 1],
            &self.opts.sim,
        )
        .map_err(|e| e.to_string())?;
        Ok((run.alpha_rad, run.beta_rad))
    }
    /// Central-difference step of parameter i (friction in baseline units, release in rad(/s)).
    fn step(&self, i: usize) -> f64 {
        let pf = self.n_fric();
        if i < pf {
            1e-3
        } else if i == pf {
            1e-5
        } else {
            1e-4
        }
    }
}

impl Problem for SwingProblem<'_> {
    fn n_params(&self) -> usize {
        self.n_fric() + N_NUIS
    }
    fn n_residuals(&self) -> usize {
        2 * self.trace.t_s.len() + self.n_fric() + 2
    }
    fn eval(&mut self, x: &[f64], r: &mut [f64], jac: &mut DMatrix<f64>) -> Result<(), String> {
        let pf = self.n_fric();
        let n = self.trace.t_s.len();
        let sigma = self.opts.angle_noise_rad;
        let (za, zb) = (x[pf + 2], x[pf + 3]);
        let (a, b) = self.sim(x)?;
        jac.fill(0.0);
        for k in 0..n {
            r[k] = (a[k] + za - self.trace.alpha_rad[k]) / sigma;
            r[n + k] = (b[k] + zb - self.trace.beta_rad[k]) / sigma;
            jac[(k, pf + 2)] = 1.0 / sigma;
            jac[(n + k, pf + 3)] = 1.0 / sigma;
        }
        for i in 0..pf + 2 {
            let h = self.step(i);
            let mut xp = x.to_vec();
            xp[i] += h;
            let (ap, bp) = self.sim(&xp)?;
            // One-sided at the lower bound (no negative friction is simulated).
            let (am, bm, width) = if i < pf && x[i] < h {
                (a.clone(), b.clone(), h)
            } else {
                let mut xm = x.to_vec();
                xm[i] -= h;
                let (am, bm) = self.sim(&xm)?;
                (am, bm, 2.0 * h)
            };
            for k in 0..n {
                jac[(k, i)] = (ap[k] - am[k]) / width / sigma;
                jac[(n + k, i)] = (bp[k] - bm[k]) / width / sigma;
            }
        }
        // Prior rows: friction (x − 1)/s_rel, sensor zeros z/s_z.
        let mut row = 2 * n;
        let s_rel = self.opts.prior_relative_sd;
        for i in 0..pf {
            r[row] = (x[i] - 1.0) / s_rel;
            jac[(row, i)] = 1.0 / s_rel;
            row += 1;
        }
        for i in [pf + 2, pf + 3] {
            r[row] = x[i] / self.opts.zero_prior_sd_rad;
            jac[(row, i)] = 1.0 / self.opts.zero_prior_sd_rad;
            row += 1;
        }
        Ok(())
    }
    fn lower_bounds(&self) -> Vec<f64> {
        let mut v = vec![0.0; self.n_fric()];
        v.extend([f64::NEG_INFINITY; N_NUIS]);
        v
    }
    fn upper_bounds(&self) -> Vec<f64> {
        let mut v = vec![MAX_MULTIPLE; self.n_fric()];
        v.extend([f64::INFINITY; N_NUIS]);
        v
    }
}

fn check(trace: &SwingTrace) -> Result<(), QuadFitError> {
    let n = trace.t_s.len();
    if n < 10 {
        return Err(QuadFitError::Invalid(format!(
            "`t_s` has {n} samples; a swing needs at least 10"
        )));
    }
    for (name, c) in [("alpha_deg", trace.alpha_rad), ("beta_deg", trace.beta_rad)] {
        if c.len() != n {
            return Err(QuadFitError::Invalid(format!(
                "`{name}` has {} samples, `t_s` {n}",
                c.len()
            )));
        }
        if let Some(k) = c.iter().position(|v| !v.is_finite()) {
            return Err(QuadFitError::Invalid(format!(
                "`{name}`[{k}] is not finite"
            )));
        }
    }
    Ok(())
}

/// MAP fit of one swing from the model's current friction (its baseline and prior centre).
pub fn fit_swing(
    model: &Quadrangle,
    trace: &SwingTrace,
    opts: &QuadFitOptions,
) -> Result<QuadFit, QuadFitError> {
    check(trace)?;
    let fric = QuadParam::all();
    let baseline: Vec<f64> = fric.iter().map(|p| p.get(model)).collect();
    if let Some((p, v)) = fric
        .iter()
        .zip(&baseline)
        .find(|(_, v)| !(**v > 0.0 && v.is_finite()))
    {
        return Err(QuadFitError::Invalid(format!(
            "{}.{} baseline {v} must be > 0 to scale its prior",
            p.joint().name(),
            p.kind()
        )));
    }
    let pf = fric.len();
    let n = fitted_window(trace.alpha_rad, opts.angle_noise_rad);
    let window = |k: usize| SwingTrace {
        t_s: &trace.t_s[..k],
        alpha_rad: &trace.alpha_rad[..k],
        beta_rad: &trace.beta_rad[..k],
    };
    let mut x = vec![1.0; pf];
    x.extend([trace.alpha_rad[0], 0.0, 0.0, 0.0]);
    let (mut iterations, mut evaluations) = (0, 0);
    for frac in [0.25, 0.5] {
        let k = ((n as f64 * frac) as usize).max(10);
        if k >= n {
            break;
        }
        let part = window(k);
        let mut stage = SwingProblem {
            base: model,
            trace: &part,
            fric: fric.clone(),
            baseline: baseline.clone(),
            opts,
        };
        // A stage only brings the next into its quadratic region: a few iterations.
        let lm = LmOptions {
            max_iter: opts.lm.max_iter.min(6),
            dtol: opts.lm.dtol.max(1.0),
            ..opts.lm
        };
        let rep = minimize(&mut stage, &x, &lm);
        iterations += rep.iterations;
        evaluations += rep.evaluations;
        if let Termination::EvaluationFailed(e) = &rep.termination {
            return Err(QuadFitError::Failed(e.clone()));
        }
        x = rep.x;
    }
    let fitted = window(n);
    let mut problem = SwingProblem {
        base: model,
        trace: &fitted,
        fric: fric.clone(),
        baseline: baseline.clone(),
        opts,
    };
    let rep = minimize(&mut problem, &x, &opts.lm);
    if let Termination::EvaluationFailed(e) = &rep.termination {
        return Err(QuadFitError::Failed(e.clone()));
    }
    let n_data = 2 * n;
    let ssr: f64 = rep.residuals[..n_data].iter().map(|v| v * v).sum();
    let kappa2 = (ssr / n_data as f64).max(1.0);
    let jd = rep.jacobian.rows(0, n_data);
    let mut post = jd.tr_mul(&jd) / kappa2;
    for i in 0..pf {
        post[(i, i)] += 1.0 / opts.prior_relative_sd.powi(2);
    }
    for i in [pf + 2, pf + 3] {
        post[(i, i)] += 1.0 / opts.zero_prior_sd_rad.powi(2);
    }
    let cov = inverse_spd(&post);
    let sd = |i: usize| cov[(i, i)].max(0.0).sqrt();
    let params = (0..pf)
        .map(|i| {
            let base = baseline[i];
            let (map_value, posterior_sd) = (rep.x[i] * base, sd(i) * base);
            let prior_sd = opts.prior_relative_sd * base;
            let informed = sd(i) < opts.prior_relative_sd / opts.informed_factor;
            let (value, ci95, status) = if informed {
                let ci = [
                    map_value - Z95 * posterior_sd,
                    map_value + Z95 * posterior_sd,
                ];
                let v = opts.thresholds.judge(ci, map_value, Some(base));
                (
                    map_value,
                    ci,
                    if v.identifiable {
                        v.status
                    } else {
                        Status::Unknown
                    },
                )
            } else {
                (
                    base,
                    [(base - Z95 * prior_sd).max(0.0), base + Z95 * prior_sd],
                    Status::Unknown,
                )
            };
            QuadEstimate {
                param: fric[i],
                baseline: base,
                prior_sd,
                value,
                map_value,
                posterior_sd,
                ci95,
                informed,
                status,
            }
        })
        .collect();
    let nuis = |i: usize| Nuisance {
        value: rep.x[pf + i],
        sd: sd(pf + i),
    };
    let whole = SwingProblem {
        base: model,
        trace,
        fric: fric.clone(),
        baseline: baseline.clone(),
        opts,
    };
    let (a, b) = whole.sim(&rep.x).map_err(QuadFitError::Failed)?;
    let (za, zb) = (rep.x[pf + 2], rep.x[pf + 3]);
    Ok(QuadFit {
        params,
        release_alpha_rad: nuis(0),
        release_rate_rad_s: nuis(1),
        alpha_zero_rad: nuis(2),
        beta_zero_rad: nuis(3),
        rmse_rad: (ssr / n_data as f64).sqrt() * opts.angle_noise_rad,
        samples_fitted: n,
        noise_rad: opts.angle_noise_rad * kappa2.sqrt(),
        residual_alpha_rad: a
            .iter()
            .zip(trace.alpha_rad)
            .map(|(f, m)| m - f - za)
            .collect(),
        fitted_alpha_rad: a.iter().map(|v| v + za).collect(),
        fitted_beta_rad: b.iter().map(|v| v + zb).collect(),
        iterations: rep.iterations + iterations,
        evaluations: rep.evaluations + evaluations,
        termination: rep.termination,
    })
}

/// Samples to fit: until the measured α last departs by more than 10 σ from its final level
/// (the mean of its last tenth), plus 10 % of that (at least 10 samples); all when it never
/// settles.
fn fitted_window(alpha_rad: &[f64], sigma_rad: f64) -> usize {
    let n = alpha_rad.len();
    let tail = (n / 10).max(1);
    let last = alpha_rad[n - tail..].iter().sum::<f64>() / tail as f64;
    let moving = alpha_rad
        .iter()
        .rposition(|a| (a - last).abs() > 10.0 * sigma_rad)
        .map_or(0, |k| k + 1);
    (moving + (moving / 10).max(10)).min(n)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lift::geometry::builtin_160ec;
    use crate::numerics::noise::Noise;

    /// The paper's Fig 12 swing (γ = 70°, released at rest 10.1° below the rest angle) on a model whose
    /// friction in `joint` has drifted by `factor`, 500 Hz, both channels with 0.05° noise and
    /// the given sensor zeros.
    pub(crate) fn drifted_swing(
        joint: QJoint,
        factor: f64,
        zeros_rad: (f64, f64),
        seed: u64,
    ) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let mut m = Quadrangle::new(builtin_160ec(), 70f64.to_radians());
        m.friction.dry_mu[joint.index()] *= factor;
        let t: Vec<f64> = (0..=6000).map(|k| f64::from(k) * 0.002).collect();
        let a0 = m.rest_alpha_rad(0.4).expect("rest at 70°") - f64::to_radians(10.1);
        let run = simulate_swing(&m, &t, a0, 0.0, &SwingOptions::default()).unwrap();
        let mut rng = Noise::new(seed);
        let s = 0.05f64.to_radians();
        let a = run
            .alpha_rad
            .iter()
            .map(|v| v + zeros_rad.0 + s * rng.normal())
            .collect();
        let b = run
            .beta_rad
            .iter()
            .map(|v| v + zeros_rad.1 + s * rng.normal())
            .collect();
        (t, a, b)
    }

    /// Issue 5, point 3: a swing with J3's dry friction drifted ×2 (truth 0.40, Table 4 0.20)
    /// is fitted; the truth lies in J3's interval, J3 is flagged as it is informed, no other
    /// joint is flagged, the sensor zeros are recovered, and uninformed parameters stay at
    /// baseline, `unknown`.
    #[test]
    fn drifted_j3_is_recovered_and_flagged_alone() {
        let zeros = (0.3f64.to_radians(), -0.2f64.to_radians());
        let (t, a, b) = drifted_swing(QJoint::J3, 2.0, zeros, 5);
        let base = Quadrangle::new(builtin_160ec(), 70f64.to_radians());
        let clock = std::time::Instant::now();
        let fit = fit_swing(
            &base,
            &SwingTrace {
                t_s: &t,
                alpha_rad: &a,
                beta_rad: &b,
            },
            &QuadFitOptions::default(),
        )
        .unwrap();
        eprintln!(
            "fit {:?}: {} iterations, {} evaluations, {:?}, rmse {:.4} deg",
            clock.elapsed(),
            fit.iterations,
            fit.evaluations,
            fit.termination,
            fit.rmse_rad.to_degrees()
        );
        for e in &fit.params {
            eprintln!(
                "{:>3}.{:<7} {:.5} [{:.5}, {:.5}] MAP {:.5} base {:.5} sd {:.2e} {} {:?}",
                e.param.joint().name(),
                e.param.kind(),
                e.value,
                e.ci95[0],
                e.ci95[1],
                e.map_value,
                e.baseline,
                e.posterior_sd,
                if e.informed { "informed" } else { "-" },
                e.status
            );
        }
        let j3 = fit.estimate(QuadParam::Dry(QJoint::J3));
        assert!(j3.informed, "{j3:?}");
        assert!(j3.ci95[0] <= 0.40 && 0.40 <= j3.ci95[1], "{j3:?}");
        assert!(matches!(
            fit.joint_status(QJoint::J3),
            Status::Watch | Status::Alarm
        ));
        for j in QJoint::ALL.into_iter().filter(|j| *j != QJoint::J3) {
            let s = fit.joint_status(j);
            assert!(!matches!(s, Status::Watch | Status::Alarm), "{j:?} {s:?}");
        }
        for e in fit.params.iter().filter(|e| !e.informed) {
            assert_eq!((e.value, e.status), (e.baseline, Status::Unknown));
        }
        let za = fit.alpha_zero_rad;
        assert!((za.value - zeros.0).abs() < 3.0 * za.sd, "{za:?}");
        assert!((fit.beta_zero_rad.value - zeros.1).abs() < 3.0 * fit.beta_zero_rad.sd);
        assert!(fit.rmse_rad < 0.06f64.to_radians());
    }
}

//! Levenberg–Marquardt for bounded nonlinear least squares: minimise ½‖r(x)‖² with
//! lower/upper bounds, Marquardt's diagonal scaling and Nielsen's damping update.
//!
//! One small problem trait, an explicit termination reason. Bounds are handled by projection
//! with an active set: a parameter on its bound whose gradient pushes outward is held for the step.

use nalgebra::{DMatrix, DVector};

/// A least-squares problem: residuals and their Jacobian at x.
pub trait Problem {
    fn n_params(&self) -> usize;
    fn n_residuals(&self) -> usize;
    /// Fill `r` (length n_residuals) and `jac` (n_residuals × n_params). An `Err` marks x as
    /// infeasible: the step is rejected and the damping raised.
    fn eval(&mut self, x: &[f64], r: &mut [f64], jac: &mut DMatrix<f64>) -> Result<(), String>;
    fn lower_bounds(&self) -> Vec<f64> {
        vec![f64::NEG_INFINITY; self.n_params()]
    }
    fn upper_bounds(&self) -> Vec<f64> {
        vec![f64::INFINITY; self.n_params()]
    }
}

/// Why the iteration stopped.
#[derive(Debug, Clone, PartialEq)]
pub enum Termination {
    /// Relative reduction of the cost below `ftol`.
    CostConverged,
    /// Relative step below `xtol`.
    StepConverged,
    /// Scaled gradient below `gtol` (a stationary point, possibly on a bound).
    GradientConverged,
    /// The Gauss–Newton step would move the parameters by less than `dtol` standard errors.
    DecrementConverged,
    /// A trial step within `noise_sd` standard errors was rejected: the objective's
    /// evaluation noise, not its minimum, ends the descent there.
    NoiseFloor,
    /// A trial step within `cliff_sd` standard errors was rejected with the cost rising by over
    /// [`CLIFF_RHO`] times the decrease the quadratic model predicted: at that scale the objective
    /// is not the smooth function the model describes, and more damping retries the same step.
    Cliff,
    /// The damping grew without finding a better point.
    NoProgress,
    MaxIterations,
    /// The model could not be evaluated at the starting point.
    EvaluationFailed(String),
    /// The fit's budget ([`crate::numerics::budget`]) is spent or the fit was stopped.
    Budget,
    /// The quadratic model's minimum is above `give_up_cost` ([`LmOptions::give_up_cost`]):
    /// the fit cannot reach the level its caller needs, and stopped short of its own minimum.
    OutOfReach,
}

impl Termination {
    pub fn converged(&self) -> bool {
        matches!(
            self,
            Termination::CostConverged
                | Termination::StepConverged
                | Termination::GradientConverged
        )
    }
}

#[derive(Debug, Clone, Copy)]
pub struct LmOptions {
    pub max_iter: usize,
    pub ftol: f64,
    pub xtol: f64,
    pub gtol: f64,
    /// Stop when an undamped step's predicted reduction is at most dtol²·cost/m: with the
    /// residual variance s² ≈ 2·cost/m, that step moves the parameters by at most dtol standard
    /// errors (in the norm of JᵀJ/s²). 0 disables the test.
    pub dtol: f64,
    /// Stop when a rejected trial step is at most this many standard errors long (the norm of
    /// `dtol`, with s² = 2·cost/m capped at 1: residuals in units of their noise sd): for
    /// objectives whose evaluation carries noise (an adaptive integrator's step choice) larger
    /// than what such a step changes. 0 (the default) disables the test.
    pub noise_sd: f64,
    /// Stop when a rejected trial step at most this many standard errors long (the norm of
    /// `noise_sd`) is a *cliff*: its cost rose by more than −[`CLIFF_RHO`] times the decrease
    /// the quadratic model predicted (ρ < [`CLIFF_RHO`]). For objectives that are not smooth at
    /// that scale (a lift's open-loop divergence at the end of the lowering amplifies the
    /// integrator's tolerance-level differences: `lift::fit`). 0 (the default) disables it.
    pub cliff_sd: f64,
    /// Stop once the cost cannot come down to this: at the start of an iteration, after
    /// [`GIVE_UP_STEPS`] accepted steps in a row whose gain ratio ρ was at least
    /// [`GIVE_UP_MIN_RHO`] (the quadratic model described them), the unconstrained Gauss–Newton
    /// minimum, cost − ½ gᵀ(JᵀJ)⁻¹g, is above it ([`Termination::OutOfReach`]). Measured on lift
    /// refits (`lift::effects`): that minimum is optimistic — near the end 5–7× under the cost
    /// the fit then reached — but from a far start it can fall 25× over the first accepted
    /// step, hence the steps asked first. For a caller that only uses a fit reaching a
    /// level (a candidate effect must halve a residual: `lift::effects`). Bounds only raise the
    /// minimum, so they are left out. 0 (the default) disables the test.
    pub give_up_cost: f64,
}

/// The gain ratio the last accepted step must have reached for [`LmOptions::give_up_cost`] to
/// end a fit: its reduction at least half what the quadratic model predicted.
pub const GIVE_UP_MIN_RHO: f64 = 0.5;

/// Accepted steps in a row with ρ ≥ [`GIVE_UP_MIN_RHO`] before [`LmOptions::give_up_cost`] is
/// tested.
pub const GIVE_UP_STEPS: usize = 2;

/// The gain ratio ρ = actual / predicted decrease below which a rejected trial is a cliff
/// (`LmOptions::cliff_sd`): the cost rose by over 5× what the quadratic model said it would drop.
pub const CLIFF_RHO: f64 = -5.0;

impl Default for LmOptions {
    fn default() -> Self {
        Self {
            max_iter: 100,
            ftol: 1e-10,
            xtol: 1e-10,
            gtol: 1e-10,
            dtol: 0.0,
            noise_sd: 0.0,
            cliff_sd: 0.0,
            give_up_cost: 0.0,
        }
    }
}

#[derive(Debug, Clone)]
pub struct LmReport {
    pub x: Vec<f64>,
    /// ½‖r‖² at x.
    pub cost: f64,
    pub residuals: Vec<f64>,
    pub jacobian: DMatrix<f64>,
    pub iterations: usize,
    /// Model evaluations, the start's included.
    pub evaluations: usize,
    /// Trial steps rejected without an evaluation (their predicted change was an increase).
    pub skipped: usize,
    /// Evaluated trial steps that were rejected (the start's and accepted ones are the rest).
    pub rejected: usize,
    /// Of the rejected, the cliffs: ρ < [`CLIFF_RHO`], whether or not `cliff_sd` ended the fit.
    pub cliffs: usize,
    pub termination: Termination,
    /// JᵀJ of `jacobian` ([`gram`]) when the last iteration formed it (no step accepted after):
    /// for the covariance, which would form it again.
    pub gram: Option<DMatrix<f64>>,
}

/// JᵀJ from its upper triangle, mirrored: the same column dot products `tr_mul` takes (so the
/// same matrix to the bit), 15 of them instead of 25 for five parameters (issue 38).
/// Over the columns as slices ([`crate::numerics::stats::dot`]: nalgebra's sums, to the bit).
pub fn gram(jac: &DMatrix<f64>) -> DMatrix<f64> {
    let n = jac.ncols();
    let cols: Vec<&[f64]> = jac.as_slice().chunks_exact(jac.nrows().max(1)).collect();
    let mut a = DMatrix::zeros(n, n);
    for i in 0..n.min(cols.len()) {
        for j in i..n.min(cols.len()) {
            let d = crate::numerics::stats::dot(cols[i], cols[j]);
            a[(i, j)] = d;
            a[(j, i)] = d;
        }
    }
    a
}

/// Jᵀr over the columns as slices: nalgebra's `tr_mul` to the bit ([`gram`]).
pub fn gradient(jac: &DMatrix<f64>, r: &[f64]) -> DVector<f64> {
    let m = jac.nrows();
    let mut g = DVector::zeros(jac.ncols());
    if m == 0 {
        return g;
    }
    for (gi, col) in g.iter_mut().zip(jac.as_slice().chunks_exact(m)) {
        *gi = crate::numerics::stats::dot(col, r);
    }
    g
}

/// An m × n zero matrix from a zeroed allocation (`calloc`: fresh pages come zero, where
/// `DMatrix::zeros` writes every element; issue 38, session 22): the same zeros.
fn zeroed(m: usize, n: usize) -> DMatrix<f64> {
    DMatrix::from_vec(m, n, vec![0.0; m * n])
}

/// Nielsen's damping increase after a step that failed or was rejected: λ·ν, ν doubled.
/// False once λ passes 10²⁰ (no step of any length helped).
fn raise_damping(lambda: &mut f64, nu: &mut f64) -> bool {
    *lambda *= *nu;
    *nu *= 2.0;
    *lambda <= 1e20
}

/// `x0` projected into the problem's bounds.
pub fn project<P: Problem>(p: &P, x0: &[f64]) -> Vec<f64> {
    let (lb, ub) = (p.lower_bounds(), p.upper_bounds());
    x0.iter()
        .zip(&lb)
        .zip(&ub)
        .map(|((x, l), u)| x.clamp(*l, *u))
        .collect()
}

/// Minimise from `x0` (projected into the bounds first).
pub fn minimize<P: Problem>(p: &mut P, x0: &[f64], opts: &LmOptions) -> LmReport {
    let (n, m) = (p.n_params(), p.n_residuals());
    let x = project(p, x0);
    let mut r = vec![0.0; m];
    let mut jac = zeroed(m, n);
    if let Err(e) = crate::numerics::budget::charge() {
        return LmReport {
            x,
            cost: f64::INFINITY,
            residuals: r,
            jacobian: jac,
            iterations: 0,
            evaluations: 0,
            skipped: 0,
            rejected: 0,
            cliffs: 0,
            termination: Termination::EvaluationFailed(e.to_string()),
            gram: None,
        };
    }
    if let Err(e) = p.eval(&x, &mut r, &mut jac) {
        return LmReport {
            x,
            cost: f64::INFINITY,
            residuals: r,
            jacobian: jac,
            iterations: 0,
            evaluations: 1,
            skipped: 0,
            rejected: 0,
            cliffs: 0,
            termination: Termination::EvaluationFailed(e),
            gram: None,
        };
    }
    minimize_evaluated(p, x, r, jac, opts)
}

/// Minimise from a start the caller has already evaluated (`x` inside the bounds, `r` and
/// `jac` its residuals and Jacobian): for a caller that looked at the start before deciding
/// how to fit. That evaluation is counted.
pub fn minimize_evaluated<P: Problem>(
    p: &mut P,
    mut x: Vec<f64>,
    mut r: Vec<f64>,
    mut jac: DMatrix<f64>,
    opts: &LmOptions,
) -> LmReport {
    let (n, m) = (p.n_params(), p.n_residuals());
    let (lb, ub) = (p.lower_bounds(), p.upper_bounds());
    let mut evaluations = 1;
    let (mut skipped, mut rejected, mut cliffs) = (0, 0, 0);
    let mut cost = 0.5 * r.iter().map(|v| v * v).sum::<f64>();
    let mut r_try = vec![0.0; m];
    let mut jac_try = zeroed(m, n);
    let mut lambda = -1.0;
    let mut nu = 2.0;
    let mut termination = Termination::MaxIterations;
    let mut iterations = 0;
    // Accepted steps in a row whose gain ratio reached GIVE_UP_MIN_RHO (`give_up_cost`).
    let mut described = 0;
    // JᵀJ of the current `jac`, when formed since it was last replaced.
    let mut last_gram: Option<DMatrix<f64>> = None;
    'outer: while iterations < opts.max_iter {
        iterations += 1;
        let a = gram(&jac);
        last_gram = Some(a.clone());
        // Jᵀr over slices: no m-sized copy per iteration.
        let g = gradient(&jac, &r);
        if opts.give_up_cost > 0.0 && described >= GIVE_UP_STEPS && cost > opts.give_up_cost {
            let floor = a
                .clone()
                .cholesky()
                .map(|ch| cost - 0.5 * g.dot(&ch.solve(&g)));
            if floor.is_some_and(|f| f > opts.give_up_cost) {
                termination = Termination::OutOfReach;
                break 'outer;
            }
        }
        let diag: Vec<f64> = (0..n).map(|i| a[(i, i)].max(1e-300)).collect();
        // MINPACK-style gradient test: cosine between r and each column of J.
        let rnorm = (2.0 * cost).sqrt();
        let gmax = (0..n)
            .map(|i| {
                if diag[i] > 1e-300 && rnorm > 0.0 {
                    g[i].abs() / (diag[i].sqrt() * rnorm)
                } else {
                    0.0
                }
            })
            .fold(0.0, f64::max);
        if gmax <= opts.gtol || cost == 0.0 {
            termination = Termination::GradientConverged;
            break;
        }
        if lambda < 0.0 {
            // Small: output-error problems here are well modelled by their linearisation
            // (ρ ≈ 1), but ill-conditioned, so Marquardt's diag(JᵀJ) damping would throttle
            // the weak directions; it grows fast enough when a step fails.
            lambda = 1e-6;
        }
        // Active set: on a bound and the descent direction −g points outward.
        let free: Vec<usize> = (0..n)
            .filter(|&i| !((x[i] <= lb[i] && g[i] > 0.0) || (x[i] >= ub[i] && g[i] < 0.0)))
            .collect();
        loop {
            let k = free.len();
            let mut ak = DMatrix::zeros(k, k);
            let mut gk = DVector::zeros(k);
            for (ii, &i) in free.iter().enumerate() {
                gk[ii] = -g[i];
                for (jj, &j) in free.iter().enumerate() {
                    ak[(ii, jj)] = a[(i, j)];
                }
                ak[(ii, ii)] += lambda * diag[i];
            }
            let delta_k = match ak.clone().cholesky() {
                Some(ch) => ch.solve(&gk),
                None => match ak.lu().solve(&gk) {
                    Some(d) => d,
                    None => {
                        if !raise_damping(&mut lambda, &mut nu) {
                            termination = Termination::NoProgress;
                            break 'outer;
                        }
                        continue;
                    }
                },
            };
            let mut x_try = x.clone();
            for (ii, &i) in free.iter().enumerate() {
                x_try[i] = (x[i] + delta_k[ii]).clamp(lb[i], ub[i]);
            }
            let step: Vec<f64> = (0..n).map(|i| x_try[i] - x[i]).collect();
            let step_v = DVector::from_column_slice(&step);
            // The quadratic model's curvature term ½δᵀAδ and predicted reduction for the
            // projected step.
            let quad = 0.5 * step_v.dot(&(&a * &step_v));
            let pred = -(step_v.dot(&g) + quad);
            if opts.dtol > 0.0
                && lambda <= 1e-4
                && pred >= 0.0
                && pred <= opts.dtol * opts.dtol * cost / m as f64
            {
                termination = Termination::DecrementConverged;
                break 'outer;
            }
            // Whether the step is within `sd` standard errors (the noise-floor and cliff tests).
            let within = |sd: f64| sd > 0.0 && quad <= sd * sd * (cost / m as f64).min(0.5);
            let within_floor = || within(opts.noise_sd);
            // A step the quadratic model says raises the cost (pred < 0: only a projected step
            // can) is rejected whatever its evaluation shows (ρ = −1 below): raise the damping
            // without running the model. Only the noise-floor test reads such a trial's outcome
            // (whether it ran), so a step short enough for that test is still evaluated. Same
            // iterates and result as evaluating it (`examples/lift_fit_dump`); realistic-noise
            // lifts step into a friction's zero bound often far from the optimum
            // (`examples/lift_fleet_profile`).
            if pred < 0.0 && !within_floor() {
                skipped += 1;
                if !raise_damping(&mut lambda, &mut nu) {
                    termination = Termination::NoProgress;
                    break 'outer;
                }
                continue;
            }
            if crate::numerics::budget::charge().is_err() {
                termination = Termination::Budget;
                break 'outer;
            }
            evaluations += 1;
            let ok = p.eval(&x_try, &mut r_try, &mut jac_try).is_ok();
            let cost_try = if ok {
                0.5 * r_try.iter().map(|v| v * v).sum::<f64>()
            } else {
                f64::INFINITY
            };
            let rho = if pred > 0.0 {
                (cost - cost_try) / pred
            } else {
                -1.0
            };
            if ok && cost_try.is_finite() && cost_try < cost && rho > 0.0 {
                let xnorm = x
                    .iter()
                    .zip(&diag)
                    .map(|(v, d)| (v * d.sqrt()).powi(2))
                    .sum::<f64>()
                    .sqrt();
                let snorm = step
                    .iter()
                    .zip(&diag)
                    .map(|(v, d)| (v * d.sqrt()).powi(2))
                    .sum::<f64>()
                    .sqrt();
                let reduction = (cost - cost_try) / cost;
                x = x_try;
                described = if rho >= GIVE_UP_MIN_RHO {
                    described + 1
                } else {
                    0
                };
                std::mem::swap(&mut r, &mut r_try);
                std::mem::swap(&mut jac, &mut jac_try);
                last_gram = None;
                cost = cost_try;
                // Nielsen's update, allowed to shrink by 10× per step (not 3×) when ρ ≈ 1.
                lambda = (lambda * 0.1f64.max(1.0 - (2.0 * rho - 1.0).powi(3))).max(1e-15);
                nu = 2.0;
                if reduction <= opts.ftol && rho > 0.5 {
                    termination = Termination::CostConverged;
                    break 'outer;
                }
                if snorm <= opts.xtol * (xnorm + opts.xtol) {
                    termination = Termination::StepConverged;
                    break 'outer;
                }
                break;
            }
            rejected += 1;
            let cliff = ok && rho < CLIFF_RHO;
            cliffs += usize::from(cliff);
            // Rejected. If even the quadratic model promises no relative reduction above ftol,
            // we are at the minimum to working precision (MINPACK's test on the prediction).
            if ok && pred >= 0.0 && pred <= opts.ftol * cost {
                termination = Termination::CostConverged;
                break 'outer;
            }
            // A step no longer than `noise_sd` standard errors made the cost worse: what it
            // could gain is below the objective's evaluation noise, and a shorter step would
            // only chase that noise. The residuals are in units of their noise sd, so the
            // norm's s² = 2·cost/m is capped at 1: far from the minimum a large misfit would
            // otherwise make every rejected step look short (a lift plain fit stopped at 60 mm).
            if ok && within_floor() {
                termination = Termination::NoiseFloor;
                break 'outer;
            }
            // A cliff within `cliff_sd`: the damping would walk up ×2, ×4, ×8 retrying nearly
            // the same step, whose cost is decided by the objective's roughness, not its slope.
            if cliff && within(opts.cliff_sd) {
                termination = Termination::Cliff;
                break 'outer;
            }
            if !raise_damping(&mut lambda, &mut nu) {
                termination = Termination::NoProgress;
                break 'outer;
            }
        }
    }
    LmReport {
        x,
        cost,
        residuals: r,
        jacobian: jac,
        iterations,
        evaluations,
        skipped,
        rejected,
        cliffs,
        termination,
        gram: last_gram,
    }
}

#[cfg(test)]
mod tests;

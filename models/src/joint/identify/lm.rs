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
mod tests {
    use super::*;

    /// MINPACK/NIST-style exponential decay y = a·exp(−b·t) + c.
    struct ExpDecay {
        t: Vec<f64>,
        y: Vec<f64>,
    }
    impl Problem for ExpDecay {
        fn n_params(&self) -> usize {
            3
        }
        fn n_residuals(&self) -> usize {
            self.t.len()
        }
        fn eval(&mut self, x: &[f64], r: &mut [f64], jac: &mut DMatrix<f64>) -> Result<(), String> {
            for (k, &t) in self.t.iter().enumerate() {
                let e = (-x[1] * t).exp();
                r[k] = x[0] * e + x[2] - self.y[k];
                jac[(k, 0)] = e;
                jac[(k, 1)] = -x[0] * t * e;
                jac[(k, 2)] = 1.0;
            }
            Ok(())
        }
    }

    /// Golden values from SciPy 1.17.1 (MINPACK lmder):
    /// `least_squares(lambda p: p[0]*np.exp(-p[1]*t)+p[2]-y, [1,1,0], method='lm', xtol=1e-15, ftol=1e-15, gtol=1e-15)`
    /// with t = linspace(0, 4, 9), y = [5.1, 3.3, 2.4, 1.62, 1.2, 0.91, 0.72, 0.61, 0.55] gives
    /// x = [4.65747683, 0.8960543, 0.41568434], cost ½‖r‖² = 0.008201899259831395.
    #[test]
    fn exponential_decay_matches_scipy_golden_and_is_stationary() {
        let t: Vec<f64> = (0..9).map(|i| i as f64 * 0.5).collect();
        let y = vec![5.1, 3.3, 2.4, 1.62, 1.2, 0.91, 0.72, 0.61, 0.55];
        let mut p = ExpDecay { t, y };
        let rep = minimize(
            &mut p,
            &[1.0, 1.0, 0.0],
            &LmOptions {
                ftol: 1e-15,
                xtol: 1e-15,
                gtol: 1e-15,
                dtol: 0.0,
                noise_sd: 0.0,
                cliff_sd: 0.0,
                give_up_cost: 0.0,
                max_iter: 500,
            },
        );
        assert!(rep.termination.converged(), "{:?}", rep.termination);
        // Stationarity: Jᵀr = 0.
        let g = rep
            .jacobian
            .tr_mul(&DVector::from_column_slice(&rep.residuals));
        assert!(g.amax() < 1e-7, "gradient {g}");
        let golden = [4.65747683, 0.8960543, 0.41568434];
        assert!(
            (rep.cost - 0.008201899259831395).abs() < 1e-12,
            "cost {}",
            rep.cost
        );
        for (x, gx) in rep.x.iter().zip(golden) {
            assert!((x - gx).abs() < 1e-6, "{:?} vs {golden:?}", rep.x);
        }
    }

    /// `give_up_cost`: a level under the problem's minimum (cost 0.0082) ends the fit early,
    /// out of reach, before the LM's own stop; a level above it changes nothing.
    #[test]
    fn a_level_out_of_reach_ends_the_fit_early_and_one_within_reach_changes_nothing() {
        let t: Vec<f64> = (0..9).map(|i| i as f64 * 0.5).collect();
        let y = vec![5.1, 3.3, 2.4, 1.62, 1.2, 0.91, 0.72, 0.61, 0.55];
        let run = |give_up_cost: f64| {
            minimize(
                &mut ExpDecay {
                    t: t.clone(),
                    y: y.clone(),
                },
                &[1.0, 1.0, 0.0],
                &LmOptions {
                    ftol: 1e-15,
                    xtol: 1e-15,
                    gtol: 1e-15,
                    max_iter: 500,
                    give_up_cost,
                    ..LmOptions::default()
                },
            )
        };
        let full = run(0.0);
        assert!(full.termination.converged(), "{:?}", full.termination);
        let out = run(0.004);
        assert_eq!(out.termination, Termination::OutOfReach);
        assert!(out.cost > 0.004 && out.evaluations < full.evaluations);
        let within = run(0.05);
        assert_eq!(within.termination, full.termination);
        assert_eq!(within.x, full.x);
        assert_eq!(within.evaluations, full.evaluations);
    }

    #[test]
    fn a_pre_evaluated_start_continues_exactly_as_minimize() {
        let t: Vec<f64> = (0..9).map(|i| i as f64 * 0.5).collect();
        let y = vec![5.1, 3.3, 2.4, 1.62, 1.2, 0.91, 0.72, 0.61, 0.55];
        let mut p = ExpDecay { t, y };
        let opts = LmOptions::default();
        let a = minimize(&mut p, &[1.0, 1.0, 0.0], &opts);
        let x0 = project(&p, &[1.0, 1.0, 0.0]);
        let (mut r, mut jac) = (vec![0.0; 9], DMatrix::zeros(9, 3));
        p.eval(&x0, &mut r, &mut jac).unwrap();
        let b = minimize_evaluated(&mut p, x0, r, jac, &opts);
        assert_eq!(a.x, b.x);
        assert_eq!(a.evaluations, b.evaluations);
        assert_eq!(a.iterations, b.iterations);
        assert_eq!(a.termination, b.termination);
    }

    /// `gram` and `gradient` are nalgebra's JᵀJ and Jᵀr to the bit, over a length that is not
    /// a multiple of eight.
    #[test]
    fn gram_and_gradient_are_nalgebras_products_to_the_bit() {
        let m = 2061;
        let jac = DMatrix::from_fn(m, 5, |k, j| ((k * 7 + j * 13) as f64 * 0.37).sin() * 1e3);
        let r: Vec<f64> = (0..m).map(|k| (k as f64 * 0.11).cos()).collect();
        assert_eq!(gram(&jac), jac.tr_mul(&jac));
        assert_eq!(
            gradient(&jac, &r),
            jac.tr_mul(&DVector::from_column_slice(&r))
        );
    }

    /// Rosenbrock as least squares, r = [10(x1 − x0²), 1 − x0]: minimum (1, 1).
    struct Rosen;
    impl Problem for Rosen {
        fn n_params(&self) -> usize {
            2
        }
        fn n_residuals(&self) -> usize {
            2
        }
        fn eval(&mut self, x: &[f64], r: &mut [f64], j: &mut DMatrix<f64>) -> Result<(), String> {
            r[0] = 10.0 * (x[1] - x[0] * x[0]);
            r[1] = 1.0 - x[0];
            j[(0, 0)] = -20.0 * x[0];
            j[(0, 1)] = 10.0;
            j[(1, 0)] = -1.0;
            j[(1, 1)] = 0.0;
            Ok(())
        }
    }

    #[test]
    fn rosenbrock_unbounded_and_with_an_active_bound() {
        let rep = minimize(&mut Rosen, &[-1.2, 1.0], &LmOptions::default());
        assert!(
            (rep.x[0] - 1.0).abs() < 1e-8 && (rep.x[1] - 1.0).abs() < 1e-8,
            "{:?}",
            rep.x
        );
        // With x0 ≤ 0.5 the constrained optimum sits on the bound: x0 = 0.5, x1 = 0.25.
        struct Bounded;
        impl Problem for Bounded {
            fn n_params(&self) -> usize {
                2
            }
            fn n_residuals(&self) -> usize {
                2
            }
            fn eval(
                &mut self,
                x: &[f64],
                r: &mut [f64],
                j: &mut DMatrix<f64>,
            ) -> Result<(), String> {
                Rosen.eval(x, r, j)
            }
            fn upper_bounds(&self) -> Vec<f64> {
                vec![0.5, f64::INFINITY]
            }
        }
        let rep = minimize(&mut Bounded, &[-1.2, 1.0], &LmOptions::default());
        assert!(
            (rep.x[0] - 0.5).abs() < 1e-9 && (rep.x[1] - 0.25).abs() < 1e-7,
            "{:?} {:?}",
            rep.x,
            rep.termination
        );
    }

    /// Straight-line fit whose every evaluation adds a pseudo-random offset to the residuals,
    /// a function of x (as an adaptive integrator's step choice is): the cost is noisy by
    /// several units where one standard error of the slope changes it by ½.
    struct NoisyLine {
        t: Vec<f64>,
        y: Vec<f64>,
    }
    impl Problem for NoisyLine {
        fn n_params(&self) -> usize {
            2
        }
        fn n_residuals(&self) -> usize {
            self.t.len()
        }
        fn eval(&mut self, x: &[f64], r: &mut [f64], jac: &mut DMatrix<f64>) -> Result<(), String> {
            // A hash of x's bits: the same x, the same noise.
            let h = (x[0].to_bits() ^ x[1].to_bits().rotate_left(17))
                .wrapping_mul(0x9e37_79b9_7f4a_7c15);
            let jitter = 0.3 * ((h >> 11) as f64 / (1u64 << 53) as f64 - 0.5);
            for (k, &t) in self.t.iter().enumerate() {
                r[k] = x[0] + x[1] * t - self.y[k] + jitter;
                jac[(k, 0)] = 1.0;
                jac[(k, 1)] = t;
            }
            Ok(())
        }
    }

    #[test]
    fn a_rejected_step_within_the_noise_ends_the_fit_near_the_minimum() {
        // y = 1 + 2t with unit-variance-like scatter: the exact least-squares line is known.
        let t: Vec<f64> = (0..200).map(|i| i as f64 / 20.0).collect();
        let y: Vec<f64> = t
            .iter()
            .enumerate()
            .map(|(k, t)| 1.0 + 2.0 * t + if k % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let opts = |noise_sd: f64| LmOptions {
            max_iter: 50,
            ftol: 1e-12,
            xtol: 1e-12,
            gtol: 1e-12,
            dtol: 0.0,
            noise_sd,
            cliff_sd: 0.0,
            give_up_cost: 0.0,
        };
        let quiet = minimize(
            &mut NoisyLine {
                t: t.clone(),
                y: y.clone(),
            },
            &[0.0, 0.0],
            &opts(3.0),
        );
        let chasing = minimize(
            &mut NoisyLine {
                t: t.clone(),
                y: y.clone(),
            },
            &[0.0, 0.0],
            &opts(0.0),
        );
        assert_eq!(quiet.termination, Termination::NoiseFloor);
        assert!(
            quiet.evaluations < chasing.evaluations,
            "{} vs {} evaluations",
            quiet.evaluations,
            chasing.evaluations
        );
        // Standard errors of intercept and slope with s² = 2·cost/m, from (JᵀJ)⁻¹.
        let n = t.len() as f64;
        let (st, stt) = (t.iter().sum::<f64>(), t.iter().map(|v| v * v).sum::<f64>());
        let det = n * stt - st * st;
        let s2 = 2.0 * quiet.cost / n;
        let sd = [(s2 * stt / det).sqrt(), (s2 * n / det).sqrt()];
        let sy: f64 = y.iter().sum();
        let sty: f64 = t.iter().zip(&y).map(|(a, b)| a * b).sum();
        let exact = [(stt * sy - st * sty) / det, (n * sty - st * sy) / det];
        for i in 0..2 {
            // The jitter (±0.15) shifts the intercept's optimum by up to 0.15 itself.
            let off = (quiet.x[i] - exact[i]).abs() - if i == 0 { 0.15 } else { 0.0 };
            assert!(
                off <= 3.0 * sd[i],
                "parameter {i}: {} vs {}",
                quiet.x[i],
                exact[i]
            );
        }
    }

    /// r = (x₀ + x₁ − 0.5, 0.1·(x₀ − x₁ − 3.5)) with x₀ ≤ 1: the unconstrained minimum (2, −1.5)
    /// lies beyond the bound, and clamping the Gauss–Newton step there raises the cost.
    struct ClampedPlane {
        calls: usize,
    }
    impl Problem for ClampedPlane {
        fn n_params(&self) -> usize {
            2
        }
        fn n_residuals(&self) -> usize {
            2
        }
        fn eval(&mut self, x: &[f64], r: &mut [f64], jac: &mut DMatrix<f64>) -> Result<(), String> {
            self.calls += 1;
            r[0] = x[0] + x[1] - 0.5;
            r[1] = 0.1 * (x[0] - x[1] - 3.5);
            jac[(0, 0)] = 1.0;
            jac[(0, 1)] = 1.0;
            jac[(1, 0)] = 0.1;
            jac[(1, 1)] = -0.1;
            Ok(())
        }
        fn upper_bounds(&self) -> Vec<f64> {
            vec![1.0, f64::INFINITY]
        }
    }

    #[test]
    fn a_projected_step_predicted_to_raise_the_cost_is_rejected_unevaluated() {
        let mut p = ClampedPlane { calls: 0 };
        let rep = minimize(&mut p, &[0.0, 0.0], &LmOptions::default());
        assert!(rep.skipped > 0, "no trial was skipped: {rep:?}");
        assert_eq!(rep.evaluations, p.calls, "every evaluation is counted");
        // On the bound x₀ = 1: 2(x₁ + 0.5) + 0.02(x₁ + 2.5) = 0.
        let x1 = -1.05 / 2.02;
        assert!((rep.x[0] - 1.0).abs() < 1e-9, "{:?}", rep.x);
        assert!((rep.x[1] - x1).abs() < 1e-6, "{:?} vs x₁ {x1}", rep.x);
    }

    /// r_i = (x − 1) + w_i with w = (½, −½, ½, −½), one parameter: the minimum is x = 1. The
    /// evaluation numbered k (0 = the start) adds `bump[k]` to every residual — the roughness of
    /// an objective whose evaluation is not smooth at the step's scale.
    struct RoughLine {
        bump: Vec<f64>,
        calls: usize,
    }
    impl Problem for RoughLine {
        fn n_params(&self) -> usize {
            1
        }
        fn n_residuals(&self) -> usize {
            4
        }
        fn eval(&mut self, x: &[f64], r: &mut [f64], jac: &mut DMatrix<f64>) -> Result<(), String> {
            let b = self.bump.get(self.calls).copied().unwrap_or(0.0);
            self.calls += 1;
            for (i, ri) in r.iter_mut().enumerate() {
                *ri = x[0] - 1.0 + if i % 2 == 0 { 0.5 } else { -0.5 } + b;
                jac[(i, 0)] = 1.0;
            }
            Ok(())
        }
    }

    #[test]
    fn a_cliff_within_cliff_sd_ends_the_fit_where_it_stood() {
        let opts = |cliff_sd: f64| LmOptions {
            cliff_sd,
            ..LmOptions::default()
        };
        let run = |x0: f64, bump: f64, cliff_sd: f64| {
            let mut p = RoughLine {
                bump: vec![0.0, bump],
                calls: 0,
            };
            minimize(&mut p, &[x0], &opts(cliff_sd))
        };
        // From x = −4 the first step is 5 long, 10 sd (½δ²·JᵀJ = 50 against s² capped at 1);
        // a bump of 20 makes its cost ~800 against 50.5 and a predicted drop of ~50: ρ ≈ −15.
        let cliff = run(-4.0, 20.0, 20.0);
        assert_eq!(cliff.termination, Termination::Cliff, "{cliff:?}");
        assert_eq!(cliff.evaluations, 2);
        assert_eq!((cliff.rejected, cliff.cliffs), (1, 1));
        assert_eq!(
            cliff.x,
            vec![-4.0],
            "the fit stays at its last accepted point"
        );
        // Without the rule the next trial (no bump) is taken and the fit reaches the minimum.
        let off = run(-4.0, 20.0, 0.0);
        assert_ne!(off.termination, Termination::Cliff);
        assert!((off.x[0] - 1.0).abs() < 1e-6, "{off:?}");
        // A cliff beyond `cliff_sd` (a 50-long step: 100 sd) does not end the fit.
        let far = run(-49.0, 200.0, 20.0);
        assert_ne!(far.termination, Termination::Cliff, "{far:?}");
        assert_eq!(
            far.cliffs, 1,
            "the cliff is counted though it did not stop the fit"
        );
        assert!((far.x[0] - 1.0).abs() < 1e-6, "{far:?}");
        // Nor does a plain rejection within it: a bump of 6 gives ρ ≈ −0.4, above CLIFF_RHO.
        let mild = run(-4.0, 6.0, 20.0);
        assert_ne!(mild.termination, Termination::Cliff, "{mild:?}");
        assert_eq!((mild.rejected, mild.cliffs), (1, 0));
        assert!((mild.x[0] - 1.0).abs() < 1e-6, "{mild:?}");
    }
}

//! Tests of the Levenberg–Marquardt solver: golden values from SciPy, bounds, the noise floor,
//! cliffs, and the Gram matrix and gradient against nalgebra's products.

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
        fn eval(&mut self, x: &[f64], r: &mut [f64], j: &mut DMatrix<f64>) -> Result<(), String> {
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
        let h =
            (x[0].to_bits() ^ x[1].to_bits().rotate_left(17)).wrapping_mul(0x9e37_79b9_7f4a_7c15);
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

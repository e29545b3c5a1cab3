//! Rosenbrock-W method ROS34PW2 (Rang & Angermann, BIT 45 (2005) 761–787): four stages, order 3
//! with an embedded order-2 error estimate, L-stable and stiffly accurate, linearly implicit.
//!
//! Why here: a smoothed dry-friction law is stiff at rest (|λ| ~ 10³/s), where an explicit
//! method is held at its stability limit; this one steps through rest at the accuracy's step.
//! It is a *W-method*: order 3 holds for any matrix W in place of ∂f/∂y, so W may be a
//! difference approximation, omit ∂f/∂t, and ignore the state's coupling into forward
//! sensitivities. W is block diagonal here: one `B × B` block (the state's Jacobian, `B` a
//! compile-time size so its LU unrolls) repeated over the state and every sensitivity column
//! appended after it.
//!
//! Allocation-free after construction. Dense output: the cubic Hermite interpolant through
//! both ends of the step (f at the new point is computed on acceptance and is the next step's
//! first stage, so it costs nothing extra).

// The coefficients are written as published (17 significant digits), so they can be checked
// against the paper digit by digit.
#![allow(clippy::excessive_precision)]

use std::ops::Range;

use super::{OdeError, Step, Tolerances};

/// A system y' = f(t, y) that also gives the `B × B` diagonal block of its W matrix (the
/// dimension a multiple of `B`).
pub trait WSystem<const B: usize> {
    fn dim(&self) -> usize;
    /// Write f(t, y) into `dy`; when `w` is given, also the block of W, an approximation of
    /// ∂f/∂y restricted to the block's components.
    fn rhs_w(
        &self,
        t: f64,
        y: &[f64],
        dy: &mut [f64],
        w: Option<&mut [[f64; B]; B]>,
    ) -> Result<(), OdeError>;

    /// Whether f can be evaluated in two parts, [`WSystem::rhs_head`] and
    /// [`WSystem::rhs_rest`] (default: no, every evaluation is [`WSystem::rhs_w`]). The stepper
    /// then computes a step's stages 2–4 for the block only, decides on the block's error, and
    /// computes the other components' stages only for a step the block's error accepts (when
    /// the error is controlled on the block alone): the same floating-point operations, in the
    /// same order, for every component, as without the split.
    ///
    /// A system that splits promises (the assumptions the split's bit-identity rests on):
    /// the block's components of f do not depend on `y[B..]`; `rhs_head` writes exactly the
    /// block's components `rhs_w` would (non-finite ones where `rhs_w` would write any), and
    /// `rhs_rest` the others; a `rhs_rest` failure is reported as `Ok(false)` (where `rhs_w`
    /// would have written non-finite values into every component), after which the system is
    /// left as the failed full evaluation at that stage would have left it; and `rhs_rest`
    /// fails only where `rhs_head` at the same point succeeds with finite values and `rhs_w`
    /// would have failed (on a step the block's error rejects, such a failure goes unseen: the
    /// split is exact only where it cannot happen).
    fn splits(&self) -> bool {
        false
    }

    /// The block's components of f(t, y) into `dy[..B]`, keeping in stage slot `slot` (0, 1,
    /// 2 for stages 2, 3, 4) what [`WSystem::rhs_rest`] needs. `y[B..]` is not the stage's.
    fn rhs_head(&self, slot: usize, t: f64, y: &[f64], dy: &mut [f64]) -> Result<(), OdeError> {
        let _ = slot;
        self.rhs_w(t, y, dy, None)
    }

    /// The other components of f at the (t, y) of the last [`WSystem::rhs_head`] in `slot`
    /// (`y` now whole) into `dy[B..]`; `Ok(false)` if the full evaluation would have failed.
    fn rhs_rest(&self, slot: usize, t: f64, y: &[f64], dy: &mut [f64]) -> Result<bool, OdeError> {
        let _ = (slot, t, y, dy);
        Ok(true)
    }
}

/// Which part of f a pass over the stages evaluates.
#[derive(Clone, Copy, PartialEq)]
enum Part {
    /// Every component, by [`WSystem::rhs_w`].
    Whole,
    /// The block's, by [`WSystem::rhs_head`].
    Head,
    /// The others, by [`WSystem::rhs_rest`] (after a `Head` pass on the same step).
    Rest,
}

// The method's coefficients in the form k_i = h f(y₀ + Σ a_ij k_j) + h W Σ_{j≤i} γ_ij k_j
// (Hairer & Wanner II, IV.7, (7.4) with W), y₁ = y₀ + Σ b_i k_i (b: `WEIGHTS`, the embedded
// b̂: `WEIGHTS_HAT`); Rang & Angermann's Table of
// ROS34PW2. Stage times: t₀ + α_i h with α_i = Σ_j a_ij (W has no ∂f/∂t column).
const GAMMA: f64 = 4.358_665_215_084_59e-1;
const A21: f64 = 8.717_330_430_169_180_1e-1;
const A31: f64 = 8.445_706_001_536_942_3e-1;
const A32: f64 = -1.129_906_423_648_418_5e-1;
// a41 = a42 = 0, a43 = 1.
const G21: f64 = -8.717_330_430_169_180_1e-1;
const G31: f64 = -9.033_805_701_304_408_2e-1;
const G32: f64 = 5.418_067_238_809_532_6e-2;
const G41: f64 = 2.421_238_070_609_534_6e-1;
const G42: f64 = -1.223_250_583_904_514_7;
const G43: f64 = 5.452_602_553_351_021_4e-1;
const WEIGHTS: [f64; 4] = [
    2.421_238_070_609_534_6e-1,
    -1.223_250_583_904_514_7,
    1.545_260_255_335_102,
    GAMMA,
];
const WEIGHTS_HAT: [f64; 4] = [
    3.781_090_314_581_936_9e-1,
    -9.604_229_221_242_317_8e-2,
    0.5,
    2.179_332_607_542_295e-1,
];
const ALPHA2: f64 = A21;
const ALPHA3: f64 = A31 + A32;
const ALPHA4: f64 = 1.0;

/// The stepper with its stage buffers and the ends of the last accepted step.
pub struct Rosw<const B: usize> {
    n: usize,
    n_ctrl: usize,
    pub tol: Tolerances,
    /// Absolute tolerance per controlled component (`tol.atol` unless set).
    atol: Vec<f64>,
    k: [Vec<f64>; 4],
    /// f and W at the current point (valid after the first evaluation until `reset`).
    f0: Vec<f64>,
    w0: [[f64; B]; B],
    f1: Vec<f64>,
    w1: [[f64; B]; B],
    current: bool,
    ytmp: Vec<f64>,
    rhs: Vec<f64>,
    y1: Vec<f64>,
    /// Hermite data of the last accepted step: y and f at its start (its end is the state).
    y_old: Vec<f64>,
    f_old: Vec<f64>,
    y_end: Vec<f64>,
    f_end: Vec<f64>,
    t_old: f64,
    h_old: f64,
    last_rejected: bool,
    /// Statistics: right-hand-side evaluations and accepted steps.
    pub n_rhs: usize,
    pub n_steps: usize,
}

/// LU factors (partial pivoting) of a B × B matrix, on the stack.
struct Lu<const B: usize> {
    a: [[f64; B]; B],
    piv: [usize; B],
}

impl<const B: usize> Lu<B> {
    /// Factor I − hγ·W; `None` if singular.
    fn of_shifted(w: &[[f64; B]; B], hg: f64) -> Option<Self> {
        let mut a = [[0.0; B]; B];
        for r in 0..B {
            for c in 0..B {
                a[r][c] = f64::from(u8::from(r == c)) - hg * w[r][c];
            }
        }
        let mut piv = [0; B];
        for col in 0..B {
            let mut p = col;
            for r in col + 1..B {
                if a[r][col].abs() > a[p][col].abs() {
                    p = r;
                }
            }
            piv[col] = p;
            if a[p][col] == 0.0 || !a[p][col].is_finite() {
                return None;
            }
            a.swap(p, col);
            let d = a[col][col];
            for r in col + 1..B {
                let f = a[r][col] / d;
                a[r][col] = f;
                for c in col + 1..B {
                    a[r][c] -= f * a[col][c];
                }
            }
        }
        Some(Lu { a, piv })
    }

    /// Solve in place for one block.
    #[inline]
    fn solve(&self, x: &mut [f64; B]) {
        let a = &self.a;
        for col in 0..B {
            x.swap(col, self.piv[col]);
        }
        for r in 1..B {
            let mut s = x[r];
            for c in 0..r {
                s -= a[r][c] * x[c];
            }
            x[r] = s;
        }
        for r in (0..B).rev() {
            let mut s = x[r];
            for c in r + 1..B {
                s -= a[r][c] * x[c];
            }
            x[r] = s / a[r][r];
        }
    }

    /// Solve in place for every block of `v` (its length a multiple of B).
    #[inline]
    fn solve_blocks(&self, v: &mut [f64]) {
        for c in v.chunks_exact_mut(B) {
            if let Ok(x) = <&mut [f64; B]>::try_from(c) {
                self.solve(x);
            }
        }
    }
}

/// out += s·(W ⊗ blocks)·v: W applied to every block of v.
#[inline]
fn add_w_times<const B: usize>(w: &[[f64; B]; B], s: f64, v: &[f64], out: &mut [f64]) {
    for (vb, ob) in v.chunks_exact(B).zip(out.chunks_exact_mut(B)) {
        for r in 0..B {
            let mut acc = 0.0;
            for c in 0..B {
                acc += w[r][c] * vb[c];
            }
            ob[r] += s * acc;
        }
    }
}

/// One step's stage computation: its start (t, y), size h, f and W at the start, the factors
/// of I − hγW, and the stepper's stage buffers.
struct Pass<'a, S, const B: usize> {
    sys: &'a S,
    t: f64,
    h: f64,
    y: &'a [f64],
    f0: &'a [f64],
    w: &'a [[f64; B]; B],
    lu: &'a Lu<B>,
    k: &'a mut [Vec<f64>; 4],
    yt: &'a mut [f64],
    rhs: &'a mut [f64],
}

impl<S: WSystem<B>, const B: usize> Pass<'_, S, B> {
    /// The stages k₁…k₄ of the components `r` (whole blocks), evaluating f's `part`; `false`
    /// if a [`Part::Rest`] evaluation failed. Each component's operations are those of the
    /// whole-vector pass, in the same order: W and the LU act block by block, so a block's
    /// stages depend on the others only through f.
    fn stages(&mut self, part: Part, r: Range<usize>) -> Result<bool, OdeError> {
        let (t, h, y) = (self.t, self.h, self.y);
        let [k1, k2, k3, k4] = &mut *self.k;
        let (yt, rhs) = (&mut *self.yt, &mut *self.rhs);
        // The rest's evaluations see the whole stage vector (the block's part recomputed, the
        // same values); the others see their own components.
        let yr = if part == Part::Rest {
            0..y.len()
        } else {
            r.clone()
        };
        let sys = self.sys;
        let eval = |slot: usize, ts: f64, yt: &[f64], rhs: &mut [f64]| match part {
            Part::Whole => sys.rhs_w(ts, yt, rhs, None).map(|()| true),
            Part::Head => sys.rhs_head(slot, ts, yt, rhs).map(|()| true),
            Part::Rest => sys.rhs_rest(slot, ts, yt, rhs),
        };
        // Stage 1: (I − hγW) k₁ = h f(y₀).
        for i in r.clone() {
            k1[i] = h * self.f0[i];
        }
        self.lu.solve_blocks(&mut k1[r.clone()]);
        // Stage 2.
        for i in yr.clone() {
            yt[i] = y[i] + A21 * k1[i];
        }
        if !eval(0, t + ALPHA2 * h, yt, rhs)? {
            return Ok(false);
        }
        for i in r.clone() {
            rhs[i] *= h;
            k2[i] = G21 * k1[i];
        }
        add_w_times(self.w, h, &k2[r.clone()], &mut rhs[r.clone()]);
        k2[r.clone()].copy_from_slice(&rhs[r.clone()]);
        self.lu.solve_blocks(&mut k2[r.clone()]);
        // Stage 3.
        for i in yr.clone() {
            yt[i] = y[i] + A31 * k1[i] + A32 * k2[i];
        }
        if !eval(1, t + ALPHA3 * h, yt, rhs)? {
            return Ok(false);
        }
        for i in r.clone() {
            rhs[i] *= h;
            k3[i] = G31 * k1[i] + G32 * k2[i];
        }
        add_w_times(self.w, h, &k3[r.clone()], &mut rhs[r.clone()]);
        k3[r.clone()].copy_from_slice(&rhs[r.clone()]);
        self.lu.solve_blocks(&mut k3[r.clone()]);
        // Stage 4 (a₄₁ = a₄₂ = 0, a₄₃ = 1).
        for i in yr {
            yt[i] = y[i] + k3[i];
        }
        if !eval(2, t + ALPHA4 * h, yt, rhs)? {
            return Ok(false);
        }
        for i in r.clone() {
            rhs[i] *= h;
            k4[i] = G41 * k1[i] + G42 * k2[i] + G43 * k3[i];
        }
        add_w_times(self.w, h, &k4[r.clone()], &mut rhs[r.clone()]);
        k4[r.clone()].copy_from_slice(&rhs[r.clone()]);
        self.lu.solve_blocks(&mut k4[r]);
        Ok(true)
    }
}

impl<const B: usize> Rosw<B> {
    /// The stage computation of a step from (t, y) of size h with the factors `lu`, over this
    /// stepper's f, W and stage buffers.
    fn pass<'a, S: WSystem<B>>(
        &'a mut self,
        sys: &'a S,
        t: f64,
        h: f64,
        y: &'a [f64],
        lu: &'a Lu<B>,
    ) -> Pass<'a, S, B> {
        Pass {
            sys,
            t,
            h,
            y,
            f0: &self.f0,
            w: &self.w0,
            lu,
            k: &mut self.k,
            yt: &mut self.ytmp,
            rhs: &mut self.rhs,
        }
    }

    /// y₁ = y₀ + Σ bᵢ kᵢ for the components `r` (into `self.y1`).
    fn advance(&mut self, y: &[f64], r: std::ops::Range<usize>) {
        let [k1, k2, k3, k4] = &self.k;
        for i in r {
            self.y1[i] = y[i]
                + WEIGHTS[0] * k1[i]
                + WEIGHTS[1] * k2[i]
                + WEIGHTS[2] * k3[i]
                + WEIGHTS[3] * k4[i];
        }
    }

    /// A stepper for systems of dimension `n` (a multiple of `B`), controlling the error on
    /// the first `n_ctrl` components.
    ///
    /// # Panics
    /// If `B` is 0 or does not divide `n` (a programming error).
    pub fn new(n: usize, n_ctrl: usize, tol: Tolerances) -> Self {
        assert!(B > 0 && n.is_multiple_of(B), "block {B} of dimension {n}");
        let z = || vec![0.0; n];
        Self {
            n,
            n_ctrl: n_ctrl.min(n),
            tol,
            atol: vec![tol.atol; n_ctrl.min(n)],
            k: [z(), z(), z(), z()],
            f0: z(),
            w0: [[0.0; B]; B],
            f1: z(),
            w1: [[0.0; B]; B],
            current: false,
            ytmp: z(),
            rhs: z(),
            y1: z(),
            y_old: z(),
            f_old: z(),
            y_end: z(),
            f_end: z(),
            t_old: 0.0,
            h_old: 0.0,
            last_rejected: false,
            n_rhs: 0,
            n_steps: 0,
        }
    }

    pub fn dim(&self) -> usize {
        self.n
    }

    /// Bytes its buffers hold (for callers that bound what they keep between runs).
    pub fn capacity_bytes(&self) -> usize {
        let vecs = [
            &self.atol,
            &self.k[0],
            &self.k[1],
            &self.k[2],
            &self.k[3],
            &self.f0,
            &self.f1,
            &self.ytmp,
            &self.rhs,
            &self.y1,
            &self.y_old,
            &self.f_old,
            &self.y_end,
            &self.f_end,
        ];
        std::mem::size_of::<f64>() * vecs.iter().map(|v| v.capacity()).sum::<usize>()
    }

    /// Absolute tolerances of the controlled components, one each (components whose scale
    /// differs from the others'); the rest keep `tol.atol`.
    pub fn set_atol(&mut self, atol: &[f64]) {
        for (a, v) in self.atol.iter_mut().zip(atol) {
            *a = *v;
        }
    }

    /// Forget f and W at the current point: call after the state or the equations change.
    pub fn reset(&mut self) {
        self.current = false;
    }

    /// Make this stepper what [`Rosw::new`] with `tol` would make, keeping its buffers (reuse
    /// across runs of the same dimension: issue 8, no allocation per run once warm). Every
    /// field a step reads before writing is set here, so a restarted stepper takes bit for bit
    /// the steps of a new one (`lift::sensitivity::tests`).
    pub fn restart(&mut self, tol: Tolerances) {
        self.tol = tol;
        self.atol.fill(tol.atol);
        self.current = false;
        self.t_old = 0.0;
        self.h_old = 0.0;
        self.last_rejected = false;
        self.n_rhs = 0;
        self.n_steps = 0;
    }

    fn ensure_current<S: WSystem<B>>(
        &mut self,
        sys: &S,
        t: f64,
        y: &[f64],
    ) -> Result<(), OdeError> {
        if !self.current {
            sys.rhs_w(t, y, &mut self.f0, Some(&mut self.w0))?;
            self.n_rhs += 1;
            self.current = true;
        }
        Ok(())
    }

    /// A starting step size (the same heuristic as [`super::Dopri5::initial_step`]).
    pub fn initial_step<S: WSystem<B>>(
        &mut self,
        sys: &S,
        t: f64,
        y: &[f64],
    ) -> Result<f64, OdeError> {
        self.ensure_current(sys, t, y)?;
        let (mut d0, mut d1) = (0.0f64, 0.0f64);
        for i in 0..self.n_ctrl {
            let sc = self.atol[i] + self.tol.rtol * y[i].abs();
            d0 += (y[i] / sc).powi(2);
            d1 += (self.f0[i] / sc).powi(2);
        }
        let (d0, d1) = (
            (d0 / self.n_ctrl as f64).sqrt(),
            (d1 / self.n_ctrl as f64).sqrt(),
        );
        let h = if d0 < 1e-5 || d1 < 1e-5 {
            1e-6
        } else {
            0.01 * d0 / d1
        };
        Ok(h.min(self.tol.h_max))
    }

    /// Attempt one step of size `h` from (t, y). On acceptance `y` is advanced in place and
    /// the dense output of the step becomes available through [`Rosw::dense_all`].
    pub fn step<S: WSystem<B>>(
        &mut self,
        sys: &S,
        t: f64,
        y: &mut [f64],
        h: f64,
    ) -> Result<Step, OdeError> {
        if h.abs() < self.tol.h_min {
            return Err(OdeError::StepUnderflow { t, h });
        }
        self.ensure_current(sys, t, y)?;
        let n = self.n;
        let w = &self.w0;
        let Some(lu) = Lu::of_shifted(w, h * GAMMA) else {
            self.last_rejected = true;
            return Ok(Step::Rejected { h_next: h * 0.5 });
        };
        // Split (the block's stages first) when the system can and the error needs the block
        // alone.
        let split = sys.splits() && self.n_ctrl <= B && B < n;
        let head = if split { B } else { n };
        let part = if split { Part::Head } else { Part::Whole };
        self.pass(sys, t, h, y, &lu).stages(part, 0..head)?;
        self.n_rhs += 3;
        self.advance(y, 0..head);
        let [k1, k2, k3, k4] = &self.k;
        let y1 = &self.y1;
        let mut err = 0.0;
        for i in 0..self.n_ctrl {
            let e = (WEIGHTS[0] - WEIGHTS_HAT[0]) * k1[i]
                + (WEIGHTS[1] - WEIGHTS_HAT[1]) * k2[i]
                + (WEIGHTS[2] - WEIGHTS_HAT[2]) * k3[i]
                + (WEIGHTS[3] - WEIGHTS_HAT[3]) * k4[i];
            let sc = self.atol[i] + self.tol.rtol * y[i].abs().max(y1[i].abs());
            err += (e / sc).powi(2);
        }
        let err = (err / self.n_ctrl as f64).sqrt();
        if !err.is_finite() {
            self.last_rejected = true;
            return Ok(Step::Rejected { h_next: h * 0.1 });
        }
        // Order of the embedded estimate 2: exponent 1/3.
        let fac = if err == 0.0 {
            5.0
        } else {
            (0.9 * err.powf(-1.0 / 3.0)).clamp(0.2, 5.0)
        };
        if err > 1.0 {
            self.last_rejected = true;
            return Ok(Step::Rejected {
                h_next: h * fac.min(1.0),
            });
        }
        if split {
            // The other components' stages, now that the step stands on the block's error.
            if !self.pass(sys, t, h, y, &lu).stages(Part::Rest, head..n)? {
                // The full evaluation would have made every stage value, so the error, NaN.
                self.last_rejected = true;
                return Ok(Step::Rejected { h_next: h * 0.1 });
            }
            self.advance(y, head..n);
        }
        // f and W at the new point: the dense output's right end and the next first stage.
        sys.rhs_w(t + h, &self.y1, &mut self.f1, Some(&mut self.w1))?;
        self.n_rhs += 1;
        if self.f1.iter().any(|v| !v.is_finite()) {
            self.last_rejected = true;
            return Ok(Step::Rejected { h_next: h * 0.5 });
        }
        // After a rejection, do not grow at once (Hairer's safeguard).
        let fac = if self.last_rejected {
            fac.min(1.0)
        } else {
            fac
        };
        self.last_rejected = false;
        let h_next = (h * fac).min(self.tol.h_max);
        self.y_old.copy_from_slice(y);
        self.f_old.copy_from_slice(&self.f0);
        y.copy_from_slice(&self.y1);
        self.y_end.copy_from_slice(&self.y1);
        std::mem::swap(&mut self.f0, &mut self.f1);
        std::mem::swap(&mut self.w0, &mut self.w1);
        self.f_end.copy_from_slice(&self.f0);
        self.current = true;
        self.t_old = t;
        self.h_old = h;
        self.n_steps += 1;
        Ok(Step::Accepted { h, h_next })
    }

    /// The whole dense state at time `t` (inside the last accepted step) into `out`.
    pub fn dense_all(&self, t: f64, out: &mut [f64]) {
        let h = self.h_old;
        let th = (t - self.t_old) / h;
        let (a, bb) = (1.0 - th, th * (th - 1.0));
        for i in 0..self.n {
            let (y0, y1) = (self.y_old[i], self.y_end[i]);
            out[i] = a * y0
                + th * y1
                + bb * ((1.0 - 2.0 * th) * (y1 - y0)
                    + (th - 1.0) * h * self.f_old[i]
                    + th * h * self.f_end[i]);
        }
    }
}

#[cfg(test)]
mod tests;

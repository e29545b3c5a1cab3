//! Dormand–Prince 5(4) with its 4th-order dense output (Hairer, Nørsett & Wanner, ODE I, II.5–II.6).
//!
//! Allocation-free after construction: the caller owns one [`Dopri5`] and reuses it across steps
//! and simulations. Error control may be restricted to the first `n_ctrl` components (the state),
//! leaving forward sensitivities appended after it to ride on the same steps.

pub mod rosw;

pub use rosw::{Rosw, WSystem};

/// Something the integrator cannot continue past.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OdeError {
    #[error(
        "step size underflow at t = {t} s (h = {h:e} s): the equations are stiff or singular there"
    )]
    StepUnderflow { t: f64, h: f64 },
    #[error("right-hand side not finite at t = {t} s")]
    NotFinite { t: f64 },
    #[error("model cannot be evaluated: {0}")]
    Model(String),
}

/// A first-order system y' = f(t, y).
pub trait OdeSystem {
    fn dim(&self) -> usize;
    /// Write f(t, y) into `dy`.
    fn rhs(&self, t: f64, y: &[f64], dy: &mut [f64]) -> Result<(), OdeError>;
}

// Butcher tableau of DOPRI5.
const C2: f64 = 1.0 / 5.0;
const C3: f64 = 3.0 / 10.0;
const C4: f64 = 4.0 / 5.0;
const C5: f64 = 8.0 / 9.0;
const A21: f64 = 1.0 / 5.0;
const A31: f64 = 3.0 / 40.0;
const A32: f64 = 9.0 / 40.0;
const A41: f64 = 44.0 / 45.0;
const A42: f64 = -56.0 / 15.0;
const A43: f64 = 32.0 / 9.0;
const A51: f64 = 19372.0 / 6561.0;
const A52: f64 = -25360.0 / 2187.0;
const A53: f64 = 64448.0 / 6561.0;
const A54: f64 = -212.0 / 729.0;
const A61: f64 = 9017.0 / 3168.0;
const A62: f64 = -355.0 / 33.0;
const A63: f64 = 46732.0 / 5247.0;
const A64: f64 = 49.0 / 176.0;
const A65: f64 = -5103.0 / 18656.0;
const A71: f64 = 35.0 / 384.0;
const A73: f64 = 500.0 / 1113.0;
const A74: f64 = 125.0 / 192.0;
const A75: f64 = -2187.0 / 6784.0;
const A76: f64 = 11.0 / 84.0;
const E1: f64 = 71.0 / 57600.0;
const E3: f64 = -71.0 / 16695.0;
const E4: f64 = 71.0 / 1920.0;
const E5: f64 = -17253.0 / 339200.0;
const E6: f64 = 22.0 / 525.0;
const E7: f64 = -1.0 / 40.0;
// Dense output (Shampine's 4th-order continuous extension, as in Hairer's dopri5.f).
const D1: f64 = -12715105075.0 / 11282082432.0;
const D3: f64 = 87487479700.0 / 32700410799.0;
const D4: f64 = -10690763975.0 / 1880347072.0;
const D5: f64 = 701980252875.0 / 199316789632.0;
const D6: f64 = -1453857185.0 / 822651844.0;
const D7: f64 = 69997945.0 / 29380423.0;

/// Tolerances and limits of the integrator.
#[derive(Debug, Clone, Copy)]
pub struct Tolerances {
    pub rtol: f64,
    pub atol: f64,
    pub h_max: f64,
    pub h_min: f64,
}

impl Default for Tolerances {
    fn default() -> Self {
        Self {
            rtol: 1e-9,
            atol: 1e-11,
            h_max: f64::INFINITY,
            h_min: 1e-14,
        }
    }
}

/// Outcome of one attempted step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Step {
    /// Accepted: the state advanced by `h`; the next step should try `h_next`.
    Accepted { h: f64, h_next: f64 },
    /// Rejected: retry with `h_next`.
    Rejected { h_next: f64 },
}

/// The stepper with its stage buffers and the dense-output coefficients of the last accepted step.
pub struct Dopri5 {
    n: usize,
    n_ctrl: usize,
    pub tol: Tolerances,
    k: [Vec<f64>; 7],
    ytmp: Vec<f64>,
    y_new: Vec<f64>,
    /// Dense coefficients r1..r5 of the last accepted step, each of length n.
    r: [Vec<f64>; 5],
    t_old: f64,
    h_old: f64,
    fsal_valid: bool,
    /// Statistics: right-hand-side evaluations and accepted steps.
    pub n_rhs: usize,
    pub n_steps: usize,
}

impl Dopri5 {
    /// A stepper for systems of dimension `n`, controlling the error on the first `n_ctrl`.
    pub fn new(n: usize, n_ctrl: usize, tol: Tolerances) -> Self {
        let z = || vec![0.0; n];
        Self {
            n,
            n_ctrl: n_ctrl.min(n),
            tol,
            k: [z(), z(), z(), z(), z(), z(), z()],
            ytmp: z(),
            y_new: z(),
            r: [z(), z(), z(), z(), z()],
            t_old: 0.0,
            h_old: 0.0,
            fsal_valid: false,
            n_rhs: 0,
            n_steps: 0,
        }
    }

    pub fn dim(&self) -> usize {
        self.n
    }

    /// Forget the stored derivative: call after the state or the equations change (an event).
    pub fn reset(&mut self) {
        self.fsal_valid = false;
    }

    /// A starting step size (Hairer's heuristic, simplified).
    pub fn initial_step<S: OdeSystem>(
        &mut self,
        sys: &S,
        t: f64,
        y: &[f64],
    ) -> Result<f64, OdeError> {
        sys.rhs(t, y, &mut self.k[0])?;
        self.n_rhs += 1;
        self.fsal_valid = true;
        let (mut d0, mut d1) = (0.0f64, 0.0f64);
        for i in 0..self.n_ctrl {
            let sc = self.tol.atol + self.tol.rtol * y[i].abs();
            d0 += (y[i] / sc).powi(2);
            d1 += (self.k[0][i] / sc).powi(2);
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

    /// Attempt one step of size `h` from (t, y). On acceptance `y` is advanced in place and the
    /// dense output of the step becomes available through [`Dopri5::dense`].
    pub fn step<S: OdeSystem>(
        &mut self,
        sys: &S,
        t: f64,
        y: &mut [f64],
        h: f64,
    ) -> Result<Step, OdeError> {
        let n = self.n;
        if h.abs() < self.tol.h_min {
            return Err(OdeError::StepUnderflow { t, h });
        }
        if !self.fsal_valid {
            sys.rhs(t, y, &mut self.k[0])?;
            self.n_rhs += 1;
            self.fsal_valid = true;
        }
        // Every buffer as a slice of length n: the loops below run without bounds checks
        // (issue 38: a single joint's step is a few dozen flops, the checks were a tenth of it).
        let [k1, k2, k3, k4, k5, k6, k7] = &mut self.k;
        let (k1, k2, k3, k4, k5, k6, k7) = (
            &mut k1[..n],
            &mut k2[..n],
            &mut k3[..n],
            &mut k4[..n],
            &mut k5[..n],
            &mut k6[..n],
            &mut k7[..n],
        );
        let y = &mut y[..n];
        let yt = &mut self.ytmp[..n];
        for i in 0..n {
            yt[i] = y[i] + h * A21 * k1[i];
        }
        sys.rhs(t + C2 * h, yt, k2)?;
        for i in 0..n {
            yt[i] = y[i] + h * (A31 * k1[i] + A32 * k2[i]);
        }
        sys.rhs(t + C3 * h, yt, k3)?;
        for i in 0..n {
            yt[i] = y[i] + h * (A41 * k1[i] + A42 * k2[i] + A43 * k3[i]);
        }
        sys.rhs(t + C4 * h, yt, k4)?;
        for i in 0..n {
            yt[i] = y[i] + h * (A51 * k1[i] + A52 * k2[i] + A53 * k3[i] + A54 * k4[i]);
        }
        sys.rhs(t + C5 * h, yt, k5)?;
        for i in 0..n {
            yt[i] =
                y[i] + h * (A61 * k1[i] + A62 * k2[i] + A63 * k3[i] + A64 * k4[i] + A65 * k5[i]);
        }
        sys.rhs(t + h, yt, k6)?;
        let yn = &mut self.y_new[..n];
        for i in 0..n {
            yn[i] =
                y[i] + h * (A71 * k1[i] + A73 * k3[i] + A74 * k4[i] + A75 * k5[i] + A76 * k6[i]);
        }
        sys.rhs(t + h, yn, k7)?;
        self.n_rhs += 6;

        let mut err = 0.0;
        let n_ctrl = self.n_ctrl.min(n);
        for i in 0..n_ctrl {
            let e =
                h * (E1 * k1[i] + E3 * k3[i] + E4 * k4[i] + E5 * k5[i] + E6 * k6[i] + E7 * k7[i]);
            let sc = self.tol.atol + self.tol.rtol * y[i].abs().max(yn[i].abs());
            err += (e / sc).powi(2);
        }
        let err = (err / self.n_ctrl as f64).sqrt();
        if !err.is_finite() {
            // Treat as a failed step: shrink hard. A persistently non-finite model ends in underflow.
            return Ok(Step::Rejected { h_next: h * 0.1 });
        }
        let fac = if err == 0.0 {
            5.0
        } else {
            (0.9 * err.powf(-0.2)).clamp(0.2, 5.0)
        };
        let h_next = (h * fac).min(self.tol.h_max);
        if err > 1.0 {
            return Ok(Step::Rejected {
                h_next: h * fac.min(1.0),
            });
        }
        // Accept: dense coefficients, then advance.
        let [r1, r2, r3, r4, r5] = &mut self.r;
        let (r1, r2, r3, r4, r5) = (
            &mut r1[..n],
            &mut r2[..n],
            &mut r3[..n],
            &mut r4[..n],
            &mut r5[..n],
        );
        for i in 0..n {
            let ydiff = yn[i] - y[i];
            let bspl = h * k1[i] - ydiff;
            r1[i] = y[i];
            r2[i] = ydiff;
            r3[i] = bspl;
            r4[i] = ydiff - h * k7[i] - bspl;
            r5[i] =
                h * (D1 * k1[i] + D3 * k3[i] + D4 * k4[i] + D5 * k5[i] + D6 * k6[i] + D7 * k7[i]);
            y[i] = yn[i];
        }
        // FSAL: the last stage is the first of the next step.
        self.k.swap(0, 6);
        self.t_old = t;
        self.h_old = h;
        self.n_steps += 1;
        Ok(Step::Accepted { h, h_next })
    }

    /// Component `i` of the dense output of the last accepted step at time `t` (inside the step).
    #[inline]
    pub fn dense(&self, i: usize, t: f64) -> f64 {
        let th = (t - self.t_old) / self.h_old;
        let th1 = 1.0 - th;
        let r = &self.r;
        r[0][i] + th * (r[1][i] + th1 * (r[2][i] + th * (r[3][i] + th1 * r[4][i])))
    }

    /// The whole dense state at time `t` into `out`.
    pub fn dense_all(&self, t: f64, out: &mut [f64]) {
        self.dense_range(t, 0..self.n, out);
    }

    /// The dense state at each of `times` (inside the last accepted step), split the way a
    /// simulation keeps it: components 0 and 1 (position and rate) into `q[i]` and `v[i]`,
    /// components 2 .. 2 + m into row i of `rows` (row-major, m = `rows.len() / times.len()`
    /// values a sample). The same products as [`Dopri5::dense_range`], to the bit (test
    /// `dense_rows_are_dense_range_to_the_bit`). Issue 38, session 23: a single joint's fit
    /// evaluates the dense output at every sample of every evaluation (~17 samples a step on a
    /// 500 Hz pendulum); one call a sample through a buffer and a copy was a fifth of the fit.
    pub fn dense_rows(&self, times: &[f64], q: &mut [f64], v: &mut [f64], rows: &mut [f64]) {
        let n = times.len();
        if n == 0 {
            return;
        }
        let m = rows.len() / n;
        assert!(q.len() == n && v.len() == n && rows.len() == n * m && 2 + m <= self.n);
        // The usual row lengths with the coefficients held in registers across the samples
        // (a loop of a run-time length over them was half the work of a sample).
        match m {
            1 => self.dense_rows_of::<1>(times, q, v, rows),
            2 => self.dense_rows_of::<2>(times, q, v, rows),
            3 => self.dense_rows_of::<3>(times, q, v, rows),
            4 => self.dense_rows_of::<4>(times, q, v, rows),
            5 => self.dense_rows_of::<5>(times, q, v, rows),
            6 => self.dense_rows_of::<6>(times, q, v, rows),
            _ => self.dense_rows_any(times, q, v, rows, m),
        }
    }

    /// [`Dopri5::dense_rows`] for rows of `M` values.
    fn dense_rows_of<const M: usize>(
        &self,
        times: &[f64],
        q: &mut [f64],
        v: &mut [f64],
        rows: &mut [f64],
    ) {
        let coeffs = |i: usize| -> [f64; M] { std::array::from_fn(|j| self.r[i][2 + j]) };
        let (c0, c1, c2, c3, c4) = (coeffs(0), coeffs(1), coeffs(2), coeffs(3), coeffs(4));
        let (hq, hv) = self.head();
        let states = times.iter().zip(q.iter_mut().zip(v.iter_mut()));
        for ((&t, (qk, vk)), row) in states.zip(rows.chunks_exact_mut(M)) {
            let th = (t - self.t_old) / self.h_old;
            let th1 = 1.0 - th;
            (*qk, *vk) = (dense_at(th, th1, hq), dense_at(th, th1, hv));
            for i in 0..M {
                row[i] = dense_at(th, th1, [c0[i], c1[i], c2[i], c3[i], c4[i]]);
            }
        }
    }

    /// [`Dopri5::dense_rows`] for rows of any length `m` (0 included).
    fn dense_rows_any(
        &self,
        times: &[f64],
        q: &mut [f64],
        v: &mut [f64],
        rows: &mut [f64],
        m: usize,
    ) {
        let (hq, hv) = self.head();
        let [r0, r1, r2, r3, r4] = &self.r;
        let (r0, r1, r2, r3, r4) = (
            &r0[2..2 + m],
            &r1[2..2 + m],
            &r2[2..2 + m],
            &r3[2..2 + m],
            &r4[2..2 + m],
        );
        for (k, (&t, (qk, vk))) in times.iter().zip(q.iter_mut().zip(v.iter_mut())).enumerate() {
            let th = (t - self.t_old) / self.h_old;
            let th1 = 1.0 - th;
            (*qk, *vk) = (dense_at(th, th1, hq), dense_at(th, th1, hv));
            let row = &mut rows[k * m..(k + 1) * m];
            for i in 0..m {
                row[i] = dense_at(th, th1, [r0[i], r1[i], r2[i], r3[i], r4[i]]);
            }
        }
    }

    /// The dense coefficients of components 0 and 1.
    #[inline(always)]
    fn head(&self) -> ([f64; 5], [f64; 5]) {
        let c = |i: usize| std::array::from_fn(|j| self.r[j][i]);
        (c(0), c(1))
    }

    /// Components `range` of the dense state at `t` into `out[range]`.
    #[inline]
    pub fn dense_range(&self, t: f64, range: std::ops::Range<usize>, out: &mut [f64]) {
        let th = (t - self.t_old) / self.h_old;
        let th1 = 1.0 - th;
        // One slice per coefficient: the loop runs without bounds checks (issue 38: a single
        // joint's fit evaluates it at every sample for q, v and each sensitivity).
        let [r0, r1, r2, r3, r4] = &self.r;
        let (r0, r1, r2, r3, r4) = (
            &r0[range.clone()],
            &r1[range.clone()],
            &r2[range.clone()],
            &r3[range.clone()],
            &r4[range.clone()],
        );
        let out = &mut out[range];
        for i in 0..out.len() {
            out[i] = r0[i] + th * (r1[i] + th1 * (r2[i] + th * (r3[i] + th1 * r4[i])));
        }
    }
}

/// One component of the dense output at θ (θ1 = 1 − θ) from its coefficients r1..r5: the
/// products of [`Dopri5::dense_range`], in its order.
#[inline(always)]
fn dense_at(th: f64, th1: f64, r: [f64; 5]) -> f64 {
    r[0] + th * (r[1] + th1 * (r[2] + th * (r[3] + th1 * r[4])))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A damped oscillator with `m` riders (each its own decay): a state of 2 + m components.
    struct Riders(usize);
    impl OdeSystem for Riders {
        fn dim(&self) -> usize {
            2 + self.0
        }
        fn rhs(&self, t: f64, y: &[f64], dy: &mut [f64]) -> Result<(), OdeError> {
            dy[0] = y[1];
            dy[1] = -y[0] - 0.3 * y[1] + (3.0 * t).sin();
            for i in 2..y.len() {
                dy[i] = -(i as f64) * y[i] + y[0];
            }
            Ok(())
        }
    }

    /// Issue 38, session 23: the dense output at a run of samples, split into position, rate
    /// and rows, is `dense_range`'s at each sample to the bit, for 0 to 8 riders, random states
    /// and steps, and random sample times inside each step (its ends included).
    #[test]
    fn dense_rows_are_dense_range_to_the_bit() {
        let mut rng = crate::numerics::noise::Noise::new(2338);
        for m in 0..=8 {
            let sys = Riders(m);
            let tol = Tolerances {
                rtol: 1e-6,
                atol: 1e-9,
                ..Default::default()
            };
            let mut st = Dopri5::new(2 + m, 2, tol);
            let mut y: Vec<f64> = (0..2 + m).map(|_| rng.normal()).collect();
            let (mut t, mut h, mut checked) = (rng.uniform(), 0.05, 0);
            while checked < 40 {
                match st.step(&sys, t, &mut y, h).unwrap() {
                    Step::Rejected { h_next } => h = h_next,
                    Step::Accepted { h: hh, h_next } => {
                        let k = 1 + (rng.uniform() * 20.0) as usize;
                        let mut times: Vec<f64> = (0..k).map(|_| t + hh * rng.uniform()).collect();
                        times.push(t);
                        times.push(t + hh);
                        times.sort_by(f64::total_cmp);
                        let n = times.len();
                        let (mut q, mut v) = (vec![f64::NAN; n], vec![f64::NAN; n]);
                        let mut rows = vec![f64::NAN; n * m];
                        st.dense_rows(&times, &mut q, &mut v, &mut rows);
                        let mut full = vec![0.0; 2 + m];
                        for (i, &ti) in times.iter().enumerate() {
                            st.dense_range(ti, 0..2 + m, &mut full);
                            assert_eq!(q[i].to_bits(), full[0].to_bits(), "m {m} q at {ti}");
                            assert_eq!(v[i].to_bits(), full[1].to_bits(), "m {m} v at {ti}");
                            for j in 0..m {
                                let (a, b) = (rows[i * m + j], full[2 + j]);
                                assert_eq!(a.to_bits(), b.to_bits(), "m {m} row {j} at {ti}");
                            }
                        }
                        t += hh;
                        h = h_next;
                        checked += 1;
                    }
                }
            }
        }
    }

    /// y'' = -y: y = cos t.
    struct Osc;
    impl OdeSystem for Osc {
        fn dim(&self) -> usize {
            2
        }
        fn rhs(&self, _t: f64, y: &[f64], dy: &mut [f64]) -> Result<(), OdeError> {
            dy[0] = y[1];
            dy[1] = -y[0];
            Ok(())
        }
    }

    #[test]
    fn harmonic_oscillator_to_tolerance_with_dense_output() {
        let mut s = Dopri5::new(
            2,
            2,
            Tolerances {
                rtol: 1e-10,
                atol: 1e-12,
                ..Default::default()
            },
        );
        let mut y = [1.0, 0.0];
        let mut t = 0.0;
        let mut h = s.initial_step(&Osc, t, &y).unwrap();
        let mut max_dense_err: f64 = 0.0;
        while t < 20.0 {
            h = h.min(20.0 - t);
            match s.step(&Osc, t, &mut y, h).unwrap() {
                Step::Accepted { h: hh, h_next } => {
                    let tm = t + 0.37 * hh;
                    max_dense_err = max_dense_err.max((s.dense(0, tm) - tm.cos()).abs());
                    t += hh;
                    h = h_next;
                }
                Step::Rejected { h_next } => h = h_next,
            }
        }
        assert!(
            (y[0] - 20f64.cos()).abs() < 1e-8,
            "end error {}",
            (y[0] - 20f64.cos()).abs()
        );
        assert!(max_dense_err < 1e-8, "dense error {max_dense_err}");
    }
}

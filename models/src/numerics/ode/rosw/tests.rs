//! Tests of the Rosenbrock-W stepper: order, L-stability, the adaptive run, and the split
//! step (state first, the other components only for a step that stands) bit for bit.

use super::*;

/// Every buffer counted: 13 state-sized vectors and the controlled components' atol; a
/// restart keeps them (no new allocation, the same bytes).
#[test]
fn capacity_counts_every_buffer_and_restart_keeps_them() {
    let tol = Tolerances::default();
    let mut st = Rosw::<4>::new(12, 4, tol);
    assert_eq!(st.capacity_bytes(), 8 * (13 * 12 + 4));
    st.restart(tol);
    assert_eq!(st.capacity_bytes(), 8 * (13 * 12 + 4));
}

/// Prothero–Robinson-like stiff test with a forced smooth solution, plus an oscillator:
/// y₀′ = λ(y₀ − sin t) + cos t (solution sin t), y₁′ = y₂, y₂′ = −y₁ (cos t).
struct Test {
    lambda: f64,
    /// W = scale · ∂f/∂y (a W-method keeps its order for any W).
    w_scale: f64,
}
impl WSystem<3> for Test {
    fn dim(&self) -> usize {
        3
    }
    fn rhs_w(
        &self,
        t: f64,
        y: &[f64],
        dy: &mut [f64],
        w: Option<&mut [[f64; 3]; 3]>,
    ) -> Result<(), OdeError> {
        dy[0] = self.lambda * (y[0] - t.sin()) + t.cos();
        dy[1] = y[2];
        dy[2] = -y[1];
        if let Some(w) = w {
            let k = self.w_scale;
            *w = [[k * self.lambda, 0.0, 0.0], [0.0, 0.0, k], [0.0, -k, 0.0]];
        }
        Ok(())
    }
}

/// Fixed-step global error at t = 1 with `steps` steps.
fn global_error(sys: &Test, steps: usize) -> f64 {
    let tol = Tolerances {
        rtol: 1e30,
        atol: 1e30,
        ..Default::default()
    };
    let mut st = Rosw::<3>::new(3, 3, tol);
    let mut y = [0.0, 1.0, 0.0];
    let h = 1.0 / steps as f64;
    for k in 0..steps {
        match st.step(sys, k as f64 * h, &mut y, h).unwrap() {
            Step::Accepted { .. } => {}
            Step::Rejected { .. } => panic!("rejected with infinite tolerance"),
        }
    }
    let exact = [1f64.sin(), 1f64.cos(), -1f64.sin()];
    y.iter()
        .zip(exact)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max)
}

fn observed_order(sys: &Test) -> f64 {
    let (e1, e2) = (global_error(sys, 40), global_error(sys, 80));
    (e1 / e2).log2()
}

#[test]
fn order_three_with_the_exact_jacobian_and_with_any_w() {
    // Non-stiff, so the classical order shows: with the exact Jacobian, a scaled one,
    // and W = 0 (the method is then explicit), the coefficients must give order 3.
    for w_scale in [1.0, 0.5, 0.0] {
        let p = observed_order(&Test {
            lambda: -1.0,
            w_scale,
        });
        assert!((2.8..3.4).contains(&p), "W scale {w_scale}: order {p}");
    }
}

#[test]
fn l_stable_on_a_very_stiff_component() {
    // λ = −10⁶ with h = 0.1: an explicit method would explode; this one follows sin t.
    let sys = Test {
        lambda: -1e6,
        w_scale: 1.0,
    };
    let e = global_error(&sys, 10);
    assert!(e < 1e-3, "error {e}");
}

/// [`Test`]'s three components as the block, then `cols` sensitivity-like columns of
/// three, s′ = W·s + g_c(t, y) (W the block's Jacobian, g_c nonlinear in the block): the
/// columns' equations read the block, the block's do not read them, as in a sensitivity
/// run. `split` turns the split on; `heads` and `rests` count the two parts' calls. Where
/// a stage time falls in `fail_t` the columns' part fails: the whole f is NaN.
struct Sens {
    base: Test,
    cols: usize,
    split: bool,
    fail_t: (f64, f64),
    heads: std::cell::Cell<usize>,
    rests: std::cell::Cell<usize>,
}
impl Sens {
    fn new(cols: usize, split: bool, fail_t: (f64, f64)) -> Self {
        Sens {
            base: Test {
                lambda: -1e4,
                w_scale: 1.0,
            },
            cols,
            split,
            fail_t,
            heads: std::cell::Cell::new(0),
            rests: std::cell::Cell::new(0),
        }
    }
    /// The columns' part; `false` where it fails.
    fn columns(&self, t: f64, y: &[f64], dy: &mut [f64]) -> bool {
        if (self.fail_t.0..=self.fail_t.1).contains(&t) {
            return false;
        }
        let mut w = [[0.0; 3]; 3];
        let mut block = [0.0; 3];
        let _ = self.base.rhs_w(t, &y[..3], &mut block, Some(&mut w));
        for c in 0..self.cols {
            let o = 3 + 3 * c;
            let sc = (c + 1) as f64;
            let g = [sc * y[0] * y[0], (sc * y[1]).sin(), y[2] * (t + sc).ln()];
            for r in 0..3 {
                let mut v = g[r];
                for k in 0..3 {
                    v += w[r][k] * y[o + k];
                }
                dy[o + r] = v;
            }
        }
        true
    }
}
impl WSystem<3> for Sens {
    fn dim(&self) -> usize {
        3 + 3 * self.cols
    }
    fn rhs_w(
        &self,
        t: f64,
        y: &[f64],
        dy: &mut [f64],
        w: Option<&mut [[f64; 3]; 3]>,
    ) -> Result<(), OdeError> {
        self.base.rhs_w(t, &y[..3], &mut dy[..3], w)?;
        if !self.columns(t, y, dy) {
            dy.fill(f64::NAN);
        }
        Ok(())
    }
    fn splits(&self) -> bool {
        self.split
    }
    fn rhs_head(&self, _: usize, t: f64, y: &[f64], dy: &mut [f64]) -> Result<(), OdeError> {
        self.heads.set(self.heads.get() + 1);
        self.base.rhs_w(t, &y[..3], &mut dy[..3], None)
    }
    fn rhs_rest(&self, _: usize, t: f64, y: &[f64], dy: &mut [f64]) -> Result<bool, OdeError> {
        self.rests.set(self.rests.get() + 1);
        Ok(self.columns(t, y, dy))
    }
}

/// Every step's outcome and the state's bits after it.
fn adaptive_trace(sys: &Sens, tol: Tolerances) -> (Vec<(u64, Vec<u64>)>, usize, usize) {
    let n = sys.dim();
    let mut st = Rosw::<3>::new(n, 3, tol);
    let mut y = vec![0.0; n];
    y[1] = 1.0;
    for (i, v) in y.iter_mut().enumerate().skip(3) {
        *v = 0.1 * i as f64;
    }
    let (mut t, mut h) = (0.0f64, 0.5f64);
    let mut trace = Vec::new();
    while t < 3.0 && trace.len() < 10_000 {
        let h_try = h.min(3.0 - t);
        let outcome = match st.step(sys, t, &mut y, h_try).unwrap() {
            Step::Accepted { h: hh, h_next } => {
                t += hh;
                h = h_next;
                h_next
            }
            Step::Rejected { h_next } => {
                h = h_next;
                -h_next
            }
        };
        trace.push((outcome.to_bits(), y.iter().map(|v| v.to_bits()).collect()));
    }
    (trace, st.n_rhs, st.n_steps)
}

#[test]
fn split_steps_are_bit_identical_and_skip_the_columns_of_rejected_steps() {
    let tol = Tolerances {
        rtol: 1e-6,
        atol: 1e-8,
        h_max: 0.5,
        ..Default::default()
    };
    let (whole, split) = (
        Sens::new(8, false, (-1.0, -1.0)),
        Sens::new(8, true, (-1.0, -1.0)),
    );
    let (a, rhs_a, steps_a) = adaptive_trace(&whole, tol);
    let (b, rhs_b, steps_b) = adaptive_trace(&split, tol);
    assert_eq!(a, b, "the split changed a step or a bit of the state");
    assert_eq!((rhs_a, steps_a), (rhs_b, steps_b));
    assert_eq!(whole.heads.get() + whole.rests.get(), 0);
    // Stages 2–4: the block's part on every attempt, the columns' only on accepted ones.
    let rejected = a.len() - steps_a;
    assert!(
        rejected > 0,
        "no rejected step: the test does not test the split"
    );
    assert_eq!(split.heads.get(), 3 * a.len());
    assert_eq!(split.rests.get(), 3 * steps_b);
}

#[test]
fn a_failing_columns_part_rejects_the_step_as_the_whole_evaluation_does() {
    // One step the error accepts (tolerances infinite) whose stage 3 or 4 fails in the
    // columns' part: the whole evaluation makes every stage value NaN (rejected, ×0.1).
    let tol = Tolerances {
        rtol: 1e30,
        atol: 1e30,
        ..Default::default()
    };
    // Stage times 0.0872 (stage 2), 0.0732 (stage 3), 0.1 (stage 4); (5, 6) misses them.
    for fail_t in [(0.08, 0.09), (0.07, 0.075), (0.1, 0.1), (5.0, 6.0)] {
        let mut outcomes = Vec::new();
        for split in [false, true] {
            let sys = Sens::new(2, split, fail_t);
            let mut st = Rosw::<3>::new(9, 3, tol);
            let mut y = vec![0.0, 1.0, 0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6];
            let step = st.step(&sys, 0.0, &mut y, 0.1).unwrap();
            let bits: Vec<u64> = y.iter().map(|v| v.to_bits()).collect();
            outcomes.push((step, bits, st.n_rhs, st.n_steps));
        }
        assert_eq!(outcomes[0], outcomes[1], "failure window {fail_t:?}");
        let rejected = matches!(outcomes[0].0, Step::Rejected { .. });
        assert_eq!(rejected, fail_t.0 < 1.0, "failure window {fail_t:?}");
    }
}

#[test]
fn adaptive_run_meets_the_tolerance_and_dense_output_is_accurate() {
    let sys = Test {
        lambda: -1e4,
        w_scale: 1.0,
    };
    let tol = Tolerances {
        rtol: 1e-6,
        atol: 1e-8,
        h_max: 0.5,
        ..Default::default()
    };
    let mut st = Rosw::<3>::new(3, 3, tol);
    let mut y = [0.0, 1.0, 0.0];
    let mut t = 0.0;
    let mut h = st.initial_step(&sys, t, &y).unwrap();
    let mut worst_dense: f64 = 0.0;
    let mut out = [0.0; 3];
    while t < 5.0 {
        let h_try = h.min(5.0 - t);
        match st.step(&sys, t, &mut y, h_try).unwrap() {
            Step::Accepted { h: hh, h_next } => {
                let tm = t + 0.37 * hh;
                st.dense_all(tm, &mut out);
                worst_dense = worst_dense
                    .max((out[0] - tm.sin()).abs())
                    .max((out[1] - tm.cos()).abs());
                t += hh;
                h = h_next;
            }
            Step::Rejected { h_next } => h = h_next,
        }
    }
    let e = (y[0] - 5f64.sin()).abs().max((y[1] - 5f64.cos()).abs());
    assert!(e < 1e-4, "end error {e}");
    assert!(worst_dense < 1e-4, "dense error {worst_dense}");
    // Stiffness does not set the step: far fewer steps than λ·T would need explicitly.
    assert!(st.n_steps < 2_000, "{} steps", st.n_steps);
}

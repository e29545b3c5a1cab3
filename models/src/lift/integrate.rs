//! Integration over a sampled record: a stepper (DOPRI5 or the Rosenbrock-W method) steps
//! freely between breakpoints (samples where an input jumps), landing only on them, and the
//! samples are read off its dense output.
//!
//! Allocation-free per step: the caller owns the stepper, the state and one sample buffer.

use crate::numerics::ode::{Dopri5, OdeError, OdeSystem, Rosw, Step, WSystem};

/// A system whose inputs change definition at breakpoints (a held input steps there).
pub(super) trait Segmented {
    /// The integration is about to run from sample `k`, a breakpoint, to the next one.
    fn enter_segment(&mut self, k: usize);
}

/// What [`integrate`] needs of a one-step method with dense output, for systems `S`.
pub(super) trait Stepper<S> {
    /// Forget what was evaluated at the current point (the equations changed).
    fn reset(&mut self);
    fn initial_step(&mut self, sys: &S, t: f64, y: &[f64]) -> Result<f64, OdeError>;
    fn step(&mut self, sys: &S, t: f64, y: &mut [f64], h: f64) -> Result<Step, OdeError>;
    /// The dense state at `t` inside the last accepted step.
    fn dense_all(&self, t: f64, out: &mut [f64]);
    fn n_rhs(&self) -> usize;
}

impl<S: OdeSystem> Stepper<S> for Dopri5 {
    fn reset(&mut self) {
        Dopri5::reset(self);
    }
    fn initial_step(&mut self, sys: &S, t: f64, y: &[f64]) -> Result<f64, OdeError> {
        Dopri5::initial_step(self, sys, t, y)
    }
    fn step(&mut self, sys: &S, t: f64, y: &mut [f64], h: f64) -> Result<Step, OdeError> {
        Dopri5::step(self, sys, t, y, h)
    }
    fn dense_all(&self, t: f64, out: &mut [f64]) {
        Dopri5::dense_all(self, t, out);
    }
    fn n_rhs(&self) -> usize {
        self.n_rhs
    }
}

impl<S: WSystem<B>, const B: usize> Stepper<S> for Rosw<B> {
    fn reset(&mut self) {
        Rosw::reset(self);
    }
    fn initial_step(&mut self, sys: &S, t: f64, y: &[f64]) -> Result<f64, OdeError> {
        Rosw::initial_step(self, sys, t, y)
    }
    fn step(&mut self, sys: &S, t: f64, y: &mut [f64], h: f64) -> Result<Step, OdeError> {
        Rosw::step(self, sys, t, y, h)
    }
    fn dense_all(&self, t: f64, out: &mut [f64]) {
        Rosw::dense_all(self, t, out);
    }
    fn n_rhs(&self) -> usize {
        self.n_rhs
    }
}

/// Why an integration stopped early.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum IntegrateError<E> {
    Ode(OdeError),
    TooManySteps(usize),
    /// The fit's budget was spent or the fit stopped ([`crate::numerics::budget::cancelled`]).
    Cancelled,
    /// The sample callback refused.
    Sample(E),
}

/// Work done by an integration.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Work {
    pub steps: usize,
    pub rhs: usize,
}

/// Integrate `sys` from `y` at `t_s[0]` through `t_s[last]` with `ode` (made for `y.len()`
/// components, its error control and tolerances set), calling `sample(k, y_k)` at every
/// sample (k = 0 with the initial state). `is_break(k)` marks samples where an input jumps:
/// the integrator lands there and restarts.
#[allow(clippy::too_many_arguments)]
pub(super) fn integrate<S: Segmented, O: Stepper<S>, E>(
    sys: &mut S,
    ode: &mut O,
    t_s: &[f64],
    is_break: impl Fn(usize) -> bool,
    y: &mut [f64],
    max_steps: usize,
    buf: &mut [f64],
    mut sample: impl FnMut(usize, &[f64]) -> Result<(), E>,
) -> Result<Work, IntegrateError<E>> {
    let n = t_s.len();
    let mut work = Work::default();
    sample(0, y).map_err(IntegrateError::Sample)?;
    let mut next = 1;
    let mut seg = 0;
    let mut h_step = f64::NAN;
    while seg + 1 < n {
        let mut end = seg + 1;
        while end + 1 < n && !is_break(end) {
            end += 1;
        }
        sys.enter_segment(seg);
        ode.reset();
        if h_step.is_nan() {
            h_step = ode
                .initial_step(sys, t_s[seg], y)
                .map_err(IntegrateError::Ode)?;
        }
        let (mut t, t_end) = (t_s[seg], t_s[end]);
        while t < t_end {
            let remaining = t_end - t;
            let landing = h_step >= remaining * (1.0 - 1e-9);
            let h_try = if landing { remaining } else { h_step };
            match ode.step(sys, t, y, h_try).map_err(IntegrateError::Ode)? {
                Step::Accepted { h, h_next } => {
                    let t_new = if landing { t_end } else { t + h };
                    while next <= end && t_s[next] <= t_new {
                        if t_s[next] == t_new {
                            sample(next, y).map_err(IntegrateError::Sample)?;
                        } else {
                            ode.dense_all(t_s[next], buf);
                            sample(next, buf).map_err(IntegrateError::Sample)?;
                        }
                        next += 1;
                    }
                    t = t_new;
                    // A step shortened to land says little about the next one.
                    h_step = if landing { h_next.max(h_step) } else { h_next };
                    work.steps += 1;
                    if work.steps > max_steps {
                        return Err(IntegrateError::TooManySteps(max_steps));
                    }
                    // An atomic load every 256 steps: a stopped fit ends within ~1 ms.
                    if work.steps.is_multiple_of(256) && crate::numerics::budget::cancelled() {
                        return Err(IntegrateError::Cancelled);
                    }
                }
                Step::Rejected { h_next } => h_step = h_next,
            }
        }
        seg = end;
    }
    work.rhs = ode.n_rhs();
    Ok(work)
}

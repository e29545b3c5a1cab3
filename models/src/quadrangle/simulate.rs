//! A free swing of the lower quadrangle with true stick–slip: DOPRI5 on smooth segments of fixed
//! motion direction, each rate reversal located on the dense output and judged there.
//!
//! At a reversal the loop is at rest: if dry friction at impending motion can hold gravity's
//! generalised force ([`Quadrangle::breakaway`]) it sticks — and with no input acting, stays
//! stuck for the rest of the record — otherwise it restarts in the direction gravity pulls.

use super::model::{QState, Quadrangle};
use crate::lift::dynamics::DynamicsError;
use crate::numerics::ode::{Dopri5, OdeError, OdeSystem, Step, Tolerances};

/// Integration settings.
#[derive(Debug, Clone, Copy)]
pub struct SwingOptions {
    pub rtol: f64,
    pub atol: f64,
    /// Most accepted steps before giving up.
    pub max_steps: usize,
}

impl Default for SwingOptions {
    fn default() -> Self {
        Self {
            rtol: 1e-10,
            atol: 1e-12,
            max_steps: 2_000_000,
        }
    }
}

/// Why a swing could not be simulated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SwingError {
    #[error("`t_s`: {0}")]
    Time(String),
    #[error(transparent)]
    Dynamics(#[from] DynamicsError),
    #[error(transparent)]
    Ode(#[from] OdeError),
    #[error("more than {0} integration steps")]
    TooManySteps(usize),
    #[error(transparent)]
    Budget(#[from] crate::numerics::budget::Exhausted),
}

/// A simulated swing at the record's sample times.
#[derive(Debug, Clone, PartialEq)]
pub struct SwingRun {
    pub alpha_rad: Vec<f64>,
    pub beta_rad: Vec<f64>,
    pub alpha_dot_rad_s: Vec<f64>,
    /// Rate reversals that restarted the motion.
    pub reversals: usize,
    /// When the loop stuck for good (None: still moving at the end).
    pub stuck_at_s: Option<f64>,
    pub steps: usize,
}

/// One smooth segment: motion direction fixed, dry friction's signs fixed with it.
struct Segment<'a> {
    model: &'a Quadrangle,
    direction: f64,
}

impl OdeSystem for Segment<'_> {
    fn dim(&self) -> usize {
        2
    }
    fn rhs(&self, _t: f64, y: &[f64], dy: &mut [f64]) -> Result<(), OdeError> {
        // Near a toggle the loop stops assembling and its joint forces diverge: say so.
        let toggle = |e: String| {
            OdeError::Model(format!(
                "the swing reaches a toggle of the loop near alpha = {:.1} deg ({e}): release \
                 closer to the rest angle",
                y[0].to_degrees()
            ))
        };
        let pose = self.model.pose(y[0]).map_err(|e| toggle(e.to_string()))?;
        let s = QState {
            alpha_rad: y[0],
            alpha_dot_rad_s: y[1],
        };
        let e = self
            .model
            .eval(&pose, &s, &self.model.signs(&pose, self.direction))
            .map_err(|e| toggle(e.to_string()))?;
        dy[0] = y[1];
        dy[1] = e.alpha_ddot_rad_s2;
        Ok(())
    }
}

/// Simulate a free swing released at `t_s[0]` from α = `alpha0_rad` at rate `alpha_dot0_rad_s`.
pub fn simulate_swing(
    model: &Quadrangle,
    t_s: &[f64],
    alpha0_rad: f64,
    alpha_dot0_rad_s: f64,
    opts: &SwingOptions,
) -> Result<SwingRun, SwingError> {
    let n = t_s.len();
    if n < 2 {
        return Err(SwingError::Time("needs at least 2 samples".into()));
    }
    if let Some(k) = t_s
        .windows(2)
        .position(|w| w[1].partial_cmp(&w[0]) != Some(std::cmp::Ordering::Greater))
    {
        return Err(SwingError::Time(format!(
            "not strictly increasing at sample {}",
            k + 1
        )));
    }
    if !(alpha0_rad.is_finite() && alpha_dot0_rad_s.is_finite()) {
        return Err(SwingError::Time("release state not finite".into()));
    }
    let mut run = SwingRun {
        alpha_rad: Vec::with_capacity(n),
        beta_rad: Vec::with_capacity(n),
        alpha_dot_rad_s: Vec::with_capacity(n),
        reversals: 0,
        stuck_at_s: None,
        steps: 0,
    };
    let push = |run: &mut SwingRun, a: f64, ad: f64| -> Result<(), SwingError> {
        let pose = model.pose(a).map_err(DynamicsError::from)?;
        run.alpha_rad.push(a);
        run.beta_rad.push(pose.beta_rad());
        run.alpha_dot_rad_s.push(ad);
        Ok(())
    };
    let fill_stuck = |run: &mut SwingRun, a: f64, t: f64| -> Result<(), SwingError> {
        run.stuck_at_s = Some(t);
        while run.alpha_rad.len() < n {
            push(run, a, 0.0)?;
        }
        Ok(())
    };
    let mut y = [alpha0_rad, alpha_dot0_rad_s];
    push(&mut run, y[0], y[1])?;
    let mut direction = if y[1] != 0.0 {
        y[1].signum()
    } else {
        match model.breakaway(&model.pose(y[0]).map_err(DynamicsError::from)?)? {
            Some(d) => d,
            None => {
                fill_stuck(&mut run, y[0], t_s[0])?;
                return Ok(run);
            }
        }
    };
    let tol = Tolerances {
        rtol: opts.rtol,
        atol: opts.atol,
        ..Tolerances::default()
    };
    let mut ode = Dopri5::new(2, 2, tol);
    let (mut t, t_end) = (t_s[0], t_s[n - 1]);
    let mut seg = Segment { model, direction };
    let mut h = ode.initial_step(&seg, t, &y)?;
    let mut buf = [0.0; 2];
    while run.alpha_rad.len() < n {
        let remaining = t_end - t;
        let landing = h >= remaining * (1.0 - 1e-12);
        let h_try = if landing { remaining } else { h };
        match ode.step(&seg, t, &mut y, h_try)? {
            Step::Rejected { h_next } => h = h_next,
            Step::Accepted { h: h_done, h_next } => {
                run.steps += 1;
                if run.steps > opts.max_steps {
                    return Err(SwingError::TooManySteps(opts.max_steps));
                }
                // An atomic load every 256 steps: a stopped fit ends within ~1 ms.
                if run.steps.is_multiple_of(256) && crate::numerics::budget::cancelled() {
                    return Err(SwingError::Budget(
                        crate::numerics::budget::Exhausted::Cancelled,
                    ));
                }
                let t_new = if landing { t_end } else { t + h_done };
                // A reversal inside the step: the rate's zero on the dense output.
                let reversal = direction * y[1] <= 0.0;
                let t_stop = if reversal {
                    let (mut lo, mut hi) = (t, t_new);
                    for _ in 0..200 {
                        let mid = 0.5 * (lo + hi);
                        if direction * ode.dense(1, mid) > 0.0 {
                            lo = mid;
                        } else {
                            hi = mid;
                        }
                        if hi - lo <= 1e-14 * hi.abs().max(1.0) {
                            break;
                        }
                    }
                    hi
                } else {
                    t_new
                };
                while run.alpha_rad.len() < n {
                    let tk = t_s[run.alpha_rad.len()];
                    if tk > t_stop {
                        break;
                    }
                    if tk == t_new && !reversal {
                        push(&mut run, y[0], y[1])?;
                    } else {
                        ode.dense_all(tk, &mut buf);
                        push(&mut run, buf[0], buf[1])?;
                    }
                }
                h = if landing { h_next.max(h) } else { h_next };
                if reversal {
                    let a = ode.dense(0, t_stop);
                    let pose = model.pose(a).map_err(DynamicsError::from)?;
                    match model.breakaway(&pose)? {
                        None => {
                            fill_stuck(&mut run, a, t_stop)?;
                            break;
                        }
                        Some(d) => {
                            direction = d;
                            seg = Segment { model, direction };
                            run.reversals += 1;
                            y = [a, 0.0];
                            t = t_stop;
                            ode.reset();
                        }
                    }
                } else {
                    t = t_new;
                }
            }
        }
    }
    Ok(run)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lift::geometry::builtin_160ec;
    use crate::quadrangle::model::QuadFriction;

    fn times(t_end: f64, dt: f64) -> Vec<f64> {
        (0..=(t_end / dt).round() as usize)
            .map(|k| k as f64 * dt)
            .collect()
    }

    /// Without friction the swing conserves energy (kinetic + gravity) to the integrator's
    /// accuracy over many periods, and keeps swinging between the same turning points.
    #[test]
    fn frictionless_swing_conserves_energy() {
        let mut q = Quadrangle::new(builtin_160ec(), 70f64.to_radians());
        q.friction = QuadFriction::frictionless();
        let t = times(20.0, 0.002);
        let a0 = q.rest_alpha_rad(0.4).expect("rest at 70°") - f64::to_radians(10.1);
        let run = simulate_swing(&q, &t, a0, 0.0, &SwingOptions::default()).unwrap();
        let energy = |k: usize| {
            let s = QState {
                alpha_rad: run.alpha_rad[k],
                alpha_dot_rad_s: run.alpha_dot_rad_s[k],
            };
            q.energy_j(&q.pose(s.alpha_rad).unwrap(), &s)
        };
        let e0 = energy(0);
        let worst = (0..t.len())
            .map(|k| (energy(k) - e0).abs())
            .fold(0.0, f64::max);
        let swing_j = {
            let lo = run.alpha_rad.iter().cloned().fold(f64::INFINITY, f64::min);
            let s = QState {
                alpha_rad: lo,
                alpha_dot_rad_s: 0.0,
            };
            (q.energy_j(&q.pose(lo).unwrap(), &s) - e0).abs()
        };
        eprintln!(
            "energy drift {worst:e} J over 20 s, {} reversals",
            run.reversals
        );
        assert!(worst < 1e-7, "energy drift {worst:e} J");
        assert!(swing_j < 1e-6, "turning point off the release level");
        assert!(run.reversals >= 10 && run.stuck_at_s.is_none());
        // Back down to the release angle every period.
        let bottom = run.alpha_rad.iter().cloned().fold(f64::INFINITY, f64::min);
        assert!((bottom - a0).abs() < 1e-6, "{bottom} vs {a0}");
    }

    /// With Table 4 friction the swing decays and sticks for good; every reversal loses
    /// amplitude, and β stays on the loop's β(α) at every sample.
    #[test]
    fn table4_swing_decays_and_sticks() {
        let q = Quadrangle::new(builtin_160ec(), 70f64.to_radians());
        let t = times(60.0, 0.002);
        let a0 = q.rest_alpha_rad(0.4).expect("rest at 70°") - f64::to_radians(10.1);
        let run = simulate_swing(&q, &t, a0, 0.0, &SwingOptions::default()).unwrap();
        let stuck = run.stuck_at_s.expect("sticks within 60 s");
        eprintln!(
            "stuck at {stuck:.3} s after {} reversals, {} steps, rest {:.4} deg",
            run.reversals,
            run.steps,
            run.alpha_rad.last().unwrap().to_degrees()
        );
        assert!(run.reversals >= 3);
        let last = *run.alpha_rad.last().unwrap();
        let k_stuck = t.iter().position(|x| *x > stuck).unwrap();
        assert!(run.alpha_rad[k_stuck..].iter().all(|a| *a == last));
        for k in (0..t.len()).step_by(97) {
            let b = q.pose(run.alpha_rad[k]).unwrap().beta_rad();
            assert_eq!(b, run.beta_rad[k]);
        }
    }

    #[test]
    fn a_loop_released_at_rest_within_the_dead_band_never_moves() {
        let q = Quadrangle::new(builtin_160ec(), 70f64.to_radians());
        let rest = q.rest_alpha_rad(0.4).expect("rest at 70°");
        let t = times(1.0, 0.01);
        let run = simulate_swing(&q, &t, rest, 0.0, &SwingOptions::default()).unwrap();
        assert_eq!(run.stuck_at_s, Some(0.0));
        assert!(run.alpha_rad.iter().all(|a| *a == rest));
    }
}

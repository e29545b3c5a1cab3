//! Event-driven simulation of a single-joint test with exact sign friction and true stick–slip,
//! and forward sensitivities of the trajectory to the parameters.
//!
//! Between events the motion direction s = ±1 is fixed, so the equations are smooth and
//! Dormand–Prince 5(4) keeps its order. The instant the rate reaches zero is located on the dense
//! output; there the body sticks if static friction can hold it (|G| ≤ lever·N_rest·μs), and stays
//! stuck until the load exceeds that capacity (only an input force can make it so). Sensitivities
//! jump at events by the standard rule s⁺ = s⁻ + (f⁻ − f⁺)·∂τ/∂p.

use crate::joint::dynamics::{Dof, Indeterminate};
use crate::joint::friction::{DynParam, FrictionLaw};
use crate::numerics::ode::{Dopri5, OdeError, OdeSystem, Step, Tolerances};

/// A parameter the trajectory's sensitivity is computed for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SensParam {
    Dyn(DynParam),
    /// Initial position q0 (rad or m).
    Q0,
    /// Initial rate v0 (rad/s or m/s).
    V0,
    /// The log of the inertia's scale, ln(J/J_stated) (`inertia_error`, issue 17): ∂a/∂ln J =
    /// −J·a/f_a from the implicit equation f = J·a − G + T(N(a)) = 0.
    Inertia,
    /// An offset b added to the measured input (issue 17, point 3): G gains b, so ∂a/∂b = 1/f_a;
    /// at a break-away the holding margin h = s·G − capacity gains s·b.
    InputOffset,
}

/// What the simulator reports when it cannot go on.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimError {
    #[error(transparent)]
    Ode(#[from] OdeError),
    #[error(transparent)]
    Indeterminate(#[from] Indeterminate),
    #[error("sample times must be finite and strictly increasing (at index {0})")]
    Times(usize),
}

/// An event of the motion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SimEvent {
    /// The rate crossed zero and the motion reversed.
    Reversal { t_s: f64, q: f64 },
    /// The rate reached zero and static friction held the body.
    Stick { t_s: f64, q: f64 },
    /// The load overcame static friction and the body started moving.
    BreakAway { t_s: f64, q: f64 },
}

/// Options of one simulation.
#[derive(Debug, Clone)]
pub struct SimOptions {
    pub tol: Tolerances,
    /// Parameters to compute ∂q/∂p for (empty: plain simulation).
    pub sens: Vec<SensParam>,
}

impl Default for SimOptions {
    fn default() -> Self {
        Self {
            tol: Tolerances {
                rtol: 1e-9,
                atol: 1e-11,
                ..Default::default()
            },
            sens: Vec::new(),
        }
    }
}

/// The simulated trajectory at the requested sample times.
#[derive(Debug, Clone, Default)]
pub struct Trajectory {
    pub q: Vec<f64>,
    pub v: Vec<f64>,
    /// ∂q/∂p, row-major: `dq[k * n_sens + j]`.
    pub dq: Vec<f64>,
    pub n_sens: usize,
    pub events: Vec<SimEvent>,
    pub n_rhs: usize,
    pub n_steps: usize,
}

impl Trajectory {
    /// The time the body came to rest for good, if it did.
    pub fn rest_time_s(&self) -> Option<f64> {
        match self.events.last() {
            Some(SimEvent::Stick { t_s, .. }) => Some(*t_s),
            _ => None,
        }
    }
}

/// The ODE of one motion segment: state [q, v, ∂q/∂p…, ∂v/∂p…].
struct Segment<'a> {
    dof: &'a Dof,
    law: &'a FrictionLaw,
    s: f64,
    sens: &'a [SensParam],
}

impl OdeSystem for Segment<'_> {
    fn dim(&self) -> usize {
        2 + 2 * self.sens.len()
    }
    #[inline]
    fn rhs(&self, t: f64, y: &[f64], dy: &mut [f64]) -> Result<(), OdeError> {
        let (q, v) = (y[0], y[1]);
        let acc = self
            .dof
            .accel(self.law, q, v, self.s, t)
            .map_err(|e| OdeError::Model(e.to_string()))?;
        if !acc.a.is_finite() {
            return Err(OdeError::NotFinite { t });
        }
        dy[0] = v;
        dy[1] = acc.a;
        let ns = self.sens.len();
        if ns == 0 {
            return Ok(());
        }
        let shapes = self.law.shapes(q, v);
        // The sensitivities as slices, zipped: no bounds check per parameter (session 23).
        let (ys_q, ys_v) = y[2..2 + 2 * ns].split_at(ns);
        let (dy_q, dy_v) = dy[2..2 + 2 * ns].split_at_mut(ns);
        let rows = ys_q.iter().zip(ys_v).zip(dy_q.iter_mut().zip(dy_v));
        for (p, ((&sq, &sv), (dq, dv))) in self.sens.iter().zip(rows) {
            let a_p = match p {
                SensParam::Dyn(dp) => self
                    .dof
                    .accel_d_param_at(self.law, &shapes, &acc, *dp, q, v, self.s),
                SensParam::Inertia => -self.dof.inertia() * acc.a / acc.f_a,
                SensParam::InputOffset => 1.0 / acc.f_a,
                _ => 0.0,
            };
            *dq = sv;
            *dv = acc.a_q * sq + acc.a_v * sv + a_p;
        }
        Ok(())
    }
}

enum Mode {
    Moving(f64),
    Stuck,
}

/// Simulate from (q0, v0) at `times[0]` and sample at every time in `times`.
pub fn simulate(
    dof: &Dof,
    law: &FrictionLaw,
    q0: f64,
    v0: f64,
    times: &[f64],
    opts: &SimOptions,
) -> Result<Trajectory, SimError> {
    simulate_reusing(dof, law, q0, v0, times, opts, Trajectory::default())
}

/// [`simulate`] into the storage of an earlier trajectory `buf` (its values are overwritten):
/// for a fit that simulates the same record many times. Fresh vectors for every evaluation of
/// a long record came from the system each time (glibc returns a freed block this large), so
/// every evaluation paid a page fault per 4 KiB of the motion and its sensitivities (issue 38,
/// session 22: the slider's wall time grew faster than its instructions, 10k → 100k samples).
pub fn simulate_reusing(
    dof: &Dof,
    law: &FrictionLaw,
    q0: f64,
    v0: f64,
    times: &[f64],
    opts: &SimOptions,
    buf: Trajectory,
) -> Result<Trajectory, SimError> {
    let n = times.len();
    // `!(b > a)` is `b.partial_cmp(a) != Some(Greater)` (NaN included), over pairs without
    // bounds checks (issue 38, session 23: the indexed check was 12 instructions a sample).
    if let Some(k) = times.windows(2).position(|w| {
        w[1].partial_cmp(&w[0]) != Some(std::cmp::Ordering::Greater) || !w[1].is_finite()
    }) {
        return Err(SimError::Times(k + 1));
    }
    let ns = opts.sens.len();
    let dim = 2 + 2 * ns;
    // Every sample is written once, in order, by index (`record`, `record_dense`): storage of
    // this length is reused as it is, too small replaced by zeroed storage from the allocator
    // (issue 38: zeroing every evaluation, then pushing sample by sample, was a fifth of a
    // pendulum's fit; session 23).
    let sized = |mut x: Vec<f64>, len: usize| {
        if x.capacity() < len {
            return vec![0.0; len];
        }
        x.resize(len, 0.0);
        x
    };
    let (q, v, dq) = (sized(buf.q, n), sized(buf.v, n), sized(buf.dq, n * ns));
    let mut events = buf.events;
    events.clear();
    let mut tr = Trajectory {
        q,
        v,
        dq,
        events,
        n_sens: ns,
        ..Default::default()
    };
    if n == 0 {
        return Ok(tr);
    }
    let mut y = vec![0.0; dim];
    y[0] = q0;
    y[1] = v0;
    for (j, p) in opts.sens.iter().enumerate() {
        match p {
            SensParam::Q0 => y[2 + j] = 1.0,
            SensParam::V0 => y[2 + ns + j] = 1.0,
            SensParam::Dyn(_) | SensParam::Inertia | SensParam::InputOffset => {}
        }
    }
    let t_end = times[n - 1];
    let mut t = times[0];
    let mut k = 0; // next sample to write
    // Sample k's values from the state y.
    let record = |tr: &mut Trajectory, k: usize, y: &[f64]| {
        tr.q[k] = y[0];
        tr.v[k] = y[1];
        tr.dq[k * ns..(k + 1) * ns].copy_from_slice(&y[2..2 + ns]);
    };
    // Samples k .. (the first at or after `until`) from the dense output of the last step,
    // written where they are kept; the next sample to write is returned.
    let record_dense = |tr: &mut Trajectory, k: usize, st: &Dopri5, until: f64| {
        let end = k + times[k..].iter().take_while(|&&t| t < until).count();
        if end == k {
            return k;
        }
        let (q, v, dq) = (
            &mut tr.q[k..end],
            &mut tr.v[k..end],
            &mut tr.dq[k * ns..end * ns],
        );
        st.dense_rows(&times[k..end], q, v, dq);
        end
    };
    let period = dof.period_s((t_end - t).max(1e-3));
    let mut tol = opts.tol;
    tol.h_max = tol.h_max.min(period / 8.0);
    let mut stepper = Dopri5::new(dim, 2, tol);

    // Initial mode: moving with the given rate, or at rest and either held or breaking away.
    let mut mode = if v0 != 0.0 {
        Mode::Moving(v0.signum())
    } else {
        rest_mode(dof, law, q0, t)
    };
    if matches!(mode, Mode::Stuck) {
        tr.events.push(SimEvent::Stick { t_s: t, q: q0 });
        stick_sens(&mut y, ns);
    }

    while k < n {
        match mode {
            Mode::Stuck => {
                // Held: q constant. Only a changing input force can break it loose.
                let Some(input) = dof.input.as_ref() else {
                    while k < n {
                        record(&mut tr, k, &y);
                        k += 1;
                    }
                    break;
                };
                // The capacity against a load toward s (direction-dependent friction).
                let cap = |s: f64| dof.static_capacity_toward(law, y[0], s);
                let mut t_break = None;
                let mut ta = t;
                while ta < t_end {
                    let tb = input.next_knot(ta).unwrap_or(t_end).min(t_end);
                    let g_end = dof.load(y[0], tb).0;
                    let hb = g_end.abs() - cap(g_end.signum());
                    if hb > 0.0 {
                        // G is linear in t on [ta, tb]: the crossing of |G| = cap is exact.
                        let (ga, gb) = (dof.load(y[0], ta).0, dof.load(y[0], tb).0);
                        let target = cap(gb.signum()) * gb.signum();
                        let frac = if (gb - ga).abs() > 0.0 {
                            ((target - ga) / (gb - ga)).clamp(0.0, 1.0)
                        } else {
                            1.0
                        };
                        t_break = Some(ta + frac * (tb - ta));
                        break;
                    }
                    ta = tb;
                }
                let until = t_break.unwrap_or(f64::INFINITY);
                while k < n && times[k] <= until {
                    record(&mut tr, k, &y);
                    k += 1;
                }
                let Some(tb) = t_break else { break };
                let (g, g_q, g_t) = dof.load(y[0], tb);
                let s = g.signum();
                let acc = dof.accel(law, y[0], 0.0, s, tb)?;
                // h(t) = s·G(q,t) − lever·N_rest·μs(p)·(1 + δ·s); τ' = −(h_q·∂q/∂p + h_p)/h_t;
                // ∂v/∂p⁺ = −a⁺·τ'.
                let h_t = s * g_t;
                let ln = dof.lever() * dof.normal_at_rest(y[0]);
                for (j, p) in opts.sens.iter().enumerate() {
                    let h_p = match p {
                        SensParam::Dyn(DynParam::DryAsymmetry) => -ln * law.static_mu(y[0]) * s,
                        SensParam::Dyn(dp) => {
                            -ln * law.d_static_mu(*dp, y[0]) * (1.0 + law.asymmetry * s)
                        }
                        SensParam::InputOffset => s,
                        _ => 0.0,
                    };
                    let tau_p = if h_t != 0.0 {
                        -(s * g_q * y[2 + j] + h_p) / h_t
                    } else {
                        0.0
                    };
                    y[2 + ns + j] = -acc.a * tau_p;
                }
                tr.events.push(SimEvent::BreakAway { t_s: tb, q: y[0] });
                t = tb;
                mode = Mode::Moving(s);
                stepper.reset();
            }
            Mode::Moving(s) => {
                let seg = Segment {
                    dof,
                    law,
                    s,
                    sens: &opts.sens,
                };
                let mut h = stepper.initial_step(&seg, t, &y)?.min(period / 50.0);
                let segment_start = t;
                loop {
                    let mut h_try = h.min(t_end - t);
                    if let Some(input) = dof.input.as_ref()
                        && let Some(knot) = input.next_knot(t)
                        && knot < t_end
                    {
                        h_try = h_try.min(knot - t);
                    }
                    if h_try <= 0.0 {
                        // Reached the end exactly.
                        while k < n {
                            record(&mut tr, k, &y);
                            k += 1;
                        }
                        break;
                    }
                    let t_old = t;
                    match stepper.step(&seg, t, &mut y, h_try)? {
                        Step::Rejected { h_next } => {
                            h = h_next;
                            continue;
                        }
                        Step::Accepted { h: hh, h_next } => {
                            let t_new =
                                if (t_end - (t_old + hh)).abs() < 1e-12 * t_end.abs().max(1.0) {
                                    t_end
                                } else {
                                    t_old + hh
                                };
                            if s * y[1] <= 0.0 {
                                // The rate reached zero inside this step: locate it.
                                let Some(t_e) =
                                    locate_zero(&stepper, s, t_old, t_new, t_old == segment_start)
                                else {
                                    // Event too close to the segment start to bracket: retry smaller.
                                    return Err(SimError::Ode(OdeError::StepUnderflow {
                                        t: t_old,
                                        h: hh,
                                    }));
                                };
                                k = record_dense(&mut tr, k, &stepper, t_e);
                                stepper.dense_all(t_e, &mut y);
                                y[1] = 0.0;
                                t = t_e;
                                mode =
                                    reverse_or_stick(dof, law, &mut y, s, t, ns, &mut tr.events)?;
                                stepper.reset();
                                break;
                            }
                            // Only q, v and ∂q/∂p are recorded; a sample at the step's end
                            // from the state itself.
                            k = record_dense(&mut tr, k, &stepper, t_new);
                            if k < n && times[k] == t_new {
                                record(&mut tr, k, &y);
                                k += 1;
                            }
                            t = t_new;
                            h = h_next;
                            if t >= t_end {
                                while k < n {
                                    record(&mut tr, k, &y);
                                    k += 1;
                                }
                                break;
                            }
                        }
                    }
                }
            }
        }
    }
    debug_assert_eq!(k, n, "every sample recorded");
    tr.n_rhs = stepper.n_rhs;
    tr.n_steps = stepper.n_steps;
    Ok(tr)
}

/// At rest at q: held by static friction, or moving off in the direction of the load.
fn rest_mode(dof: &Dof, law: &FrictionLaw, q: f64, t: f64) -> Mode {
    let g = dof.load(q, t).0;
    if g.abs() <= dof.static_capacity_toward(law, q, g.signum()) {
        Mode::Stuck
    } else {
        Mode::Moving(g.signum())
    }
}

fn stick_sens(y: &mut [f64], ns: usize) {
    // ∂q/∂p⁺ = ∂q/∂p⁻ + v·τ' = ∂q/∂p⁻ (v = 0); ∂v/∂p⁺ = 0.
    for j in 0..ns {
        y[2 + ns + j] = 0.0;
    }
}

/// Apply the event at a zero of the rate: stick, or reverse with the sensitivity jump
/// ∂v/∂p⁺ = ∂v/∂p⁻ · a⁺/a⁻ (from s⁺ = s⁻ + (f⁻ − f⁺)τ', τ' = −(∂v/∂p⁻)/a⁻).
fn reverse_or_stick(
    dof: &Dof,
    law: &FrictionLaw,
    y: &mut [f64],
    s_old: f64,
    t: f64,
    ns: usize,
    events: &mut Vec<SimEvent>,
) -> Result<Mode, SimError> {
    let q = y[0];
    let mode = rest_mode(dof, law, q, t);
    match mode {
        Mode::Moving(s_new) if s_new != s_old => {
            let a_minus = dof.accel(law, q, 0.0, s_old, t)?.a;
            let a_plus = dof.accel(law, q, 0.0, s_new, t)?.a;
            let ratio = if a_minus.abs() > 1e-300 {
                a_plus / a_minus
            } else {
                0.0
            };
            for j in 0..ns {
                y[2 + ns + j] *= ratio;
            }
            events.push(SimEvent::Reversal { t_s: t, q });
            Ok(mode)
        }
        _ => {
            // Held (or, at a numerical edge, a load pointing the way it was already moving
            // while the rate vanished: it cannot continue that way with v = 0, so it rests).
            stick_sens(y, ns);
            events.push(SimEvent::Stick { t_s: t, q });
            Ok(Mode::Stuck)
        }
    }
}

/// The time in (t0, t1] where s·v(t) reaches zero on the dense output of the last step.
fn locate_zero(st: &Dopri5, s: f64, t0: f64, t1: f64, starts_at_rest: bool) -> Option<f64> {
    let g = |t: f64| s * st.dense(1, t);
    let mut lo = t0;
    if starts_at_rest || g(t0) <= 0.0 {
        // g(t0) = 0: find an interior point where the motion is under way.
        let mut frac = 0.5;
        let mut found = false;
        for _ in 0..40 {
            let tm = t0 + frac * (t1 - t0);
            if g(tm) > 0.0 {
                lo = tm;
                found = true;
                break;
            }
            frac *= 0.5;
        }
        if !found {
            return None;
        }
    }
    let mut hi = t1;
    // Bisection to machine precision on the time axis (≈ 50 dense evaluations).
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        if g(mid) > 0.0 { lo = mid } else { hi = mid }
    }
    Some(hi)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::joint::dynamics::{Input, Mechanism};
    use crate::joint::rig::{PendulumRig, SliderRig};

    fn pendulum(m: f64, j: f64, d: f64, r: f64) -> Dof {
        Dof {
            mech: Mechanism::Pendulum(PendulumRig {
                mass_kg: m,
                inertia_kgm2: j,
                com_distance_m: d,
                pin_radius_m: r,
                gravity_m_s2: 9.81,
            }),
            input: None,
            torsion: 0.0,
        }
    }

    fn grid(t_end: f64, fs: f64) -> Vec<f64> {
        (0..=((t_end * fs).round() as usize))
            .map(|i| i as f64 / fs)
            .collect()
    }

    #[test]
    fn frictionless_energy_is_conserved_to_1e_8_over_30_s() {
        let d = pendulum(18.8, 5.61, 0.272, 0.05);
        let law = FrictionLaw::base(0.0, 0.0);
        let t = grid(30.0, 500.0);
        let opts = SimOptions {
            tol: Tolerances {
                rtol: 1e-12,
                atol: 1e-14,
                ..Default::default()
            },
            sens: vec![],
        };
        let tr = simulate(&d, &law, 74.2f64.to_radians(), 0.0, &t, &opts).unwrap();
        let energy = |q: f64, v: f64| 0.5 * 5.61 * v * v + 18.8 * 9.81 * 0.272 * (1.0 - q.cos());
        let e0 = energy(tr.q[0], tr.v[0]);
        let worst =
            tr.q.iter()
                .zip(&tr.v)
                .map(|(&q, &v)| ((energy(q, v) - e0) / e0).abs())
                .fold(0.0, f64::max);
        assert!(worst < 1e-8, "relative energy drift {worst:e}");
        // It swings through the bottom many times: 30 s is ~14 periods of 2.1 s.
        assert!(
            tr.events
                .iter()
                .filter(|e| matches!(e, SimEvent::Reversal { .. }))
                .count()
                >= 25
        );
    }

    #[test]
    fn coulomb_small_angle_amplitude_falls_by_four_tc_over_mgd_per_cycle() {
        // Coulomb only, small angle: each half swing loses 2·Tc/(m g d) of amplitude, so
        // 4·Tc/(m·g·d) per full cycle, Tc = R·μ·N ≈ R·μ·m·g at small amplitude.
        let (m, j, d, r, mu) = (10.0, 2.0, 0.4, 0.01, 0.1);
        let dof = pendulum(m, j, d, r);
        let law = FrictionLaw::base(0.0, mu);
        let t = grid(40.0, 1000.0);
        let tr = simulate(&dof, &law, 0.1, 0.0, &t, &SimOptions::default()).unwrap();
        let amps: Vec<f64> = tr
            .events
            .iter()
            .filter_map(|e| {
                if let SimEvent::Reversal { q, .. } = e {
                    Some(q.abs())
                } else {
                    None
                }
            })
            .collect();
        let tc = r * mu * m * 9.81;
        let expect = 4.0 * tc / (m * 9.81 * d);
        assert!(amps.len() >= 6, "{} reversals", amps.len());
        for w in amps.windows(3).take(4) {
            let drop = w[0] - w[2];
            assert!(
                (drop - expect).abs() < 0.02 * expect,
                "drop {drop} vs {expect}"
            );
        }
        // And it ends stuck inside the dead band |sin q| <= R·μ/d.
        let rest = tr.q.last().unwrap().abs();
        assert!(tr.rest_time_s().is_some() && rest.sin() <= r * mu / d + 1e-12);
    }

    #[test]
    fn a_body_held_by_static_friction_stays_put() {
        // Dead band: d·|sin q| ≤ R·μ  →  q ≤ asin(0.01·0.5/0.4) = 0.0125 rad.
        let dof = pendulum(10.0, 2.0, 0.4, 0.01);
        let law = FrictionLaw::base(0.1, 0.5);
        let t = grid(5.0, 100.0);
        let tr = simulate(&dof, &law, 0.010, 0.0, &t, &SimOptions::default()).unwrap();
        assert!(tr.q.iter().all(|&q| q == 0.010) && tr.v.iter().all(|&v| v == 0.0));
        // Just outside the dead band it moves.
        let tr = simulate(&dof, &law, 0.0130, 0.0, &t, &SimOptions::default()).unwrap();
        assert!(tr.q.iter().any(|&q| q != 0.0130));
        // A moving body stuck by the end stays at exactly one angle afterwards.
        let tr = simulate(
            &dof,
            &law,
            0.3,
            0.0,
            &grid(30.0, 100.0),
            &SimOptions::default(),
        )
        .unwrap();
        let t_rest = tr.rest_time_s().expect("comes to rest");
        let after: Vec<f64> = t
            .iter()
            .zip(&tr.q)
            .filter(|(t, _)| **t > t_rest)
            .map(|(_, q)| *q)
            .collect();
        assert!(after.windows(2).all(|w| w[0] == w[1]));
    }

    #[test]
    fn slider_breaks_away_when_the_input_force_exceeds_static_friction() {
        let dof = Dof {
            mech: Mechanism::Slider(SliderRig {
                moving_mass_kg: 10.5,
                stiffness_n_per_m: 4000.0,
                normal_force_n: 4.05,
            }),
            input: Some(Input {
                t_s: vec![0.0, 1.0, 2.0],
                value: vec![0.0, 0.0, 10.0],
            }),
            torsion: 0.0,
        };
        let law = FrictionLaw::base(3.99, 0.5);
        let t = grid(3.0, 500.0);
        let tr = simulate(&dof, &law, 0.0, 0.0, &t, &SimOptions::default()).unwrap();
        // Static capacity 4.05·0.5 = 2.025 N: the ramp 10 N/s reaches it at t = 1.2025 s.
        let SimEvent::BreakAway { t_s, .. } = tr
            .events
            .iter()
            .find(|e| matches!(e, SimEvent::BreakAway { .. }))
            .unwrap()
        else {
            unreachable!()
        };
        assert!((t_s - 1.2025).abs() < 1e-9, "break-away at {t_s}");
        assert!(tr.q[t.iter().position(|&x| x > 1.21).unwrap()] > 0.0);
    }

    /// The forward sensitivities through reversals and the final stick agree with finite
    /// differences of whole simulations.
    #[test]
    fn sensitivities_match_finite_differences_through_events() {
        let dof = pendulum(7.415, 4.645, 0.6685, 0.01);
        let law = FrictionLaw::base(0.401, 0.88);
        let t = grid(12.0, 200.0);
        let sens = vec![
            SensParam::Dyn(DynParam::Viscous),
            SensParam::Dyn(DynParam::Dry),
            SensParam::Q0,
            SensParam::V0,
            SensParam::Inertia,
        ];
        let opts = SimOptions {
            tol: Tolerances {
                rtol: 1e-11,
                atol: 1e-13,
                ..Default::default()
            },
            sens: sens.clone(),
        };
        let (q0, v0) = (1.3, 0.05);
        let base = simulate(&dof, &law, q0, v0, &t, &opts).unwrap();
        assert!(base.events.len() > 5);
        let plain = SimOptions {
            sens: vec![],
            ..opts.clone()
        };
        for (j, p) in sens.iter().enumerate() {
            let h = 1e-6;
            let run = |sgn: f64| {
                let mut l = law;
                let (mut a, mut b) = (q0, v0);
                let mut d = dof.clone();
                match p {
                    SensParam::Dyn(dp) => l.set(*dp, law.get(*dp) + sgn * h),
                    SensParam::Q0 => a += sgn * h,
                    SensParam::V0 => b += sgn * h,
                    SensParam::Inertia => d = dof.with_inertia_scale((sgn * h).exp()),
                    SensParam::InputOffset => d = dof.with_input_offset(sgn * h),
                }
                simulate(&d, &l, a, b, &t, &plain).unwrap().q
            };
            let (qp, qm) = (run(1.0), run(-1.0));
            let mut worst: f64 = 0.0;
            let mut scale: f64 = 0.0;
            // Only before the final stick: there the resting angle is piecewise smooth too, but
            // which reversal sticks can switch under a finite difference.
            let t_rest = base.rest_time_s().unwrap_or(f64::INFINITY);
            for k in 0..t.len() {
                if t[k] > t_rest - 0.5 {
                    break;
                }
                let fd = (qp[k] - qm[k]) / (2.0 * h);
                let an = base.dq[k * sens.len() + j];
                worst = worst.max((fd - an).abs());
                scale = scale.max(an.abs());
            }
            assert!(
                worst < 1e-4 * scale.max(1e-3),
                "{p:?}: worst {worst:e} of {scale:e}"
            );
        }
    }

    /// Issue 38, session 23: a run into an earlier run's storage (longer, shorter, with more
    /// or fewer sensitivities; written in place, never cleared) is a fresh run to the bit.
    #[test]
    fn a_run_into_used_storage_is_a_fresh_run() {
        let dof = pendulum(7.415, 4.645, 0.6685, 0.01);
        let law = FrictionLaw::base(0.401, 0.88);
        let all = [SensParam::Dyn(DynParam::Dry), SensParam::Q0, SensParam::V0];
        let run = |t_end: f64, ns: usize, buf: Trajectory| {
            let opts = SimOptions {
                sens: all[..ns].to_vec(),
                ..SimOptions::default()
            };
            simulate_reusing(&dof, &law, 1.2, 0.0, &grid(t_end, 500.0), &opts, buf).unwrap()
        };
        let bits = |x: &[f64]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        let mut used = run(9.0, 3, Trajectory::default());
        for (t_end, ns) in [(4.0, 2), (12.0, 3), (12.0, 0), (3.0, 1), (3.0, 3)] {
            let fresh = run(t_end, ns, Trajectory::default());
            used = run(t_end, ns, used);
            assert_eq!(bits(&used.q), bits(&fresh.q), "{t_end} s, {ns}");
            assert_eq!(bits(&used.v), bits(&fresh.v));
            assert_eq!(bits(&used.dq), bits(&fresh.dq));
            assert_eq!(used.events, fresh.events);
        }
    }

    /// A pendulum driven by a measured torque from rest: the input offset's sensitivity, through
    /// the break-away from rest and the reversals, agrees with finite differences (issue 17).
    #[test]
    fn a_driven_pendulum_s_input_offset_sensitivity_matches_finite_differences() {
        let mut dof = pendulum(7.415, 4.645, 0.6685, 0.01);
        let t = grid(6.0, 200.0);
        dof.input = Some(Input {
            t_s: t.clone(),
            value: t.iter().map(|x| 12.0 * (1.3 * x).sin()).collect(),
        });
        // With direction-dependent friction (δ 0.2): break-away and sliding by direction.
        let law = FrictionLaw {
            asymmetry: 0.2,
            ..FrictionLaw::base(0.401, 0.88)
        };
        let sens = vec![
            SensParam::Dyn(DynParam::Viscous),
            SensParam::Dyn(DynParam::Dry),
            SensParam::Dyn(DynParam::DryAsymmetry),
            SensParam::InputOffset,
        ];
        let opts = SimOptions {
            tol: Tolerances {
                rtol: 1e-11,
                atol: 1e-13,
                ..Default::default()
            },
            sens: sens.clone(),
        };
        let base = simulate(&dof, &law, 0.0, 0.0, &t, &opts).unwrap();
        assert!(
            base.events
                .iter()
                .any(|e| matches!(e, SimEvent::BreakAway { .. })),
            "the drive breaks it loose"
        );
        let plain = SimOptions {
            sens: vec![],
            ..opts.clone()
        };
        for (j, p) in sens.iter().enumerate() {
            let h = 1e-6;
            let run = |sgn: f64| {
                let mut l = law;
                let mut d = dof.clone();
                match p {
                    SensParam::Dyn(dp) => l.set(*dp, law.get(*dp) + sgn * h),
                    _ => d = dof.with_input_offset(sgn * h),
                }
                simulate(&d, &l, 0.0, 0.0, &t, &plain).unwrap().q
            };
            let (qp, qm) = (run(1.0), run(-1.0));
            let (mut worst, mut scale) = (0.0f64, 0.0f64);
            for k in 0..t.len() {
                let fd = (qp[k] - qm[k]) / (2.0 * h);
                let an = base.dq[k * sens.len() + j];
                worst = worst.max((fd - an).abs());
                scale = scale.max(an.abs());
            }
            assert!(
                scale > 0.0 && worst < 1e-4 * scale.max(1e-3),
                "{p:?}: worst {worst:e} of {scale:e}"
            );
        }
    }
}

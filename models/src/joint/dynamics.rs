//! Equation of motion of a one-degree-of-freedom joint test, with the friction's normal force
//! solved together with the acceleration.
//!
//! Pendulum: `J·α̈ = −m·g·d·sin α − T_f(ω, N)`, N = |m·a_cm − m·g| depends on α̈ (implicit).
//! Slider:   `m·ẍ = −k·x + F_N(t) − F_f(v)`, Fn constant.

use crate::joint::friction::{DynParam, FrictionLaw, Shapes};
use crate::joint::rig::{PendulumRig, SliderRig};

/// The mechanism of a single-joint test.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Mechanism {
    Pendulum(PendulumRig),
    Slider(SliderRig),
}

/// An external force on the moving part, piecewise linear between samples (slider `F_N`).
#[derive(Debug, Clone, PartialEq)]
pub struct Input {
    pub t_s: Vec<f64>,
    pub value: Vec<f64>,
}

impl Input {
    /// Value and slope at `t`; held constant outside the samples.
    #[inline]
    pub fn at(&self, t: f64) -> (f64, f64) {
        let n = self.t_s.len();
        if n == 0 {
            return (0.0, 0.0);
        }
        // (A NaN time reads the first value, as before the record starts.)
        if t <= self.t_s[0] || t.is_nan() {
            return (self.value[0], 0.0);
        }
        if t >= self.t_s[n - 1] {
            return (self.value[n - 1], 0.0);
        }
        let i = self.interval(t);
        let (t0, t1) = (self.t_s[i], self.t_s[i + 1]);
        let slope = (self.value[i + 1] - self.value[i]) / (t1 - t0);
        (self.value[i] + slope * (t - t0), slope)
    }

    /// The first sample time strictly after `t`.
    pub fn next_knot(&self, t: f64) -> Option<f64> {
        let n = self.t_s.len();
        if n == 0 || t >= self.t_s[n - 1] {
            return None;
        }
        if t < self.t_s[0] || t.is_nan() {
            return Some(self.t_s[0]);
        }
        Some(self.t_s[self.interval(t) + 1])
    }

    /// The sample interval holding `t`: the last i with `t_s[i] ≤ t`, for
    /// `t_s[0] ≤ t < t_s[n−1]` (issue 38: O(1), not a search over the record). A logger's times
    /// are evenly spaced, so the interval is where that spacing puts it, checked and moved by a
    /// sample when a time's rounding puts it next door; a search is the fallback (an uneven grid).
    /// The same i as `partition_point(|x| x ≤ t) − 1`.
    #[inline]
    fn interval(&self, t: f64) -> usize {
        let ts = &self.t_s;
        let last = ts.len() - 2;
        let (first, end) = (ts[0], ts[last + 1]);
        let guess = ((t - first) / (end - first) * (last + 1) as f64) as usize;
        let i = guess.min(last);
        if ts[i] <= t {
            if t < ts[i + 1] {
                return i;
            }
            if i < last && t < ts[i + 2] {
                return i + 1;
            }
        } else if i > 0 && ts[i - 1] <= t {
            return i - 1;
        }
        ts.partition_point(|&x| x <= t).saturating_sub(1).min(last)
    }
}

/// A single-joint test: mechanism plus optional input force.
#[derive(Debug, Clone, PartialEq)]
pub struct Dof {
    pub mech: Mechanism,
    pub input: Option<Input>,
    /// Extra linear restoring stiffness (N·m/rad or N/m) — a torsional spring in the joint.
    /// The identified model holds it at 0 (the paper's model has none); the simulator uses it to
    /// make traces with an effect outside the contract's vocabulary.
    pub torsion: f64,
}

/// The acceleration and its partial derivatives at one state.
#[derive(Debug, Clone, Copy, Default)]
pub struct Accel {
    pub a: f64,
    pub a_q: f64,
    pub a_v: f64,
    /// ∂f/∂a of the implicit residual f = M·a − G + T(N(a)); a_p = −f_p / f_a.
    pub f_a: f64,
    /// The friction's normal force at this state.
    pub normal: f64,
}

/// The equation has no unique acceleration (friction lever too large for the rig).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(
    "no unique acceleration: dry friction torque grows faster with α̈ than inertia (R·μ·m·d ≥ J); μ = {dry} is unphysical for this rig"
)]
pub struct Indeterminate {
    pub dry: f64,
}

impl Dof {
    /// Generalised inertia M: J (kg·m²) or m (kg).
    pub fn inertia(&self) -> f64 {
        match self.mech {
            Mechanism::Pendulum(r) => r.inertia_kgm2,
            Mechanism::Slider(r) => r.moving_mass_kg,
        }
    }

    /// This degree of freedom with its inertia × `scale` (the `inertia_error` effect, issue 17:
    /// a body parameter off its stated value). A pendulum: its inertia about the pin (a stated J
    /// off by a few per cent sets the swing's period wrong); its mass and centre-of-mass
    /// distance, hence gravity and the reaction's static part, are unchanged. A slider: its
    /// moving mass, which in this model is inertia only (the spring force is measured from the
    /// loaded rest position and the normal force is stated, so the weight enters neither).
    pub fn with_inertia_scale(&self, scale: f64) -> Dof {
        let mut d = self.clone();
        match &mut d.mech {
            Mechanism::Pendulum(r) => r.inertia_kgm2 *= scale,
            Mechanism::Slider(r) => r.moving_mass_kg *= scale,
        }
        d
    }

    /// This degree of freedom with its measured input read `offset` too low: the force (or
    /// torque) acting is the recorded one + `offset` (issue 17, point 3: a force sensor's zero
    /// is not the force's). Without an input it is returned as it is.
    pub fn with_input_offset(&self, offset: f64) -> Dof {
        let mut d = self.clone();
        if let Some(i) = &mut d.input {
            for v in &mut i.value {
                *v += offset;
            }
        }
        d
    }

    /// The lever of the dry friction: R (m) for a revolute joint, 1 for a slider.
    pub fn lever(&self) -> f64 {
        match self.mech {
            Mechanism::Pendulum(r) => r.pin_radius_m,
            Mechanism::Slider(_) => 1.0,
        }
    }

    /// Applied generalised force G(q, t) (gravity torque or spring + input), ∂G/∂q and ∂G/∂t.
    #[inline]
    pub fn load(&self, q: f64, t: f64) -> (f64, f64, f64) {
        let (f, df) = self.input.as_ref().map_or((0.0, 0.0), |i| i.at(t));
        match self.mech {
            Mechanism::Pendulum(r) => {
                let mgd = r.mass_kg * r.gravity_m_s2 * r.com_distance_m;
                (
                    -mgd * q.sin() - self.torsion * q + f,
                    -mgd * q.cos() - self.torsion,
                    df,
                )
            }
            Mechanism::Slider(r) => (
                -(r.stiffness_n_per_m + self.torsion) * q + f,
                -(r.stiffness_n_per_m + self.torsion),
                df,
            ),
        }
    }

    /// Normal force N(q, v, a) of the dry friction and its partials (∂q, ∂v, ∂a).
    ///
    /// Pendulum: the pin reaction |m·a_cm − m·g| with the centre of mass at distance d:
    /// tangential m·d·α̈ + m·g·sin α, centripetal m·d·ω² + m·g·cos α.
    #[inline]
    pub fn normal(&self, q: f64, v: f64, a: f64) -> (f64, f64, f64, f64) {
        match self.mech {
            Mechanism::Pendulum(r) => {
                let (m, g, d) = (r.mass_kg, r.gravity_m_s2, r.com_distance_m);
                let (sq, cq) = q.sin_cos();
                let x = m * d * a + m * g * sq;
                let y = m * d * v * v + m * g * cq;
                let n = (x * x + y * y).sqrt();
                if n == 0.0 {
                    return (0.0, 0.0, 0.0, 0.0);
                }
                (
                    n,
                    (x * m * g * cq - y * m * g * sq) / n,
                    y * 2.0 * m * d * v / n,
                    x * m * d / n,
                )
            }
            Mechanism::Slider(r) => (r.normal_force_n, 0.0, 0.0, 0.0),
        }
    }

    /// The normal force at rest (a = 0, v = 0): m·g for a pendulum, Fn for a slider.
    pub fn normal_at_rest(&self, q: f64) -> f64 {
        self.normal(q, 0.0, 0.0).0
    }

    /// Acceleration in motion direction `s` (±1): solves M·a − G(q,t) + T(v, s, N(q,v,a)) = 0
    /// by Newton's method (the dependence on a is weak and monotone), then the partials by the
    /// implicit function theorem.
    ///
    /// Always inlined: a sensitivity right-hand side calls it once, and out of line its result
    /// went through memory (an input-driven record's fit did 6 % more work; session 23).
    #[inline(always)]
    pub fn accel(
        &self,
        law: &FrictionLaw,
        q: f64,
        v: f64,
        s: f64,
        t: f64,
    ) -> Result<Accel, Indeterminate> {
        let m_gen = self.inertia();
        let lever = self.lever();
        match self.mech {
            Mechanism::Slider(r) => {
                let (g, g_q, _) = self.load(q, t);
                // Fn is constant: the equation is linear in a.
                let fr = law.eval(q, v, s, r.normal_force_n, lever);
                let a = (g - fr.value) / m_gen;
                Ok(Accel {
                    a,
                    a_q: (g_q - fr.d_q) / m_gen,
                    a_v: -fr.d_v / m_gen,
                    f_a: m_gen,
                    normal: r.normal_force_n,
                })
            }
            Mechanism::Pendulum(r) => {
                // The friction is affine in N: T = T0 + k·N, k = ∂T/∂N (lever·μ·φ(v)·s). With
                // N(a) = |(m·d·a + p, y)|, p = m·g·sin q, y = m·d·v² + m·g·cos q, the equation
                // J·a + c = −k·N(a), c = T0 − G, squares to a quadratic in a whose root with
                // sign(J·a + c) = −sign(k) is
                //   a = (−(J·c − k²·md·p) − k·S) / (J² − k²·md²),
                //   S = √((J·p − md·c)² + y²·(J² − k²·md²)),
                // exact and free of cancellation (k → 0 gives a = −c/J). J² > k²·md² is the
                // condition for a unique acceleration.
                let (m, gr, d) = (r.mass_kg, r.gravity_m_s2, r.com_distance_m);
                let (sq, cq) = q.sin_cos();
                // `load`'s G and ∂G/∂q from the same sine and cosine (one sincos per state,
                // not two: session 21).
                let (f, _) = self.input.as_ref().map_or((0.0, 0.0), |i| i.at(t));
                let mgd = r.mass_kg * r.gravity_m_s2 * r.com_distance_m;
                let g = -mgd * sq - self.torsion * q + f;
                let g_q = -mgd * cq - self.torsion;
                let (md, mg) = (m * d, m * gr);
                let (p, y) = (mg * sq, md * v * v + mg * cq);
                let fr0 = law.eval(q, v, s, 0.0, lever);
                let k = fr0.d_normal;
                let c = fr0.value - g;
                let den = m_gen * m_gen - k * k * md * md;
                if den <= 1e-12 * m_gen * m_gen {
                    return Err(Indeterminate { dry: law.dry });
                }
                let sroot = ((m_gen * p - md * c).powi(2) + y * y * den).sqrt();
                let a = (-(m_gen * c - k * k * md * p) - k * sroot) / den;
                let x = md * a + p;
                let n = (x * x + y * y).sqrt();
                let fr = law.eval(q, v, s, n, lever);
                let (n_q, n_v, n_a) = if n > 0.0 {
                    (
                        (x * mg * cq - y * mg * sq) / n,
                        y * 2.0 * md * v / n,
                        x * md / n,
                    )
                } else {
                    (0.0, 0.0, 0.0)
                };
                let f_a = m_gen + fr.d_normal * n_a;
                if f_a <= 1e-6 * m_gen {
                    return Err(Indeterminate { dry: law.dry });
                }
                let f_q = -g_q + fr.d_q + fr.d_normal * n_q;
                let f_v = fr.d_v + fr.d_normal * n_v;
                Ok(Accel {
                    a,
                    a_q: -f_q / f_a,
                    a_v: -f_v / f_a,
                    f_a,
                    normal: n,
                })
            }
        }
    }

    /// ∂a/∂p for a friction parameter at a solved state.
    #[inline]
    pub fn accel_d_param(
        &self,
        law: &FrictionLaw,
        acc: &Accel,
        p: DynParam,
        q: f64,
        v: f64,
        s: f64,
    ) -> f64 {
        -law.d_param(p, q, v, s, acc.normal, self.lever()) / acc.f_a
    }

    /// [`Dof::accel_d_param`] with the friction's factors at (q, v) given
    /// ([`FrictionLaw::shapes`]): one evaluation of them for every parameter of a state.
    #[inline]
    #[allow(clippy::too_many_arguments)]
    pub fn accel_d_param_at(
        &self,
        law: &FrictionLaw,
        shapes: &Shapes,
        acc: &Accel,
        p: DynParam,
        q: f64,
        v: f64,
        s: f64,
    ) -> f64 {
        -law.d_param_at(shapes, p, q, v, s, acc.normal, self.lever()) / acc.f_a
    }

    /// The static friction capacity at rest at q: lever · N_rest · μs.
    pub fn static_capacity(&self, law: &FrictionLaw, q: f64) -> f64 {
        self.lever() * self.normal_at_rest(q) * law.static_mu(q)
    }

    /// The static capacity against a load pushing in direction `s` (±1): direction-dependent
    /// friction (`FrictionLaw::asymmetry` δ) holds μs·(1 + δ·s), the same factor as it slides
    /// with (a kinetic friction above the static one would stick at once).
    pub fn static_capacity_toward(&self, law: &FrictionLaw, q: f64, s: f64) -> f64 {
        self.static_capacity(law, q) * (1.0 + law.asymmetry * s)
    }

    /// A time scale of the motion for step-size limits: the small-amplitude period, or
    /// `fallback` when there is no restoring force.
    pub fn period_s(&self, fallback: f64) -> f64 {
        let p = match self.mech {
            Mechanism::Pendulum(r) => r.small_angle_period_s(),
            Mechanism::Slider(r) => r.period_s(),
        };
        if p.is_finite() && p > 0.0 {
            p
        } else {
            fallback
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn j5() -> Dof {
        Dof {
            mech: Mechanism::Pendulum(PendulumRig {
                mass_kg: 7.415,
                inertia_kgm2: 4.645,
                com_distance_m: 0.6685,
                pin_radius_m: 0.01,
                gravity_m_s2: 9.81,
            }),
            input: None,
            torsion: 0.0,
        }
    }

    #[test]
    fn implicit_acceleration_satisfies_the_equation_with_the_reaction_at_that_acceleration() {
        let d = j5();
        let law = FrictionLaw::base(0.401, 0.88);
        let (q, v) = (1.2, -0.7);
        let acc = d.accel(&law, q, v, -1.0, 0.0).unwrap();
        let (n, ..) = d.normal(q, v, acc.a);
        let r = 4.645 * acc.a + 7.415 * 9.81 * 0.6685 * q.sin() + 0.401 * v + -(n * 0.01 * 0.88);
        assert!(r.abs() < 1e-12, "residual {r}");
        // The reaction is not m·g: it includes the inertial load.
        assert!((n - 7.415 * 9.81).abs() > 1.0);
    }

    /// Issue 38: the input's interval found in O(1) is the one the search over the record finds,
    /// on an even logger grid (times from i/fs, with their rounding), an uneven one, repeated
    /// times and outside the record.
    #[test]
    fn input_lookup_is_the_search_s_answer() {
        let even: Vec<f64> = (0..=5000).map(|i| i as f64 / 1000.0).collect();
        let mut rng = crate::numerics::noise::Noise::new(38);
        let mut uneven = vec![0.0];
        for _ in 0..2000 {
            let last = *uneven.last().unwrap();
            uneven.push(last + 1e-4 + 0.01 * rng.uniform().powi(3));
        }
        let repeated = vec![0.0, 0.5, 0.5, 0.5, 1.0, 2.0, 2.0, 3.0];
        for ts in [even, uneven, repeated] {
            let input = Input {
                value: ts.iter().map(|t| (3.0 * t).sin()).collect(),
                t_s: ts.clone(),
            };
            let (a, b) = (ts[0], ts[ts.len() - 1]);
            let mut probes: Vec<f64> = ts.clone();
            probes.extend(ts.iter().map(|t| t + 1e-12));
            probes.extend(ts.iter().map(|t| t - 1e-12));
            probes.extend((0..3000).map(|_| a - 0.1 + (b - a + 0.2) * rng.uniform()));
            for t in probes {
                let k = ts.partition_point(|&x| x <= t);
                assert_eq!(input.next_knot(t), ts.get(k).copied(), "next knot at {t}");
                if t > a && t < b {
                    let i = k - 1;
                    let slope = (input.value[i + 1] - input.value[i]) / (ts[i + 1] - ts[i]);
                    let expect = (input.value[i] + slope * (t - ts[i]), slope);
                    assert_eq!(input.at(t), expect, "value at {t}");
                }
            }
        }
    }

    #[test]
    fn partials_match_finite_differences() {
        let d = j5();
        let law = FrictionLaw::base(0.401, 0.88);
        let (q, v, s) = (0.9, 1.3, 1.0);
        let acc = d.accel(&law, q, v, s, 0.0).unwrap();
        let h = 1e-7;
        let aq = (d.accel(&law, q + h, v, s, 0.0).unwrap().a
            - d.accel(&law, q - h, v, s, 0.0).unwrap().a)
            / (2.0 * h);
        let av = (d.accel(&law, q, v + h, s, 0.0).unwrap().a
            - d.accel(&law, q, v - h, s, 0.0).unwrap().a)
            / (2.0 * h);
        assert!((aq - acc.a_q).abs() < 1e-6, "{aq} vs {}", acc.a_q);
        assert!((av - acc.a_v).abs() < 1e-6, "{av} vs {}", acc.a_v);
        for p in [DynParam::Viscous, DynParam::Dry] {
            let (mut lp, mut lm) = (law, law);
            lp.set(p, law.get(p) + h);
            lm.set(p, law.get(p) - h);
            let fd = (d.accel(&lp, q, v, s, 0.0).unwrap().a
                - d.accel(&lm, q, v, s, 0.0).unwrap().a)
                / (2.0 * h);
            let an = d.accel_d_param(&law, &acc, p, q, v, s);
            assert!((fd - an).abs() < 1e-6, "{p:?}: {fd} vs {an}");
        }
    }
}

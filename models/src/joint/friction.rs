//! Joint friction laws, exactly as the paper states them, with their parameter derivatives.
//!
//! Base law (paper, Section 4.2): revolute `T = D·ω + N·R·μ·sign(ω)`, slider `F = D·v + Fn·μ·sign(v)`.
//! Optional effects the base model lacks (`stribeck`, `quadratic_drag`, `position_friction`)
//! extend it in place, each with few parameters and their derivatives.

/// A parameter of the joint's dynamics that identification can estimate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DynParam {
    /// D: N·m·s/rad (revolute) or N·s/m (slider).
    Viscous,
    /// μ, dimensionless.
    Dry,
    /// Stribeck: static over Coulomb coefficient μs/μ, dimensionless (> 1 for a Stribeck hump).
    StribeckRatio,
    /// Stribeck: characteristic speed vs, rad/s (revolute) or m/s (slider).
    StribeckSpeed,
    /// Quadratic drag coefficient C: N·m·s²/rad² (revolute) or N·s²/m² (slider).
    QuadraticDrag,
    /// Position friction: c_k, the factor on μ at knot k minus 1 ([`PositionFriction`]) (1).
    Position(u8),
    /// Direction-dependent dry friction: δ in μ± = μ·(1 ± δ) (1; |δ| < 1).
    DryAsymmetry,
}

/// Stribeck friction: μ(v) = μ · (1 + (r − 1)·exp(−(v/vs)²)); static capacity uses μ·r.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stribeck {
    pub ratio: f64,
    pub speed: f64,
}

/// Knots of [`PositionFriction`]'s grid.
pub const POSITION_KNOTS: usize = 9;

/// Position-dependent dry friction (an out-of-round pin, a worn or dirty patch on a pin or
/// slide), the vocabulary's `position_friction`: μ(q) = μ·ψ(q) with ψ piecewise linear on
/// [`POSITION_KNOTS`] evenly spaced knots q_k = lo + k·step, ψ(q_k) = 1 + c_k, constant beyond
/// the end knots. It takes any shape along the travel a band or a cosine has at the grid's
/// resolution, and it depends on position only, never on speed (that is Stribeck friction).
/// One knot, the anchor (nearest the rest position q = 0), keeps c = 0 in a fit: μ is the
/// friction there, and the other c_k are not collinear with μ. Assumed: the factor is floored
/// at 0 (friction never drives).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PositionFriction {
    /// First knot: rad or m.
    pub lo: f64,
    /// Knot spacing: rad or m (> 0).
    pub step: f64,
    pub coeffs: [f64; POSITION_KNOTS],
}

impl PositionFriction {
    /// A flat grid (every c_k = 0) spanning `lo..=hi`.
    pub fn flat(lo: f64, hi: f64) -> Self {
        let span = (hi - lo).max(1e-9);
        Self {
            lo,
            step: span / (POSITION_KNOTS - 1) as f64,
            coeffs: [0.0; POSITION_KNOTS],
        }
    }

    /// The knot nearest q = 0, whose coefficient a fit holds at 0.
    pub fn anchor(&self) -> usize {
        ((-self.lo / self.step).round().max(0.0) as usize).min(POSITION_KNOTS - 1)
    }

    pub fn knot(&self, k: usize) -> f64 {
        self.lo + k as f64 * self.step
    }

    /// The hat weights at q: (k, w_k, w_{k+1}) with ψ − 1 = w_k·c_k + w_{k+1}·c_{k+1}, and
    /// ∂w_{k+1}/∂q (0 beyond the ends).
    #[inline]
    fn weights(&self, q: f64) -> (usize, f64, f64, f64) {
        let x = (q - self.lo) / self.step;
        if x <= 0.0 {
            (0, 1.0, 0.0, 0.0)
        } else if x >= (POSITION_KNOTS - 1) as f64 {
            (POSITION_KNOTS - 2, 0.0, 1.0, 0.0)
        } else {
            let k = (x.floor() as usize).min(POSITION_KNOTS - 2);
            let f = x - k as f64;
            (k, 1.0 - f, f, 1.0 / self.step)
        }
    }

    /// The knots whose coefficients shape ψ at q, with their weights (summing to 1).
    pub fn hat_weights(&self, q: f64) -> [(usize, f64); 2] {
        let (k, a, b, _) = self.weights(q);
        [(k, a), (k + 1, b)]
    }

    /// ψ(q) − 1 before the floor, and its derivative.
    #[inline]
    fn excess(&self, q: f64) -> (f64, f64) {
        let (k, a, b, db) = self.weights(q);
        let (c0, c1) = (self.coeffs[k], self.coeffs[k + 1]);
        (a * c0 + b * c1, db * (c1 - c0))
    }

    /// ∂ψ/∂c_j at q (before the floor).
    #[inline]
    fn d_coeff(&self, j: usize, q: f64) -> f64 {
        let (k, a, b, _) = self.weights(q);
        if j == k {
            a
        } else if j == k + 1 {
            b
        } else {
            0.0
        }
    }
}

/// A shape of μ along the joint's travel that the simulator makes but the fit does not carry:
/// the residual loop's test cases for position-dependent friction (issue 17, point 6), which the
/// vocabulary's [`PositionFriction`] must name from a shape it was not written as. μ is
/// multiplied by the shape's factor (floored at 0, as [`PositionFriction`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PositionProfile {
    /// Friction growing away from the rest position (a worn pin end):
    /// factor 1 + a·u + b·u², u = q/scale (scale: rad or m).
    Polynomial {
        linear: f64,
        quadratic: f64,
        scale: f64,
    },
    /// A band of higher (gain > 0) or lower friction between `from` and `to` (rad or m), with
    /// logistic edges of width `edge` (a worn or dirty patch on the pin or slide):
    /// factor 1 + gain·σ((q − from)/edge)·σ((to − q)/edge).
    Band {
        gain: f64,
        from: f64,
        to: f64,
        edge: f64,
    },
    /// A periodic modulation (an out-of-round pin): factor 1 + amplitude·cos(2π·q/period + phase).
    Cosine {
        amplitude: f64,
        period: f64,
        phase: f64,
    },
}

impl PositionProfile {
    /// The factor on μ at q and its derivative ∂/∂q.
    fn factor(&self, q: f64) -> (f64, f64) {
        match *self {
            PositionProfile::Polynomial {
                linear,
                quadratic,
                scale,
            } => {
                let u = q / scale;
                (
                    1.0 + linear * u + quadratic * u * u,
                    (linear + 2.0 * quadratic * u) / scale,
                )
            }
            PositionProfile::Band {
                gain,
                from,
                to,
                edge,
            } => {
                let sig = |x: f64| 1.0 / (1.0 + (-x).exp());
                let (a, b) = (sig((q - from) / edge), sig((to - q) / edge));
                (
                    1.0 + gain * a * b,
                    gain * (a * (1.0 - a) * b - a * b * (1.0 - b)) / edge,
                )
            }
            PositionProfile::Cosine {
                amplitude,
                period,
                phase,
            } => {
                let w = std::f64::consts::TAU / period;
                (
                    1.0 + amplitude * (w * q + phase).cos(),
                    -amplitude * w * (w * q + phase).sin(),
                )
            }
        }
    }
}

/// A joint's friction law: the paper's viscous + dry, plus optional effects.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrictionLaw {
    pub viscous: f64,
    pub dry: f64,
    pub stribeck: Option<Stribeck>,
    /// Extra torque C·v·|v| (aerodynamic or fluid drag).
    pub quadratic_drag: Option<f64>,
    pub position: Option<PositionFriction>,
    /// A simulated shape of μ along the travel, never fitted ([`PositionProfile`]).
    pub profile: Option<PositionProfile>,
    /// Direction-dependent sliding friction (the vocabulary's `asymmetric_friction`, issue 17):
    /// μ₊ = μ·(1 + δ) moving in the positive direction, μ₋ = μ·(1 − δ) in the negative one, 0
    /// for none. Assumed: while sliding only — the static capacity stays μs in both directions
    /// (a break-away threshold that differs by direction is not modelled).
    pub asymmetry: f64,
}

/// The dry friction's speed factor φ(v) and position factor ψ(q) at one state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shapes {
    pub phi: f64,
    pub psi: f64,
}

/// Friction torque (or force) and its partial derivatives.
#[derive(Debug, Clone, Copy, Default)]
pub struct FrictionEval {
    pub value: f64,
    pub d_q: f64,
    pub d_v: f64,
    /// ∂/∂N: the dry part's dependence on the normal force (the law is affine in N).
    pub d_normal: f64,
}

impl FrictionLaw {
    /// The paper's two-parameter law.
    pub fn base(viscous: f64, dry: f64) -> Self {
        Self {
            viscous,
            dry,
            stribeck: None,
            quadratic_drag: None,
            position: None,
            profile: None,
            asymmetry: 0.0,
        }
    }

    pub fn get(&self, p: DynParam) -> f64 {
        match p {
            DynParam::Viscous => self.viscous,
            DynParam::Dry => self.dry,
            DynParam::DryAsymmetry => self.asymmetry,
            DynParam::StribeckRatio => self.stribeck.map_or(1.0, |s| s.ratio),
            DynParam::StribeckSpeed => self.stribeck.map_or(1.0, |s| s.speed),
            DynParam::QuadraticDrag => self.quadratic_drag.unwrap_or(0.0),
            DynParam::Position(k) => self.position.map_or(0.0, |p| p.coeffs[k as usize]),
        }
    }

    pub fn set(&mut self, p: DynParam, x: f64) {
        let pos = PositionFriction::flat(-1.0, 1.0);
        match p {
            DynParam::Viscous => self.viscous = x,
            DynParam::Dry => self.dry = x,
            DynParam::DryAsymmetry => self.asymmetry = x,
            DynParam::StribeckRatio => {
                self.stribeck
                    .get_or_insert(Stribeck {
                        ratio: 1.0,
                        speed: 1.0,
                    })
                    .ratio = x
            }
            DynParam::StribeckSpeed => {
                self.stribeck
                    .get_or_insert(Stribeck {
                        ratio: 1.0,
                        speed: 1.0,
                    })
                    .speed = x
            }
            DynParam::QuadraticDrag => self.quadratic_drag = Some(x),
            DynParam::Position(k) => self.position.get_or_insert(pos).coeffs[k as usize] = x,
        }
    }

    /// Speed factor φ(v) on μ and ∂φ/∂v.
    #[inline]
    fn dry_shape(&self, v: f64) -> (f64, f64) {
        match self.stribeck {
            None => (1.0, 0.0),
            Some(Stribeck { ratio, speed }) => {
                let x = v / speed;
                let e = (-x * x).exp();
                (
                    1.0 + (ratio - 1.0) * e,
                    (ratio - 1.0) * e * (-2.0 * x / speed),
                )
            }
        }
    }

    /// Position factor ψ(q) = max(0, 1 + a·u + b·u²) (times a simulated profile's factor) and
    /// ∂ψ/∂q.
    #[inline(always)]
    fn position_shape(&self, q: f64) -> (f64, f64) {
        // Neither effect: (1, 0), what the general path returns, without its call (three a
        // right-hand side of a single joint's sensitivities; issue 38, session 23).
        if self.position.is_none() && self.profile.is_none() {
            return (1.0, 0.0);
        }
        self.shaped_position(q)
    }

    /// [`FrictionLaw::position_shape`] with a fitted or a simulated position effect.
    #[inline(never)]
    fn shaped_position(&self, q: f64) -> (f64, f64) {
        let (psi, dpsi) = self.fitted_position_shape(q);
        match self.profile {
            None => (psi, dpsi),
            Some(p) => {
                let (f, df) = p.factor(q);
                if psi * f <= 0.0 {
                    (0.0, 0.0)
                } else {
                    (psi * f, dpsi * f + psi * df)
                }
            }
        }
    }

    /// The simulated profile's factor at q (1 without one).
    #[inline]
    fn profile_factor(&self, q: f64) -> f64 {
        self.profile.map_or(1.0, |p| p.factor(q).0)
    }

    #[inline]
    fn fitted_position_shape(&self, q: f64) -> (f64, f64) {
        match self.position {
            None => (1.0, 0.0),
            Some(pf) => {
                let (e, de) = pf.excess(q);
                if 1.0 + e <= 0.0 {
                    (0.0, 0.0)
                } else {
                    (1.0 + e, de)
                }
            }
        }
    }

    /// Static friction capacity coefficient μs at position q (the limit a body at rest can be
    /// held by, per unit of lever·N).
    pub fn static_mu(&self, q: f64) -> f64 {
        self.dry * self.dry_shape(0.0).0 * self.position_shape(q).0
    }

    /// Friction opposing motion in direction `s` (±1) at position q and rate v, with normal
    /// force `normal` acting at lever `lever` (R for a revolute joint, 1 for a slider).
    ///
    /// `s` is the direction of the current motion segment, not `sign(v)` recomputed: inside a
    /// segment the simulator keeps it fixed, so the law is smooth there (exact sign friction).
    #[inline]
    pub fn eval(&self, q: f64, v: f64, s: f64, normal: f64, lever: f64) -> FrictionEval {
        let (phi, dphi_dv) = self.dry_shape(v);
        let (psi, dpsi_dq) = self.position_shape(q);
        // μ·(1 + δ·s)·s = μ·(s + δ) for s = ±1.
        let dry_k = lever * self.dry * (s + self.asymmetry);
        let mut e = FrictionEval {
            value: self.viscous * v + dry_k * normal * phi * psi,
            d_q: dry_k * normal * phi * dpsi_dq,
            d_v: self.viscous + dry_k * normal * dphi_dv * psi,
            d_normal: dry_k * phi * psi,
        };
        if let Some(c) = self.quadratic_drag {
            e.value += c * v * v.abs();
            e.d_v += 2.0 * c * v.abs();
        }
        e
    }

    /// ∂(friction)/∂p for the parameter `p`, same arguments as [`FrictionLaw::eval`].
    #[inline]
    pub fn d_param(&self, p: DynParam, q: f64, v: f64, s: f64, normal: f64, lever: f64) -> f64 {
        self.d_param_at(&self.shapes(q, v), p, q, v, s, normal, lever)
    }

    /// The speed and position factors φ(v), ψ(q) at a state, for [`FrictionLaw::d_param_at`]:
    /// computed once for all the parameters of a sensitivity right-hand side (issue 38).
    #[inline]
    pub fn shapes(&self, q: f64, v: f64) -> Shapes {
        Shapes {
            phi: self.dry_shape(v).0,
            psi: self.position_shape(q).0,
        }
    }

    /// [`FrictionLaw::d_param`] with the factors at (q, v) given ([`FrictionLaw::shapes`]).
    #[inline]
    #[allow(clippy::too_many_arguments)]
    pub fn d_param_at(
        &self,
        shapes: &Shapes,
        p: DynParam,
        q: f64,
        v: f64,
        s: f64,
        normal: f64,
        lever: f64,
    ) -> f64 {
        let Shapes { phi, psi } = *shapes;
        let base = lever * (s + self.asymmetry) * normal;
        match p {
            DynParam::Viscous => v,
            DynParam::Dry => base * phi * psi,
            DynParam::DryAsymmetry => lever * normal * self.dry * phi * psi,
            DynParam::StribeckRatio => match self.stribeck {
                Some(st) => base * self.dry * psi * (-(v / st.speed).powi(2)).exp(),
                None => 0.0,
            },
            DynParam::StribeckSpeed => match self.stribeck {
                Some(st) => {
                    let x = v / st.speed;
                    base * self.dry
                        * psi
                        * (st.ratio - 1.0)
                        * (-x * x).exp()
                        * (2.0 * x * x / st.speed)
                }
                None => 0.0,
            },
            DynParam::QuadraticDrag => v * v.abs(),
            DynParam::Position(k) => match self.position {
                Some(pf) if psi > 0.0 => {
                    base * self.dry * phi * self.profile_factor(q) * pf.d_coeff(k as usize, q)
                }
                _ => 0.0,
            },
        }
    }

    /// ∂μs/∂p at position q: how the static capacity moves with a parameter (break-away
    /// sensitivities).
    pub fn d_static_mu(&self, p: DynParam, q: f64) -> f64 {
        let (phi0, _) = self.dry_shape(0.0);
        let (psi, _) = self.position_shape(q);
        match p {
            DynParam::Dry => phi0 * psi,
            DynParam::StribeckRatio if self.stribeck.is_some() => self.dry * psi,
            DynParam::Position(k) if psi > 0.0 => match self.position {
                Some(pf) => self.dry * phi0 * self.profile_factor(q) * pf.d_coeff(k as usize, q),
                None => 0.0,
            },
            _ => 0.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_law_values() {
        // J1, Table 4: D = 0.034, μ = 0.023, R = 0.05; ω = 0.5 rad/s, N = 200 N.
        let f = FrictionLaw::base(0.034, 0.023).eval(0.3, 0.5, 1.0, 200.0, 0.05);
        assert!((f.value - (0.034 * 0.5 + 200.0 * 0.05 * 0.023)).abs() < 1e-15);
        assert!((f.d_normal - 0.05 * 0.023).abs() < 1e-15);
        let back = FrictionLaw::base(0.034, 0.023).eval(0.3, -0.5, -1.0, 200.0, 0.05);
        assert!((back.value + f.value).abs() < 1e-15, "odd in the rate");
    }

    #[test]
    fn derivatives_match_finite_differences() {
        let mut law = FrictionLaw::base(0.3, 0.4);
        law.stribeck = Some(Stribeck {
            ratio: 2.0,
            speed: 0.3,
        });
        law.quadratic_drag = Some(0.02);
        law.asymmetry = 0.15;
        let mut pf = PositionFriction::flat(-0.55, 0.7);
        pf.coeffs = [0.1, -0.2, 0.3, 0.05, 0.0, 0.4, -0.1, 0.2, 0.1];
        law.position = Some(pf);
        let (q, v, s, n, r) = (0.4, 0.21, 1.0, 75.0, 0.01);
        for p in [
            DynParam::Viscous,
            DynParam::Dry,
            DynParam::StribeckRatio,
            DynParam::StribeckSpeed,
            DynParam::QuadraticDrag,
            DynParam::DryAsymmetry,
            DynParam::Position(2),
            DynParam::Position(6),
            DynParam::Position(7),
        ] {
            let h = 1e-6 * law.get(p).abs().max(1e-3);
            let (mut a, mut b) = (law, law);
            a.set(p, law.get(p) + h);
            b.set(p, law.get(p) - h);
            let fd = (a.eval(q, v, s, n, r).value - b.eval(q, v, s, n, r).value) / (2.0 * h);
            let an = law.d_param(p, q, v, s, n, r);
            assert!(
                (fd - an).abs() < 1e-6 * an.abs().max(1e-6),
                "{p:?}: fd {fd} vs {an}"
            );
            let fd_s = (a.static_mu(q) - b.static_mu(q)) / (2.0 * h);
            assert!((fd_s - law.d_static_mu(p, q)).abs() < 1e-6, "{p:?} static");
        }
        for profile in [
            None,
            Some(PositionProfile::Band {
                gain: 0.8,
                from: 0.3,
                to: 0.6,
                edge: 0.05,
            }),
            Some(PositionProfile::Cosine {
                amplitude: 0.3,
                period: 1.2,
                phase: 0.4,
            }),
        ] {
            let law = FrictionLaw { profile, ..law };
            let h = 1e-7;
            let e = law.eval(q, v, s, n, r);
            let fd_q =
                (law.eval(q + h, v, s, n, r).value - law.eval(q - h, v, s, n, r).value) / (2.0 * h);
            assert!(
                (fd_q - e.d_q).abs() < 1e-6,
                "{profile:?}: {fd_q} vs {}",
                e.d_q
            );
            let p = DynParam::Position(7);
            let (mut a, mut b) = (law, law);
            a.set(p, law.get(p) + 1e-6);
            b.set(p, law.get(p) - 1e-6);
            let fd = (a.eval(q, v, s, n, r).value - b.eval(q, v, s, n, r).value) / 2e-6;
            assert!(
                (fd - law.d_param(p, q, v, s, n, r)).abs() < 1e-6,
                "{profile:?}"
            );
        }
        let h = 1e-7;
        let e = law.eval(q, v, s, n, r);
        let fd_v =
            (law.eval(q, v + h, s, n, r).value - law.eval(q, v - h, s, n, r).value) / (2.0 * h);
        let fd_q =
            (law.eval(q + h, v, s, n, r).value - law.eval(q - h, v, s, n, r).value) / (2.0 * h);
        assert!((fd_v - e.d_v).abs() < 1e-6 && (fd_q - e.d_q).abs() < 1e-6);
    }
}

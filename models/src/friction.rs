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
    /// Position friction, linear term a of μ(q) = μ·(1 + a·u + b·u²), u = q/q_ref (1).
    PositionLinear,
    /// Position friction, quadratic term b (1).
    PositionQuadratic,
}

/// Stribeck friction: μ(v) = μ · (1 + (r − 1)·exp(−(v/vs)²)); static capacity uses μ·r.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stribeck {
    pub ratio: f64,
    pub speed: f64,
}

/// Position-dependent dry friction (an out-of-round pin, a worn patch on a slide):
/// μ(q) = μ·(1 + a·u + b·u²), u = q/q_ref with q_ref = 1 rad (revolute) or 10 mm (slider).
/// Assumed small: the factor is floored at 0 (friction never drives).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PositionFriction {
    pub linear: f64,
    pub quadratic: f64,
    /// q_ref: rad or m.
    pub scale: f64,
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
        }
    }

    pub fn get(&self, p: DynParam) -> f64 {
        match p {
            DynParam::Viscous => self.viscous,
            DynParam::Dry => self.dry,
            DynParam::StribeckRatio => self.stribeck.map_or(1.0, |s| s.ratio),
            DynParam::StribeckSpeed => self.stribeck.map_or(1.0, |s| s.speed),
            DynParam::QuadraticDrag => self.quadratic_drag.unwrap_or(0.0),
            DynParam::PositionLinear => self.position.map_or(0.0, |p| p.linear),
            DynParam::PositionQuadratic => self.position.map_or(0.0, |p| p.quadratic),
        }
    }

    pub fn set(&mut self, p: DynParam, x: f64) {
        let pos = PositionFriction {
            linear: 0.0,
            quadratic: 0.0,
            scale: 1.0,
        };
        match p {
            DynParam::Viscous => self.viscous = x,
            DynParam::Dry => self.dry = x,
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
            DynParam::PositionLinear => self.position.get_or_insert(pos).linear = x,
            DynParam::PositionQuadratic => self.position.get_or_insert(pos).quadratic = x,
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

    /// Position factor ψ(q) = max(0, 1 + a·u + b·u²) and ∂ψ/∂q.
    #[inline]
    fn position_shape(&self, q: f64) -> (f64, f64) {
        match self.position {
            None => (1.0, 0.0),
            Some(PositionFriction {
                linear,
                quadratic,
                scale,
            }) => {
                let u = q / scale;
                let psi = 1.0 + linear * u + quadratic * u * u;
                if psi <= 0.0 {
                    (0.0, 0.0)
                } else {
                    (psi, (linear + 2.0 * quadratic * u) / scale)
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
        let dry_k = lever * self.dry * s;
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
        let (phi, _) = self.dry_shape(v);
        let (psi, _) = self.position_shape(q);
        let base = lever * s * normal;
        match p {
            DynParam::Viscous => v,
            DynParam::Dry => base * phi * psi,
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
            DynParam::PositionLinear | DynParam::PositionQuadratic => match self.position {
                Some(pf) if psi > 0.0 => {
                    let u = q / pf.scale;
                    base * self.dry
                        * phi
                        * if p == DynParam::PositionLinear {
                            u
                        } else {
                            u * u
                        }
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
            DynParam::PositionLinear | DynParam::PositionQuadratic if psi > 0.0 => {
                let u = q / self.position.map_or(1.0, |pf| pf.scale);
                self.dry
                    * phi0
                    * if p == DynParam::PositionLinear {
                        u
                    } else {
                        u * u
                    }
            }
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
        law.position = Some(PositionFriction {
            linear: 0.2,
            quadratic: -0.1,
            scale: 1.0,
        });
        let (q, v, s, n, r) = (0.4, 0.21, 1.0, 75.0, 0.01);
        for p in [
            DynParam::Viscous,
            DynParam::Dry,
            DynParam::StribeckRatio,
            DynParam::StribeckSpeed,
            DynParam::QuadraticDrag,
            DynParam::PositionLinear,
            DynParam::PositionQuadratic,
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
        let h = 1e-7;
        let e = law.eval(q, v, s, n, r);
        let fd_v =
            (law.eval(q, v + h, s, n, r).value - law.eval(q, v - h, s, n, r).value) / (2.0 * h);
        let fd_q =
            (law.eval(q + h, v, s, n, r).value - law.eval(q - h, v, s, n, r).value) / (2.0 * h);
        assert!((fd_v - e.d_v).abs() < 1e-6 && (fd_q - e.d_q).abs() < 1e-6);
    }
}

//! Joint friction laws, exactly as the paper states them, with their parameter derivatives.
//!
//! Base law (paper, Section 4.2): revolute `T = D·ω + N·R·μ·sign(ω)`, slider `F = D·v + Fn·μ·sign(v)`.
//! Optional effects the base model lacks (`stribeck`, `quadratic_drag`) extend it in place.

/// A parameter of the joint's dynamics that identification can estimate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DynParam {
    /// D: N·m·s/rad (revolute) or N·s/m (slider).
    Viscous,
    /// μ, dimensionless.
    Dry,
    /// Stribeck: static over Coulomb coefficient μs/μ, dimensionless (≥ 1 for a Stribeck hump).
    StribeckRatio,
    /// Stribeck: characteristic speed vs, rad/s (revolute) or m/s (slider).
    StribeckSpeed,
    /// Quadratic drag coefficient C: N·m·s²/rad² (revolute) or N·s²/m² (slider).
    QuadraticDrag,
}

/// Stribeck friction: μ(v) = μ · (1 + (r − 1)·exp(−(v/vs)²)); static capacity uses μ·r.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stribeck {
    pub ratio: f64,
    pub speed: f64,
}

/// A joint's friction law: the paper's viscous + dry, plus optional effects.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrictionLaw {
    pub viscous: f64,
    pub dry: f64,
    pub stribeck: Option<Stribeck>,
    /// Extra torque C·v·|v| (aerodynamic or fluid drag).
    pub quadratic_drag: Option<f64>,
}

/// Friction torque (or force) and its partial derivatives.
#[derive(Debug, Clone, Copy, Default)]
pub struct FrictionEval {
    pub value: f64,
    pub d_q: f64,
    pub d_v: f64,
    /// ∂/∂N: the dry part's dependence on the normal force.
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
        }
    }

    pub fn get(&self, p: DynParam) -> f64 {
        match p {
            DynParam::Viscous => self.viscous,
            DynParam::Dry => self.dry,
            DynParam::StribeckRatio => self.stribeck.map_or(1.0, |s| s.ratio),
            DynParam::StribeckSpeed => self.stribeck.map_or(1.0, |s| s.speed),
            DynParam::QuadraticDrag => self.quadratic_drag.unwrap_or(0.0),
        }
    }

    pub fn set(&mut self, p: DynParam, x: f64) {
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
        }
    }

    /// Dry-friction multiplier φ(v) on μ and ∂φ/∂v.
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

    /// Static friction capacity coefficient μs (the limit a body at rest can be held by, per
    /// unit of lever·N).
    pub fn static_mu(&self) -> f64 {
        self.dry * self.dry_shape(0.0).0
    }

    /// Friction opposing motion in direction `s` (±1) at rate `v`, with normal force `normal`
    /// acting at lever `lever` (R for a revolute joint, 1 for a slider).
    ///
    /// `s` is the direction of the current motion segment, not `sign(v)` recomputed: inside a
    /// segment the simulator keeps it fixed, so the law is smooth there (exact sign friction).
    #[inline]
    pub fn eval(&self, v: f64, s: f64, normal: f64, lever: f64) -> FrictionEval {
        let (phi, dphi_dv) = self.dry_shape(v);
        let dry_k = lever * self.dry * s;
        let mut e = FrictionEval {
            value: self.viscous * v + dry_k * normal * phi,
            d_q: 0.0,
            d_v: self.viscous + dry_k * normal * dphi_dv,
            d_normal: dry_k * phi,
        };
        if let Some(c) = self.quadratic_drag {
            e.value += c * v * v.abs();
            e.d_v += 2.0 * c * v.abs();
        }
        e
    }

    /// ∂(friction)/∂p for the parameter `p`, same arguments as [`FrictionLaw::eval`].
    #[inline]
    pub fn d_param(&self, p: DynParam, v: f64, s: f64, normal: f64, lever: f64) -> f64 {
        let (phi, _) = self.dry_shape(v);
        match p {
            DynParam::Viscous => v,
            DynParam::Dry => lever * s * normal * phi,
            DynParam::StribeckRatio => match self.stribeck {
                Some(st) => lever * self.dry * s * normal * (-(v / st.speed).powi(2)).exp(),
                None => 0.0,
            },
            DynParam::StribeckSpeed => match self.stribeck {
                Some(st) => {
                    let x = v / st.speed;
                    let e = (-x * x).exp();
                    lever * self.dry * s * normal * (st.ratio - 1.0) * e * (2.0 * x * x / st.speed)
                }
                None => 0.0,
            },
            DynParam::QuadraticDrag => v * v.abs(),
        }
    }

    /// ∂μs/∂p: how the static capacity moves with a parameter (for break-away sensitivities).
    pub fn d_static_mu(&self, p: DynParam) -> f64 {
        let (phi0, _) = self.dry_shape(0.0);
        match p {
            DynParam::Dry => phi0,
            DynParam::StribeckRatio if self.stribeck.is_some() => self.dry,
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
        let f = FrictionLaw::base(0.034, 0.023).eval(0.5, 1.0, 200.0, 0.05);
        assert!((f.value - (0.034 * 0.5 + 200.0 * 0.05 * 0.023)).abs() < 1e-15);
        assert!((f.d_normal - 0.05 * 0.023).abs() < 1e-15);
        let back = FrictionLaw::base(0.034, 0.023).eval(-0.5, -1.0, 200.0, 0.05);
        assert!((back.value + f.value).abs() < 1e-15, "odd in the rate");
    }

    #[test]
    fn parameter_derivatives_match_finite_differences() {
        let mut law = FrictionLaw::base(0.3, 0.4);
        law.stribeck = Some(Stribeck {
            ratio: 2.0,
            speed: 0.3,
        });
        law.quadratic_drag = Some(0.02);
        let (v, s, n, r) = (0.21, 1.0, 75.0, 0.01);
        for p in [
            DynParam::Viscous,
            DynParam::Dry,
            DynParam::StribeckRatio,
            DynParam::StribeckSpeed,
            DynParam::QuadraticDrag,
        ] {
            let h = 1e-6 * law.get(p).abs().max(1e-3);
            let (mut a, mut b) = (law, law);
            a.set(p, law.get(p) + h);
            b.set(p, law.get(p) - h);
            let fd = (a.eval(v, s, n, r).value - b.eval(v, s, n, r).value) / (2.0 * h);
            let an = law.d_param(p, v, s, n, r);
            assert!(
                (fd - an).abs() < 1e-6 * an.abs().max(1e-6),
                "{p:?}: fd {fd} vs {an}"
            );
        }
        let h = 1e-7;
        let fd = (law.eval(v + h, s, n, r).value - law.eval(v - h, s, n, r).value) / (2.0 * h);
        assert!((fd - law.eval(v, s, n, r).d_v).abs() < 1e-6);
    }
}

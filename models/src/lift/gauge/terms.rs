//! The gauge's terms besides the friction — its effects (`sensor_offset`, `spring_rate`) with
//! their priors and estimates — and the Jacobian's step: what the gauge fit ([`super::fit`]) and
//! a lift fit pooling gauge records ([`super::super::identify`], [`super::super::fit`]) share.
//! Below all three (issue 39, point 4: no circle between the gauge fit and the lift fit); it
//! imports only [`super::super::posterior`].

use super::super::posterior::EffectPrior;

/// Forward-difference step of a gauge record's Jacobian: 10⁻⁴ in ln μ (a joint's force change
/// is ~10⁻³ N, 10⁵ times the strip-force solver's tolerance) and in a spring-rate factor; a
/// pooled gauge record's (`lift::identify`) in units of Table 4.
pub const FD_STEP: f64 = 1e-4;

/// The prior of the gauge's zero b, N ([`GaugeEffect::prior`]); a pooled gauge record's too.
pub const SENSOR_OFFSET_PRIOR: EffectPrior = EffectPrior {
    mean: 0.0,
    sd: 10.0,
    lower: -50.0,
    upper: 50.0,
};

/// An effect a gauge fit can carry besides the friction (`effects`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GaugeEffect {
    /// The gauge's zero off by b, N: F_meas = F + b (both branches shifted alike).
    SensorOffset,
    /// The drive characteristic's slope × k about its first point (the mean curve tilted): a
    /// spring whose rate differs from the type's.
    SpringRate,
}

impl GaugeEffect {
    pub const ALL: [GaugeEffect; 2] = [GaugeEffect::SensorOffset, GaugeEffect::SpringRate];

    /// The contract's vocabulary name.
    pub fn name(self) -> &'static str {
        match self {
            GaugeEffect::SensorOffset => "sensor_offset",
            GaugeEffect::SpringRate => "spring_rate",
        }
    }

    /// The effect of a contract vocabulary name.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|e| e.name() == name)
    }

    /// The value of "no effect": b = 0 N, k = 1.
    pub fn null_value(self) -> f64 {
        match self {
            GaugeEffect::SensorOffset => 0.0,
            GaugeEffect::SpringRate => 1.0,
        }
    }

    /// The prior. `sensor_offset` b: N(0, (10 N)²) in [−50, 50] N — a gauge's zero is off by
    /// newtons after a bad tare; 50 N is half the static force, a mounting error, not a zero.
    /// `spring_rate` k: N(1, 0.5²) in [0.2, 5] — a spring of another rate class is tens of
    /// per cent off; beyond 5× it is another pantograph.
    pub fn prior(self) -> EffectPrior {
        match self {
            GaugeEffect::SensorOffset => SENSOR_OFFSET_PRIOR,
            GaugeEffect::SpringRate => EffectPrior {
                mean: 1.0,
                sd: 0.5,
                lower: 0.2,
                upper: 5.0,
            },
        }
    }
}

/// A fitted effect, its units (N or a factor).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GaugeEffectEstimate {
    pub effect: GaugeEffect,
    pub value: f64,
    pub posterior_sd: f64,
    /// value ± t·sd (the t quantile at the fit's degrees of freedom), cut at the prior's bounds.
    pub ci95: [f64; 2],
}

impl GaugeEffectEstimate {
    /// The interval leaves out the value of "no effect".
    pub fn excludes_null(&self) -> bool {
        let v = self.effect.null_value();
        self.ci95[0] > v || self.ci95[1] < v
    }
}

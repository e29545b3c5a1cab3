//! What a joint parameter's state rests on, and how much of it is left (issue 37, point 1): the
//! test that last informed the parameter gave a value and a 95 % interval *then*; the interval
//! *now* is that interval widened by the wear the time since may have brought.
//!
//! Model (stated; every assumption here):
//! - the last informing test's value is normal, sd = its 95 % half-width / 1.96 (an asymmetric
//!   interval is read by its mean half-width);
//! - since then the parameter has moved linearly at an unknown rate r ~ N(m, s²) per day, the
//!   same over the whole age (no random walk: a bearing wears steadily between tests). So
//!   after `age` days it is normal with mean v + m·age and sd √(sd_then² + (s·age)²);
//! - the rate comes from the joint's own trend ([`WearRate::from_trend`]) when it has one, else
//!   from the fleet ([`WearRate::fleet`]): mean 0, sd a share of the baseline per year (the
//!   type's data file, `[test_plan] fleet_wear_sd_per_year`; a fleet prior learned from the store
//!   plugs in here, issue 37 point 3);
//! - a parameter no test has informed is read from the prior the lift fit assumes for a joint
//!   it does not report: Table 4 baseline, relative sd `unmeasured_relative_sd` (0.5, the lift
//!   fit's `prior_relative_sd`);
//! - friction is ≥ 0: the interval's lower end is clamped at 0, the probability below a band
//!   is that of the normal (a small overstatement for wide intervals near 0).

use serde::{Deserialize, Serialize};

use crate::numerics::stats::Z95;

/// Where a wear rate came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum RateSource {
    /// The joint's own trend over its informing tests (`models::trend`).
    Trend,
    /// The fleet's spread of wear rates (the type's data file, or a learned fleet prior).
    Fleet,
}

/// A parameter's wear rate, per day, in the parameter's own unit: r ~ N(`mean_per_day`,
/// `sd_per_day`²).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct WearRate {
    pub mean_per_day: f64,
    pub sd_per_day: f64,
    pub source: RateSource,
}

impl WearRate {
    /// The fleet's rate: no drift expected, sd `sd_per_year` × `baseline` per year.
    pub fn fleet(baseline: f64, sd_per_year: f64) -> WearRate {
        WearRate {
            mean_per_day: 0.0,
            sd_per_day: (sd_per_year * baseline.abs() / 365.25).max(0.0),
            source: RateSource::Fleet,
        }
    }

    /// The joint's trend (slope per day and its 95 % interval), with the fleet's rate as the
    /// floor of its spread: mean = the slope when its interval excludes 0 (`significant`), else
    /// 0; sd = the larger of the slope's sd (half-width / 1.96) and the fleet's. A flat, tight
    /// trend over a year says little about a bearing that starts to wear next month.
    pub fn from_trend(
        slope: f64,
        slope_ci95: [f64; 2],
        significant: bool,
        fleet: WearRate,
    ) -> Self {
        let sd = ((slope_ci95[1] - slope_ci95[0]) / (2.0 * Z95)).abs();
        if !slope.is_finite() || !sd.is_finite() {
            return fleet;
        }
        WearRate {
            mean_per_day: if significant { slope } else { 0.0 },
            sd_per_day: sd.max(fleet.sd_per_day),
            source: RateSource::Trend,
        }
    }
}

/// A parameter's belief: normal, with its 95 % interval (lower end ≥ 0).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct Belief {
    pub mean: f64,
    pub sd: f64,
    pub ci95: [f64; 2],
}

impl Belief {
    pub fn new(mean: f64, sd: f64) -> Belief {
        let sd = sd.abs();
        Belief {
            mean,
            sd,
            ci95: [(mean - Z95 * sd).max(0.0), mean + Z95 * sd],
        }
    }

    /// A test's value and 95 % interval as a belief; `None` for an interval that is not one.
    pub fn from_interval(value: f64, ci95: [f64; 2]) -> Option<Belief> {
        let sd = (ci95[1] - ci95[0]) / (2.0 * Z95);
        (value.is_finite() && sd.is_finite() && sd > 0.0).then(|| Belief::new(value, sd))
    }

    /// The prior of a parameter no test has informed: baseline, relative sd `relative_sd`.
    pub fn unmeasured(baseline: f64, relative_sd: f64) -> Belief {
        Belief::new(baseline, relative_sd * baseline.abs())
    }

    /// This belief `age_days` later under `rate` (the module's model).
    pub fn widened(&self, age_days: f64, rate: &WearRate) -> Belief {
        let age = age_days.max(0.0);
        let drift_sd = rate.sd_per_day * age;
        Belief::new(
            self.mean + rate.mean_per_day * age,
            (self.sd * self.sd + drift_sd * drift_sd).sqrt(),
        )
    }

    /// Probability that the parameter lies outside `[lo, hi]` (a band, in the parameter's unit).
    pub fn p_outside(&self, band: [f64; 2]) -> f64 {
        if self.sd.is_nan() || self.sd <= 0.0 {
            return if self.mean < band[0] || self.mean > band[1] {
                1.0
            } else {
                0.0
            };
        }
        let below = normal_cdf((band[0] - self.mean) / self.sd);
        let above = 1.0 - normal_cdf((band[1] - self.mean) / self.sd);
        (below + above).clamp(0.0, 1.0)
    }

    /// The sd after a test that gives Fisher information `info` (1/unit²) on the parameter:
    /// 1/σ² adds (a normal prior and a normal likelihood).
    pub fn sd_after(&self, info: f64) -> f64 {
        if !info.is_finite() || info <= 0.0 {
            return self.sd;
        }
        (1.0 / (1.0 / (self.sd * self.sd) + info)).sqrt()
    }
}

/// Standard normal CDF (erfc, from `statrs`).
pub fn normal_cdf(z: f64) -> f64 {
    0.5 * statrs::function::erf::erfc(-z / std::f64::consts::SQRT_2)
}

/// The Fisher information a test's 95 % interval stands for: 1/sd² (sd = half-width / 1.96).
/// The fits' intervals come from their own Fisher or sandwich covariance (`identify`,
/// `lift::posterior`), so this reads back the information the fit computed.
pub fn information_of_interval(ci95: [f64; 2]) -> Option<f64> {
    let sd = (ci95[1] - ci95[0]) / (2.0 * Z95);
    (sd.is_finite() && sd > 0.0).then(|| 1.0 / (sd * sd))
}

/// The fleet prior a lift or gauge fit rested on for the joints it does not report (issue 37,
/// point 3; `fit.prior` of the fit result): the audit trail of which version it used.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct PriorUsed {
    /// The stored prior's version; 0: none learned yet, the type file's (Table 4 ± its floor).
    pub version: i64,
    /// `learned` (from the store's workshop fits) or `type_file` (no joint had enough of them).
    pub source: String,
    /// The factor the learned sds were widened by in the fit (1 for the type file's floor).
    pub sd_scale: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_belief_widens_with_age_at_the_rate_and_not_before() {
        let b = Belief::from_interval(0.10, [0.08, 0.12]).expect("belief");
        assert!((b.sd - 0.02 / Z95).abs() < 1e-12);
        let fleet = WearRate::fleet(0.10, 0.5);
        assert_eq!(b.widened(0.0, &fleet), b);
        let year = b.widened(365.25, &fleet);
        // sd² = sd_then² + (0.05)²: a year at 0.5 × baseline per year.
        assert!((year.sd - (b.sd.powi(2) + 0.05f64.powi(2)).sqrt()).abs() < 1e-12);
        assert!(year.ci95[1] - year.ci95[0] > b.ci95[1] - b.ci95[0]);
        // A significant trend moves the mean; a flat one only widens.
        let up = WearRate::from_trend(1e-4, [5e-5, 1.5e-4], true, fleet);
        assert!((b.widened(100.0, &up).mean - 0.11).abs() < 1e-12);
        let flat = WearRate::from_trend(1e-6, [-1e-5, 1.2e-5], false, fleet);
        assert_eq!(b.widened(100.0, &flat).mean, 0.10);
        assert_eq!(flat.sd_per_day, fleet.sd_per_day);
        assert_eq!(flat.source, RateSource::Trend);
    }

    #[test]
    fn probability_outside_a_band_and_the_information_a_test_adds() {
        let b = Belief::new(1.0, 0.25);
        // 2 sd either side: 4.55 % outside.
        assert!((b.p_outside([0.5, 1.5]) - 0.0455).abs() < 1e-3);
        assert!(b.p_outside([0.0, 10.0]) < 1e-4);
        assert!((Belief::new(2.0, 0.1).p_outside([0.5, 2.0]) - 0.5).abs() < 1e-9);
        // A test as informative as the belief halves the variance.
        let info = 1.0 / 0.25f64.powi(2);
        assert!((b.sd_after(info) - 0.25 / 2f64.sqrt()).abs() < 1e-12);
        assert_eq!(b.sd_after(0.0), 0.25);
        assert!((information_of_interval([0.0, 2.0 * Z95]).expect("info") - 1.0).abs() < 1e-12);
        assert!(information_of_interval([1.0, 1.0]).is_none());
        assert!(Belief::from_interval(f64::NAN, [0.0, 1.0]).is_none());
    }
}

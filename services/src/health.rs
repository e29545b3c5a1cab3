//! Joint health over time: a joint's history mapped to `models::trend` points per parameter, the
//! trend and the forecast of its alarm-band crossing as dates. No statistics here: the models fit.
//!
//! The alarm band is the drift alarm band × the Table 4 baseline from the fit result; times are
//! days since the joint's first test.

use chrono::{DateTime, TimeDelta, Utc};
use pantowatch_models::report::{FitResult, JointResult, ParamResult};
use pantowatch_models::trend::{self, Point};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::store::JointPoint;

/// Which friction parameter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum Param {
    Viscous,
    Dry,
}

impl Param {
    pub const BOTH: [Param; 2] = [Param::Viscous, Param::Dry];

    pub fn as_str(self) -> &'static str {
        match self {
            Param::Viscous => "viscous",
            Param::Dry => "dry",
        }
    }

    /// (value, lo, hi) of this parameter in a history point — only when that test informed it
    /// ([`JointFit::informs`]): a lift reports the joints it cannot see at baseline with the
    /// prior's interval, which is no measurement of them (issue 15).
    pub fn of(self, p: &JointPoint) -> Option<(f64, f64, f64)> {
        let f = &p.fit;
        if !f.informs(self.as_str()) {
            return None;
        }
        let (v, lo, hi) = match self {
            Param::Viscous => (f.viscous, f.viscous_lo, f.viscous_hi),
            Param::Dry => (f.dry, f.dry_lo, f.dry_hi),
        };
        let (v, lo, hi) = (v?, lo?, hi?);
        (v.is_finite() && lo.is_finite() && hi.is_finite() && hi > lo).then_some((v, lo, hi))
    }
}

/// The fitted trend of one parameter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct TrendView {
    /// Change per day.
    pub slope_per_day: f64,
    pub slope_ci95: [f64; 2],
    /// Value of the line at `level_at`.
    pub level: f64,
    pub level_at: DateTime<Utc>,
    pub n_points: usize,
    /// The slope's 95 % interval excludes 0.
    pub significant: bool,
}

/// When the trend reaches the alarm band.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct ForecastView {
    /// The band edge crossed (a value of the parameter).
    pub threshold: f64,
    pub date: DateTime<Utc>,
    /// Earliest and latest crossing the slope's interval allows; `null` for "not within the
    /// horizon the data support".
    pub date_ci95: [Option<DateTime<Utc>>; 2],
}

/// One parameter's trend and forecast.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct ParamTrend {
    pub param: Param,
    /// Table 4 baseline (from the latest fit result).
    pub baseline: Option<f64>,
    /// Drift alarm band × baseline.
    pub alarm_band: Option<[f64; 2]>,
    /// `None` with fewer than 3 usable points.
    pub trend: Option<TrendView>,
    /// True when the data support no trend (too few points, or the slope's interval holds 0).
    pub no_trend: bool,
    /// Only with a significant trend heading to a band edge that it has not reached by the
    /// latest informing test.
    pub forecast: Option<ForecastView>,
    /// The date the trend line reached the alarm band, when that lies before the latest test
    /// that informed this parameter: a crossing already reached, never a forecast in the past.
    pub crossed_on: Option<DateTime<Utc>>,
}

fn at_days(t0: DateTime<Utc>, days: f64) -> Option<DateTime<Utc>> {
    if !days.is_finite() || days.abs() > 1.0e6 {
        return None;
    }
    TimeDelta::try_milliseconds((days * 86_400_000.0).round() as i64)
        .and_then(|d| t0.checked_add_signed(d))
}

fn days_since(t0: DateTime<Utc>, t: DateTime<Utc>) -> f64 {
    (t - t0).num_milliseconds() as f64 / 86_400_000.0
}

/// The trend and forecast of `param` over `history` (oldest first).
pub fn param_trend(
    history: &[JointPoint],
    param: Param,
    baseline: Option<f64>,
    alarm: [f64; 2],
) -> ParamTrend {
    let alarm_band = baseline
        .filter(|b| b.is_finite() && *b > 0.0)
        .map(|b| [alarm[0] * b, alarm[1] * b]);
    let Some(t0) = history.first().map(|p| p.recorded_at) else {
        return ParamTrend {
            param,
            baseline,
            alarm_band,
            trend: None,
            no_trend: true,
            forecast: None,
            crossed_on: None,
        };
    };
    let points: Vec<Point> = history
        .iter()
        .filter_map(|p| {
            let (value, lo, hi) = param.of(p)?;
            Some(Point {
                t_days: days_since(t0, p.recorded_at),
                value,
                ci95: [lo, hi],
            })
        })
        .collect();
    let fitted = trend::fit(&points);
    let forecast = fitted
        .zip(alarm_band)
        .and_then(|(t, [lo, hi])| t.forecast(lo, hi))
        .and_then(|f| {
            Some(ForecastView {
                threshold: f.threshold,
                date: at_days(t0, f.t_days)?,
                date_ci95: f.t_days_ci95.map(|d| d.and_then(|d| at_days(t0, d))),
            })
        });
    let trend = fitted.and_then(|t| {
        Some(TrendView {
            slope_per_day: t.slope,
            slope_ci95: t.slope_ci95,
            level: t.level,
            level_at: at_days(t0, t.t_ref_days)?,
            n_points: t.n_points,
            significant: t.significant,
        })
    });
    // A crossing at or before the latest informing test has happened: say so, don't forecast.
    let last_informed = history
        .iter()
        .filter(|p| param.of(p).is_some())
        .map(|p| p.recorded_at)
        .max();
    let (forecast, crossed_on) = match (forecast, last_informed) {
        (Some(f), Some(last)) if f.date <= last => (None, Some(f.date)),
        (f, _) => (f, None),
    };
    ParamTrend {
        param,
        baseline,
        alarm_band,
        no_trend: !trend.as_ref().is_some_and(|t| t.significant),
        trend,
        forecast,
        crossed_on,
    }
}

/// Table 4 baselines (viscous, dry) of `joint` in a fit result.
pub fn baselines(result: &FitResult, joint: &str) -> (Option<f64>, Option<f64>) {
    let j = result.joints.iter().find(|j| j.joint == joint);
    let b = |p: fn(&JointResult) -> &ParamResult| {
        j.and_then(|j| p(j).baseline).filter(|v| v.is_finite())
    };
    (b(|j| &j.viscous), b(|j| &j.dry))
}

/// The line's value at `t` (for charts).
pub fn line_at(t: &TrendView, at: DateTime<Utc>) -> f64 {
    t.level + t.slope_per_day * days_since(t.level_at, at)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::{JointFit, Status};

    fn point(day: i64, v: f64) -> JointPoint {
        let t0 = DateTime::parse_from_rfc3339("2026-01-01T00:00:00Z")
            .expect("t")
            .with_timezone(&Utc);
        JointPoint {
            trace_id: format!("t{day}"),
            vehicle_id: "V".into(),
            recorded_at: t0 + TimeDelta::days(day),
            model_version: "v".into(),
            fit_id: day,
            fitted_at: t0,
            fit: JointFit {
                joint: "J1".into(),
                viscous: Some(v),
                viscous_lo: Some(v - 0.001),
                viscous_hi: Some(v + 0.001),
                dry: Some(0.023),
                dry_lo: Some(0.0225),
                dry_hi: Some(0.0235),
                identifiable: true,
                status: Status::Ok,
                viscous_informed: None,
                viscous_status: None,
                dry_informed: None,
                dry_status: None,
            },
        }
    }

    #[test]
    fn a_rising_joint_has_a_trend_and_a_crossing_date_a_flat_one_none() {
        // 0.034 rising 0.0001/day: reaches 2 × 0.034 at day 340.
        let h: Vec<_> = (0..8)
            .map(|m| point(30 * m, 0.034 + 0.0001 * (30 * m) as f64))
            .collect();
        let v = param_trend(&h, Param::Viscous, Some(0.034), [0.5, 2.0]);
        assert!(!v.no_trend);
        let f = v.forecast.expect("forecast");
        let days = days_since(h[0].recorded_at, f.date);
        assert!((days - 340.0).abs() < 2.0, "{days}");
        assert_eq!(v.alarm_band, Some([0.017, 0.068]));
        let d = param_trend(&h, Param::Dry, Some(0.023), [0.5, 2.0]);
        assert!(d.no_trend && d.forecast.is_none());
        let short = param_trend(&h[..2], Param::Viscous, Some(0.034), [0.5, 2.0]);
        assert!(short.no_trend && short.trend.is_none());
    }

    #[test]
    fn baselines_from_the_fit_result() {
        use pantowatch_models::drift::Status;
        let p = |baseline: Option<f64>| ParamResult {
            value: 0.02,
            ci95: [0.01, 0.03],
            baseline,
            unit: "1".into(),
            identifiable: true,
            status: Status::Ok,
            combination: None,
        };
        let j3 = |v, d| JointResult {
            joint: "J3".into(),
            viscous: p(v),
            dry: p(d),
            identifiable: true,
            status: Status::Ok,
        };
        let mut r = FitResult {
            joints: vec![j3(Some(0.017), Some(0.2))],
            ..FitResult::default()
        };
        assert_eq!(baselines(&r, "J3"), (Some(0.017), Some(0.2)));
        assert_eq!(baselines(&r, "J1"), (None, None));
        // A baseline written `null` (none, or not finite) is none.
        r.joints = vec![j3(None, Some(f64::NAN))];
        assert_eq!(baselines(&r, "J3"), (None, None));
    }
}

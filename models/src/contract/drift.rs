//! Drift status of an identified parameter against its Table 4 baseline, judged with the
//! confidence interval, not the point value.

use serde::{Deserialize, Serialize};

/// Bands as multiples of the baseline. Defaults: watch outside [0.67, 1.5]×, alarm outside
/// [0.5, 2]× (issue 2); configurable.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DriftThresholds {
    pub watch: [f64; 2],
    pub alarm: [f64; 2],
}

impl Default for DriftThresholds {
    fn default() -> Self {
        Self {
            watch: [0.67, 1.5],
            alarm: [0.5, 2.0],
        }
    }
}

/// Drift status of a parameter or joint.
/// The one status type of pantowatch (issue 19, point 1): the service stores, serves and judges
/// health with it. Ordered `Unknown < Ok < Watch < Alarm`, so `max` is the worst (`unknown`
/// says nothing is known to be wrong).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum Status {
    /// Not judged: the trace cannot pin the parameter down, or there is no baseline.
    Unknown,
    Ok,
    Watch,
    Alarm,
}

impl Status {
    pub fn as_str(self) -> &'static str {
        match self {
            Status::Unknown => "unknown",
            Status::Ok => "ok",
            Status::Watch => "watch",
            Status::Alarm => "alarm",
        }
    }

    /// Rank used in SQL aggregates: `unknown` 0, `ok` 1, `watch` 2, `alarm` 3.
    pub fn rank(self) -> i64 {
        self as i64
    }

    /// The status of a [`Status::rank`]; `None` for any other number.
    pub fn from_rank(rank: i64) -> Option<Self> {
        [Status::Unknown, Status::Ok, Status::Watch, Status::Alarm]
            .into_iter()
            .find(|s| s.rank() == rank)
    }
}

/// A status word that is none of `unknown`, `ok`, `watch`, `alarm`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown Status {0:?}")]
pub struct UnknownStatus(pub String);

impl std::str::FromStr for Status {
    type Err = UnknownStatus;
    fn from_str(s: &str) -> Result<Self, UnknownStatus> {
        [Status::Unknown, Status::Ok, Status::Watch, Status::Alarm]
            .into_iter()
            .find(|v| v.as_str() == s)
            .ok_or_else(|| UnknownStatus(s.to_owned()))
    }
}

impl std::fmt::Display for Status {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.pad(self.as_str())
    }
}

/// The verdict on one parameter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Verdict {
    pub identifiable: bool,
    pub status: Status,
}

impl DriftThresholds {
    /// Judge an interval `[lo, hi]` against `baseline`.
    ///
    /// A parameter is identifiable when its interval is no wider than the watch band
    /// (`(watch[1] − watch[0])·baseline`; without a baseline, than that fraction of the value).
    /// An unidentifiable parameter is `unknown` — never `ok`, never `alarm`. Otherwise: `alarm`
    /// when the whole interval lies outside the alarm band, `watch` when outside the watch band.
    pub fn judge(&self, ci: [f64; 2], value: f64, baseline: Option<f64>) -> Verdict {
        let [lo, hi] = ci;
        let width = hi - lo;
        let Some(b) = baseline.filter(|b| b.is_finite() && *b > 0.0) else {
            let identifiable =
                width.is_finite() && width <= (self.watch[1] - self.watch[0]) * value.abs();
            return Verdict {
                identifiable,
                status: Status::Unknown,
            };
        };
        let identifiable = width.is_finite() && width <= (self.watch[1] - self.watch[0]) * b;
        if !identifiable {
            return Verdict {
                identifiable,
                status: Status::Unknown,
            };
        }
        let outside = |band: [f64; 2]| lo > band[1] * b || hi < band[0] * b;
        let status = if outside(self.alarm) {
            Status::Alarm
        } else if outside(self.watch) {
            Status::Watch
        } else {
            Status::Ok
        };
        Verdict {
            identifiable,
            status,
        }
    }

    /// Check the bands are ordered: 0 < alarm_lo ≤ watch_lo < 1 < watch_hi ≤ alarm_hi.
    pub fn validate(&self) -> Result<(), String> {
        let [wl, wh] = self.watch;
        let [al, ah] = self.alarm;
        if 0.0 < al && al <= wl && wl < 1.0 && 1.0 < wh && wh <= ah && ah.is_finite() {
            Ok(())
        } else {
            Err(format!(
                "drift bands must satisfy 0 < alarm_lo <= watch_lo < 1 < watch_hi <= alarm_hi, got watch {:?} alarm {:?}",
                self.watch, self.alarm
            ))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn judged_with_the_interval_not_the_point() {
        let th = DriftThresholds::default();
        // Point value 1.6× but the interval reaches back into the band: ok.
        assert_eq!(th.judge([1.45, 1.75], 1.6, Some(1.0)).status, Status::Ok);
        assert_eq!(th.judge([1.55, 1.9], 1.7, Some(1.0)).status, Status::Watch);
        assert_eq!(th.judge([2.05, 2.3], 2.2, Some(1.0)).status, Status::Alarm);
        assert_eq!(th.judge([0.3, 0.45], 0.4, Some(1.0)).status, Status::Alarm);
        assert_eq!(th.judge([0.55, 0.65], 0.6, Some(1.0)).status, Status::Watch);
        // Wider than the band: not identifiable, never ok, never alarm.
        let v = th.judge([2.1, 3.5], 2.8, Some(1.0));
        assert!(!v.identifiable);
        assert_eq!(v.status, Status::Unknown);
        assert!(th.validate().is_ok());
        assert!(
            DriftThresholds {
                watch: [0.67, 1.5],
                alarm: [0.7, 2.0]
            }
            .validate()
            .is_err()
        );
    }
}

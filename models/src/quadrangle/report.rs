//! A quadrangle swing as a document gives it (angles in degrees, rig options) → the fitted
//! joints J1, J2, J2′, J3 as the contract's fit result; and the swing simulated as recorded.
//!
//! Mapping (stated so the service knows no physics), as `lift::report`:
//! - An informed parameter is reported at its MAP estimate with the posterior interval and judged
//!   against Table 4 by the drift bands; an uninformed one at baseline with the prior's interval,
//!   `identifiable: false`, status `unknown`.
//! - `rmse` is the residual RMS over both angle channels, deg. `fit.sensor_offset` is the α
//!   channel's zero, deg (the β zero is fitted too, and reported only in [`QuadFit`]);
//!   `release_position` / `release_rate` are the fitted α₀ (deg) and α̇₀ (deg/s).
//! - `residual`: no effect vocabulary is tried on swing traces yet (`effects` empty,
//!   `rmse_before = rmse_after`); the `holdout_` pair equals the fitted values, not a refit.

use super::identify::{QuadEstimate, QuadFit, QuadFitError, QuadFitOptions, SwingTrace, fit_swing};
use super::model::{PointMass, QJoint, Quadrangle, RigError};
use super::simulate::{SwingError, SwingOptions, simulate_swing};
use crate::contract::drift::DriftThresholds;
use crate::contract::report::{
    FitDetails, FitResult, JointResult, MODEL_VERSION, ParamResult, Quantity, ResidualResult,
};
use crate::data::RigLimits;
use crate::lift::geometry::builtin_160ec;
use crate::numerics::noise::Noise;
use crate::numerics::stats::Z95;

/// The paper's incline of the frame plane in the Fig 12 test, deg (`[paper_tests]` of
/// models/data/160ec.toml).
pub fn paper_incline_deg() -> f64 {
    crate::data::builtin_160ec()
        .paper_tests()
        .quadrangle_incline_deg
}

/// The paper's release in the Fig 12 test as a deflection from the loop's own rest angle, deg
/// (`[paper_tests]` of models/data/160ec.toml, which says why a deflection).
pub fn paper_deflection_deg() -> f64 {
    crate::data::builtin_160ec()
        .paper_tests()
        .quadrangle_deflection_deg
}

/// The test stand as a document describes it (`test.rig`), defaults the paper's.
#[derive(Debug, Clone, PartialEq)]
pub struct QuadRig {
    pub incline_deg: f64,
    pub gravity_m_s2: f64,
    pub attachments: Vec<PointMass>,
}

impl Default for QuadRig {
    fn default() -> Self {
        Self {
            incline_deg: paper_incline_deg(),
            gravity_m_s2: builtin_160ec().gravity_m_s2,
            attachments: Vec::new(),
        }
    }
}

/// The plausible spans of a stand and its channels: the 160EC type's `[rig_limits]`
/// (`models/data/160ec.toml`; the quadrangle is of that type only).
fn limits() -> &'static RigLimits {
    crate::data::builtin_160ec().rig_limits()
}

fn out_of_range((field, message): (String, String)) -> RigError {
    RigError { field, message }
}

impl QuadRig {
    /// The 160EC quadrangle on this stand, Table 4 friction. Errors name the rig field. Every
    /// stated value lies in the type's plausible span (`[rig_limits]`: `incline_deg`,
    /// `gravity_m_s2`, and per attachment `mass_kg` and its distance `attachment_m`), checked
    /// before the model is built (issue 18: a 1e308 kg point mass was accepted).
    pub fn model(&self) -> Result<Quadrangle, RigError> {
        let l = limits();
        let c = |field: &str, v: f64, span| {
            RigLimits::check(&format!("test.rig.{field}"), v, span).map_err(out_of_range)
        };
        c("incline_deg", self.incline_deg, l.incline_deg)?;
        c("gravity_m_s2", self.gravity_m_s2, l.gravity_m_s2)?;
        for (i, a) in self.attachments.iter().enumerate() {
            c(&format!("attachments[{i}].mass_kg"), a.mass_kg, l.mass_kg)?;
            let d = a.position_m.norm();
            let within = a.position_m.x.is_finite()
                && a.position_m.y.is_finite()
                && d >= l.attachment_m[0]
                && d <= l.attachment_m[1];
            if !within {
                return Err(RigError {
                    field: format!("test.rig.attachments[{i}].position_m"),
                    message: format!(
                        "must be two finite numbers within [{}, {}] m of the body's origin \
                         (models/data, `rig_limits.attachment_m`), got [{}, {}]",
                        l.attachment_m[0], l.attachment_m[1], a.position_m.x, a.position_m.y
                    ),
                });
            }
        }
        let mut m = Quadrangle::new(builtin_160ec(), self.incline_deg.to_radians());
        m.set_gravity(self.gravity_m_s2, self.incline_deg.to_radians());
        for (i, a) in self.attachments.iter().enumerate() {
            m.add_point_mass(a, &format!("test.rig.attachments[{i}]"))?;
        }
        Ok(m)
    }
}

impl QuadChannels<'_> {
    /// Both angle channels within the type's plausible joint angle (`[rig_limits]`
    /// `alpha_deg_abs`); a refusal names the sample (`channels.beta_deg[7]`).
    pub fn check_limits(&self) -> Result<(), RigError> {
        let abs = limits().alpha_deg_abs;
        RigLimits::check_channel("alpha_deg", self.alpha_deg, abs).map_err(out_of_range)?;
        RigLimits::check_channel("beta_deg", self.beta_deg, abs).map_err(out_of_range)
    }
}

/// The recorded channels of a `quadrangle_swing` document.
#[derive(Debug, Clone, Copy)]
pub struct QuadChannels<'a> {
    pub t_s: &'a [f64],
    pub alpha_deg: &'a [f64],
    pub beta_deg: &'a [f64],
}

/// A swing fit: the contract result and the MAP fit (fitted channels inside, rad).
#[derive(Debug, Clone)]
pub struct QuadReport {
    pub result: FitResult,
    pub fit: QuadFit,
}

/// Why a swing document could not be fitted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum QuadReportError {
    #[error(transparent)]
    Rig(#[from] RigError),
    #[error(transparent)]
    Fit(#[from] QuadFitError),
    #[error(
        "`test.rig.incline_deg`: the loop has no rest position at {incline_deg}° on this \
         geometry (it falls into a toggle of its assembly range): no default release"
    )]
    NoRest { incline_deg: f64 },
}

/// Fit one swing with the MAP identification ([`QuadFitOptions::default`] with these drift
/// bands) and map it to the contract's fit result.
pub fn fit_quadrangle_trace(
    channels: &QuadChannels,
    rig: &QuadRig,
    thresholds: &DriftThresholds,
    trace_id: &str,
) -> Result<QuadReport, QuadReportError> {
    let model = rig.model()?;
    let opts = QuadFitOptions {
        thresholds: *thresholds,
        ..QuadFitOptions::default()
    };
    let a: Vec<f64> = channels.alpha_deg.iter().map(|v| v.to_radians()).collect();
    let b: Vec<f64> = channels.beta_deg.iter().map(|v| v.to_radians()).collect();
    let trace = SwingTrace {
        t_s: channels.t_s,
        alpha_rad: &a,
        beta_rad: &b,
    };
    let fit = fit_swing(&model, &trace, &opts)?;
    let result = fit_result(&fit, channels.t_s, &opts, trace_id);
    Ok(QuadReport { result, fit })
}

fn param(e: &QuadEstimate) -> ParamResult {
    ParamResult {
        value: e.value,
        ci95: e.ci95,
        baseline: Some(e.baseline),
        unit: match e.param.kind() {
            "dry" => "1".into(),
            _ => "N·m·s/rad".into(),
        },
        identifiable: e.informed,
        status: e.status,
        combination: None,
    }
}

/// Lag-1 autocorrelation of a residual (NaN when too short or constant).
fn rho1(r: &[f64]) -> f64 {
    if r.len() < 3 {
        return f64::NAN;
    }
    let mean = r.iter().sum::<f64>() / r.len() as f64;
    let var: f64 = r.iter().map(|v| (v - mean).powi(2)).sum();
    let cov: f64 = r.windows(2).map(|w| (w[0] - mean) * (w[1] - mean)).sum();
    cov / var
}

/// The contract's fit result of a swing fit.
pub fn fit_result(fit: &QuadFit, t_s: &[f64], opts: &QuadFitOptions, trace_id: &str) -> FitResult {
    let joints = QJoint::ALL
        .iter()
        .map(|j| {
            let viscous = param(fit.estimate(super::identify::QuadParam::Viscous(*j)));
            let dry = param(fit.estimate(super::identify::QuadParam::Dry(*j)));
            JointResult {
                joint: j.name().to_string(),
                identifiable: viscous.identifiable || dry.identifiable,
                status: fit.joint_status(*j),
                viscous,
                dry,
            }
        })
        .collect();
    let rmse = fit.rmse_rad.to_degrees();
    let deg = |v: f64| v.to_degrees();
    let z = fit.alpha_zero_rad;
    FitResult {
        trace_id: trace_id.to_string(),
        joints,
        rmse: Quantity {
            value: rmse,
            unit: "deg".into(),
        },
        residual: ResidualResult {
            effects: Vec::new(),
            rmse_before: rmse,
            rmse_after: rmse,
            holdout_rmse_before: rmse,
            holdout_rmse_after: rmse,
            verdict: None,
            correlates_with: Vec::new(),
            excess_ratio: None,
            joints_withheld: None,
            holdout_note: None,
            autocorrelation: Vec::new(),
            autocorrelation_before: Vec::new(),
            ambiguity: None,
            halves: None,
        },
        fit: FitDetails {
            model_version: MODEL_VERSION.to_string(),
            release_t_s: t_s.first().copied().unwrap_or(0.0),
            release_rule: crate::joint::identify::release::ReleaseRule::FirstSample
                .as_str()
                .to_owned(),
            release_warning: None,
            release_disturbed_until_s: None,
            release_disturbance: None,
            release_position: Quantity {
                value: deg(fit.release_alpha_rad.value),
                unit: "deg".into(),
            },
            release_rate: Quantity {
                value: deg(fit.release_rate_rad_s.value),
                unit: "deg/s".into(),
            },
            sensor_offset: Quantity {
                value: deg(z.value),
                unit: "deg".into(),
            },
            sensor_offset_ci95: Some([deg(z.value - Z95 * z.sd), deg(z.value + Z95 * z.sd)]),
            input_offset: None,
            input_offset_ci95: None,
            samples_fitted: fit.samples_fitted,
            termination: format!("{:?}", fit.termination),
            iterations: fit.iterations,
            residual_rho1: rho1(&fit.residual_alpha_rad),
            interval_inflation: fit.noise_rad / opts.angle_noise_rad,
            // Not defined for a many-joint fit (null in JSON).
            viscous_dry_correlation: f64::NAN,
            body_uncertainty: None,
            absorption: None,
            prior: None,
        },
        pooled: None,
        combinations: Vec::new(),
        pooled_rig: None,
    }
}

/// A swing as the stand records it: the quadrangle on `rig` with friction `scale`d per
/// parameter from Table 4, released at rest from `release_deg` (default: 10.1° below the
/// frictionless rest angle, [`paper_deflection_deg`]), sampled at `fs_hz` for
/// `duration_s`, both channels with Gaussian noise `noise_deg` and sensor zeros `zeros_deg`.
#[derive(Debug, Clone)]
pub struct SwingRecipe {
    pub rig: QuadRig,
    /// (parameter, factor on its Table 4 value).
    pub scale: Vec<(super::identify::QuadParam, f64)>,
    pub release_deg: Option<f64>,
    pub fs_hz: f64,
    pub duration_s: f64,
    pub noise_deg: f64,
    pub zeros_deg: (f64, f64),
    pub seed: u64,
}

/// A recorded swing, degrees.
#[derive(Debug, Clone, PartialEq)]
pub struct SwingRecord {
    pub t_s: Vec<f64>,
    pub alpha_deg: Vec<f64>,
    pub beta_deg: Vec<f64>,
}

/// Simulate a swing as recorded ([`SwingRecipe`]).
pub fn record_swing(r: &SwingRecipe) -> Result<SwingRecord, QuadReportError> {
    let mut m = r.rig.model()?;
    for (p, f) in &r.scale {
        let v = p.get(&m);
        p.set(&mut m, v * f);
    }
    let release_rad = match r.release_deg {
        Some(d) => d.to_radians(),
        None => {
            m.rest_alpha_rad(0.4).ok_or(QuadReportError::NoRest {
                incline_deg: r.rig.incline_deg,
            })? + paper_deflection_deg().to_radians()
        }
    };
    let n = (r.duration_s * r.fs_hz).round() as usize + 1;
    let t_s: Vec<f64> = (0..n).map(|k| k as f64 / r.fs_hz).collect();
    let run = simulate_swing(&m, &t_s, release_rad, 0.0, &SwingOptions::default())
        .map_err(|e: SwingError| QuadReportError::Fit(e.into()))?;
    let mut rng = Noise::new(r.seed);
    let mut read = |v: &[f64], zero: f64| -> Vec<f64> {
        v.iter()
            .map(|x| x.to_degrees() + zero + r.noise_deg * rng.normal())
            .collect()
    };
    let alpha_deg = read(&run.alpha_rad, r.zeros_deg.0);
    let beta_deg = read(&run.beta_rad, r.zeros_deg.1);
    Ok(SwingRecord {
        t_s,
        alpha_deg,
        beta_deg,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contract::drift::Status;

    /// The Table 4 swing maps to J1, J2, J2′, J3 with every status `ok` or `unknown`, each
    /// uninformed parameter at baseline; nothing flagged; units as the contract's.
    #[test]
    fn baseline_swing_maps_to_the_four_joints_ok_or_unknown() {
        let rec = record_swing(&SwingRecipe {
            rig: QuadRig::default(),
            scale: Vec::new(),
            release_deg: None,
            fs_hz: 200.0,
            duration_s: 12.0,
            noise_deg: 0.05,
            zeros_deg: (0.0, 0.0),
            seed: 3,
        })
        .unwrap();
        let ch = QuadChannels {
            t_s: &rec.t_s,
            alpha_deg: &rec.alpha_deg,
            beta_deg: &rec.beta_deg,
        };
        let rep = fit_quadrangle_trace(&ch, &QuadRig::default(), &DriftThresholds::default(), "q")
            .unwrap();
        let r = &rep.result;
        let names: Vec<&str> = r.joints.iter().map(|j| j.joint.as_str()).collect();
        assert_eq!(names, ["J1", "J2", "J2'", "J3"]);
        for j in &r.joints {
            assert!(matches!(j.status, Status::Ok | Status::Unknown), "{j:?}");
            for p in [&j.viscous, &j.dry] {
                if !p.identifiable {
                    assert_eq!((Some(p.value), p.status), (p.baseline, Status::Unknown));
                }
                assert!(p.ci95[0] <= p.value && p.value <= p.ci95[1]);
            }
        }
        assert!(r.joints.iter().any(|j| j.identifiable), "{r:?}");
        assert_eq!(r.rmse.unit, "deg");
        assert!(r.rmse.value < 0.06, "{}", r.rmse.value);
        let json = serde_json::to_value(r).unwrap();
        assert_eq!(json["joints"][0]["viscous"]["unit"], "N·m·s/rad");
        assert_eq!(json["fit"]["release_rate"]["unit"], "deg/s");
    }

    #[test]
    fn rig_errors_name_their_field() {
        let rig = QuadRig {
            incline_deg: 120.0,
            ..QuadRig::default()
        };
        assert_eq!(rig.model().unwrap_err().field, "test.rig.incline_deg");
        let rig = QuadRig {
            gravity_m_s2: f64::NAN,
            ..QuadRig::default()
        };
        assert_eq!(rig.model().unwrap_err().field, "test.rig.gravity_m_s2");
    }

    /// Issue 18: the stand and its channels are held to the type's `[rig_limits]` — a point
    /// mass of 1e308 kg, the Moon's gravity, a mass 6 m off its body, an angle of 1e308° are
    /// refused naming the field; the paper's stand and the spans' own ends are accepted.
    #[test]
    fn absurd_stands_and_channels_are_refused_by_the_rig_limits() {
        let l = crate::data::builtin_160ec().rig_limits();
        let point = |mass_kg: f64, x: f64| PointMass {
            body: super::super::model::QBody::named("upper_arm").unwrap(),
            mass_kg,
            position_m: crate::lift::vec2::V2::new(x, 0.0),
        };
        let with = |attachments: Vec<PointMass>| QuadRig {
            attachments,
            ..QuadRig::default()
        };
        for (rig, field) in [
            (
                with(vec![point(1e308, 0.5)]),
                "test.rig.attachments[0].mass_kg",
            ),
            (
                with(vec![point(5.0, 0.5), point(5.0, l.attachment_m[1] + 1.0)]),
                "test.rig.attachments[1].position_m",
            ),
            (
                QuadRig {
                    gravity_m_s2: 1.62,
                    ..QuadRig::default()
                },
                "test.rig.gravity_m_s2",
            ),
            (
                QuadRig {
                    incline_deg: l.incline_deg[0] - 1.0,
                    ..QuadRig::default()
                },
                "test.rig.incline_deg",
            ),
        ] {
            assert_eq!(rig.model().unwrap_err().field, field, "{rig:?}");
        }
        QuadRig::default().model().expect("the paper's stand");
        QuadRig {
            gravity_m_s2: l.gravity_m_s2[1],
            incline_deg: l.incline_deg[1],
            attachments: vec![point(l.mass_kg[1], l.attachment_m[1])],
        }
        .model()
        .expect("the spans' upper ends");
        let t = [0.0, 0.002, 0.004];
        let ok = [-10.0, -10.0, -9.9];
        let bad = [-3.6, 1e308, -3.6];
        let ch = |alpha_deg, beta_deg| QuadChannels {
            t_s: &t,
            alpha_deg,
            beta_deg,
        };
        assert_eq!(
            ch(&ok, &bad).check_limits().unwrap_err().field,
            "channels.beta_deg[1]"
        );
        assert_eq!(
            ch(&bad, &ok).check_limits().unwrap_err().field,
            "channels.alpha_deg[1]"
        );
        ch(&ok, &ok).check_limits().expect("plausible angles");
    }
}

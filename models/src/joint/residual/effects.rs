//! The contract's effect vocabulary as physical laws added to the base model: their
//! parameters, null values, starting values, and how a found effect is reported.

use crate::contract::report::EffectResult;
use crate::joint::dynamics::Mechanism;
use crate::joint::friction::{DynParam, POSITION_KNOTS, PositionFriction, Stribeck};
use crate::joint::identify::{FitOutcome, FitSpec, JointTest, Param};
use serde::Serialize;

/// The contract's effect vocabulary.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Effect {
    Stribeck,
    QuadraticDrag,
    PositionFriction,
    Backlash,
    SensorOffset,
    SensorDelay,
    /// pantowatch's addition (issue 17, points 1 and 3): the stated inertia is off, J =
    /// J_stated·e^λ — a pendulum's about its pin (the model swings at the wrong period and the
    /// residual grows like a phase drift), a slider's moving mass (its force–acceleration
    /// balance is off). Body parameters are measured with an uncertainty; a friction law cannot
    /// absorb them.
    InertiaError,
    /// pantowatch's addition (issue 17, point 3): dry friction that differs by direction of
    /// motion, μ± = μ·(1 ± δ) (a pin worn on one flank, a slide with a directional finish).
    /// While sliding it is a symmetric friction plus a constant force or torque lever·N·μ·δ, so a
    /// test that also fits its input's zero (a driven axis without a position reference) cannot
    /// tell the two apart: there the score test finds it collinear and it is not tried.
    AsymmetricFriction,
}

impl Effect {
    pub const SEARCHED: [Effect; 7] = [
        Effect::Stribeck,
        Effect::QuadraticDrag,
        Effect::PositionFriction,
        Effect::Backlash,
        Effect::SensorDelay,
        Effect::InertiaError,
        Effect::AsymmetricFriction,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Effect::Stribeck => "stribeck",
            Effect::QuadraticDrag => "quadratic_drag",
            Effect::PositionFriction => "position_friction",
            Effect::Backlash => "backlash",
            Effect::SensorOffset => "sensor_offset",
            Effect::SensorDelay => "sensor_delay",
            Effect::InertiaError => "inertia_error",
            Effect::AsymmetricFriction => "asymmetric_friction",
        }
    }

    pub fn parse(s: &str) -> Option<Effect> {
        [
            Effect::Stribeck,
            Effect::QuadraticDrag,
            Effect::PositionFriction,
            Effect::Backlash,
            Effect::SensorOffset,
            Effect::SensorDelay,
            Effect::InertiaError,
            Effect::AsymmetricFriction,
        ]
        .into_iter()
        .find(|e| e.name() == s)
    }

    /// The parameters the effect adds.
    pub fn params(self) -> Vec<Param> {
        match self {
            Effect::Stribeck => vec![
                Param::Dyn(DynParam::StribeckRatio),
                Param::Dyn(DynParam::StribeckSpeed),
            ],
            Effect::QuadraticDrag => vec![Param::Dyn(DynParam::QuadraticDrag)],
            // Every knot's coefficient; a fit frees all but the anchor's.
            Effect::PositionFriction => (0..POSITION_KNOTS as u8)
                .map(|k| Param::Dyn(DynParam::Position(k)))
                .collect(),
            Effect::Backlash => vec![Param::Backlash],
            Effect::SensorOffset => vec![Param::Offset],
            Effect::SensorDelay => vec![Param::Delay],
            Effect::InertiaError => vec![Param::Inertia],
            Effect::AsymmetricFriction => vec![Param::Dyn(DynParam::DryAsymmetry)],
        }
    }

    /// Degrees of freedom of the effect's score statistic: the parameters it frees at its null
    /// (Stribeck's speed is not defined there; position friction holds its anchor knot).
    pub fn score_dof(self) -> usize {
        match self {
            Effect::Stribeck => 1,
            Effect::PositionFriction => POSITION_KNOTS - 1,
            e => e.params().len(),
        }
    }

    /// The parameters whose null values mean "no effect", with those values.
    pub(super) fn nulls(self) -> Vec<(Param, f64)> {
        match self {
            Effect::Stribeck => vec![(Param::Dyn(DynParam::StribeckRatio), 1.0)],
            Effect::QuadraticDrag => vec![(Param::Dyn(DynParam::QuadraticDrag), 0.0)],
            Effect::PositionFriction => (0..POSITION_KNOTS as u8)
                .map(|k| (Param::Dyn(DynParam::Position(k)), 0.0))
                .collect(),
            Effect::Backlash => vec![(Param::Backlash, 0.0)],
            Effect::SensorOffset => vec![(Param::Offset, 0.0)],
            Effect::SensorDelay => vec![(Param::Delay, 0.0)],
            Effect::InertiaError => vec![(Param::Inertia, 0.0)],
            Effect::AsymmetricFriction => vec![(Param::Dyn(DynParam::DryAsymmetry), 0.0)],
        }
    }

    /// Add the effect to `spec` at its starting value (`at_null`: at the null value, for the
    /// score test).
    pub(super) fn add_to(self, spec: &mut FitSpec, scales: &Scales, at_null: bool) {
        match self {
            Effect::Stribeck => {
                spec.law.stribeck = Some(Stribeck {
                    ratio: if at_null { 1.0 } else { 1.5 },
                    speed: 0.1 * scales.v_max,
                });
                spec.free.push(DynParam::StribeckRatio);
                if !at_null {
                    spec.free.push(DynParam::StribeckSpeed);
                }
            }
            Effect::QuadraticDrag => {
                spec.law.quadratic_drag = Some(if at_null {
                    0.0
                } else {
                    0.1 * scales.friction / (scales.v_max * scales.v_max)
                });
                spec.free.push(DynParam::QuadraticDrag);
            }
            Effect::PositionFriction => {
                let pf = PositionFriction::flat(scales.q_range[0], scales.q_range[1]);
                let anchor = pf.anchor();
                spec.law.position = Some(pf);
                spec.free.extend(
                    (0..POSITION_KNOTS)
                        .filter(|&k| k != anchor)
                        .map(|k| DynParam::Position(k as u8)),
                );
            }
            Effect::Backlash => {
                spec.backlash = Some(if at_null {
                    0.0
                } else {
                    0.5 * scales.noise_model
                })
            }
            Effect::SensorDelay => spec.delay = Some(0.0),
            Effect::SensorOffset => spec.fit_offset = true,
            Effect::InertiaError => spec.inertia = Some(0.0),
            Effect::AsymmetricFriction => {
                spec.law.asymmetry = 0.0;
                spec.free.push(DynParam::DryAsymmetry);
            }
        }
    }
}

/// Scales of the motion for starting values.
pub(super) struct Scales {
    pub(super) v_max: f64,
    /// Typical friction torque/force: D·v_max + lever·N_rest·μ.
    pub(super) friction: f64,
    /// The travel the free motion covers, rad or m: the position-friction grid's span.
    pub(super) q_range: [f64; 2],
    /// Sensor noise in model units.
    pub(super) noise_model: f64,
}

pub(super) fn effect_result(e: Effect, fit: &FitOutcome, test: &JointTest) -> EffectResult {
    let (rate, pos) = match test.dof.mech {
        Mechanism::Pendulum(_) => ("rad_s", "rad"),
        Mechanism::Slider(_) => ("m_s", "m"),
    };
    let mut params = serde_json::Map::new();
    let mut put = |name: String, p: Param| {
        if let Some((v, _, ci)) = fit.get(p) {
            params.insert(name.clone(), serde_json::json!(v));
            params.insert(format!("{name}_ci95"), serde_json::json!(ci));
        }
    };
    match e {
        Effect::Stribeck => {
            put("mu_s_ratio".into(), Param::Dyn(DynParam::StribeckRatio));
            put(format!("v_s_{rate}"), Param::Dyn(DynParam::StribeckSpeed));
        }
        Effect::QuadraticDrag => put(
            if pos == "rad" {
                "c_nms2_per_rad2".into()
            } else {
                "c_ns2_per_m2".into()
            },
            Param::Dyn(DynParam::QuadraticDrag),
        ),
        // The factor on μ at each knot, 1 + c_k, with its interval (the anchor's is 1 exactly).
        Effect::PositionFriction => {
            if let Some(pf) = fit.law.position {
                let (scale, unit) = if pos == "rad" {
                    (180.0 / std::f64::consts::PI, "deg")
                } else {
                    (1000.0, "mm")
                };
                let knots: Vec<f64> = (0..POSITION_KNOTS).map(|k| scale * pf.knot(k)).collect();
                let (mut factor, mut ci95) = (Vec::new(), Vec::new());
                for k in 0..POSITION_KNOTS {
                    match fit.get(Param::Dyn(DynParam::Position(k as u8))) {
                        Some((v, _, ci)) => {
                            factor.push(1.0 + v);
                            ci95.push([1.0 + ci[0], 1.0 + ci[1]]);
                        }
                        None => {
                            factor.push(1.0 + pf.coeffs[k]);
                            ci95.push([1.0 + pf.coeffs[k]; 2]);
                        }
                    }
                }
                params.insert(format!("knots_{unit}"), serde_json::json!(knots));
                params.insert("factor".into(), serde_json::json!(factor));
                params.insert("factor_ci95".into(), serde_json::json!(ci95));
            }
        }
        Effect::Backlash => put(format!("half_width_{pos}"), Param::Backlash),
        Effect::SensorDelay => put("delay_s".into(), Param::Delay),
        Effect::SensorOffset => put(format!("offset_{}", test.unit), Param::Offset),
        // Reported as δ with μ₊ = μ·(1 + δ), μ₋ = μ·(1 − δ).
        Effect::AsymmetricFriction => put("asymmetry".into(), Param::Dyn(DynParam::DryAsymmetry)),
        // Reported as the ratio J/J_stated and its interval (the fit's λ = ln of it).
        Effect::InertiaError => {
            if let Some((v, _, ci)) = fit.get(Param::Inertia) {
                params.insert("inertia_ratio".into(), serde_json::json!(v.exp()));
                params.insert(
                    "inertia_ratio_ci95".into(),
                    serde_json::json!([ci[0].exp(), ci[1].exp()]),
                );
            }
        }
    }
    EffectResult {
        name: e.name().into(),
        params,
    }
}

/// `sensor_offset` when the fitted zero's interval excludes 0 and the zero is at least the
/// logger's `resolution` (channel units; 0: unquantised).
pub fn sensor_offset_effect(
    full: &FitOutcome,
    unit: &str,
    resolution: f64,
) -> Option<EffectResult> {
    let (v, _, ci) = full.get(Param::Offset)?;
    // Below the logger's resolution (`signal::resolution`) a zero is no finding, however
    // narrow its interval (issue 17, point 6: −0.0028 mm on a 0.01 mm slider channel).
    if (ci[0] > 0.0 || ci[1] < 0.0) && v.abs() >= resolution {
        let mut params = serde_json::Map::new();
        params.insert(format!("offset_{unit}"), serde_json::json!(v));
        params.insert(format!("offset_{unit}_ci95"), serde_json::json!(ci));
        Some(EffectResult {
            name: "sensor_offset".into(),
            params,
        })
    } else {
        None
    }
}

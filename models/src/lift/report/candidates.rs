//! The vocabulary's candidates as `report::fit_lift_trace` tries them: one refit each
//! (`lift::effects`), its contract name and parameters.

use super::super::dynamics::LiftModel;
use super::super::identify::{LiftFit, LiftFitError, LiftFitOptions, LiftTrace};

/// A candidate that passed, with its held-out test.
pub(super) struct Named {
    pub(super) found: Found,
    pub(super) hold_after: super::super::holdout::Holdout,
}

/// An effect a candidate's refit found: its contract name and `params`, the fit and the
/// options it was fitted with (for its held-out test).
pub(super) struct Found {
    pub(super) name: &'static str,
    /// The refit's residual RMS over the noise (`lift::residual::diagnose`).
    pub(super) excess_ratio: f64,
    pub(super) params: Vec<(&'static str, serde_json::Value)>,
    pub(super) fit: LiftFit,
    pub(super) opts: LiftFitOptions,
}

/// Try one candidate of the vocabulary on a lift whose plain fit `base` left a model error.
pub(super) fn try_candidate(
    candidate: Candidate,
    model: &LiftModel,
    trace: &LiftTrace,
    base: &LiftFit,
    opts: &LiftFitOptions,
) -> Result<Option<Found>, LiftFitError> {
    use super::super::effects as fx;
    use serde_json::json;
    Ok(match candidate {
        Candidate::Drag => fx::try_quadratic_drag(model, trace, base, opts)?.map(|f| Found {
            name: "quadratic_drag",
            params: vec![
                ("c_a_ns2_per_m2", json!(f.c_a_ns2_per_m2)),
                ("c_a_ns2_per_m2_ci95", json!(f.c_a_ci95)),
            ],
            excess_ratio: f.excess_ratio,
            fit: f.fit,
            opts: fx::drag_options(opts),
        }),
        Candidate::Delay => fx::try_sensor_delay(model, trace, base, opts)?.map(|f| Found {
            name: "sensor_delay",
            params: vec![
                ("delay_s", json!(f.delay_s)),
                ("delay_s_ci95", json!(f.delay_ci95_s)),
            ],
            excess_ratio: f.excess_ratio,
            fit: f.fit,
            opts: fx::delay_options(opts),
        }),
        Candidate::Offset => fx::try_sensor_offset(model, trace, base, opts)?.map(|f| Found {
            name: "sensor_offset",
            params: vec![
                ("offset_m", json!(f.offset_m)),
                ("offset_m_ci95", json!(f.offset_ci95_m)),
            ],
            excess_ratio: f.excess_ratio,
            fit: f.fit,
            opts: fx::offset_options(opts),
        }),
        Candidate::Stribeck => fx::try_stribeck(model, trace, base, opts)?.map(|f| Found {
            name: "stribeck",
            params: vec![
                // A lift cannot tell the lower arm's pins apart (their dry friction is one
                // combination, `lift::attribution`): measured, a Stribeck at J1 is named as
                // well, fitted at J3.
                ("joint", json!(fx::STRIBECK_JOINTS)),
                ("fitted_at", json!(f.joint.name())),
                ("ratio", json!(f.ratio)),
                ("ratio_ci95", json!(f.ratio_ci95)),
                ("stribeck_speed_rad_s", json!(f.speed_rad_s)),
                ("stribeck_speed_rad_s_ci95", json!(f.speed_ci95_rad_s)),
            ],
            excess_ratio: f.excess_ratio,
            fit: f.fit,
            opts: fx::stribeck_options(opts),
        }),
        Candidate::Compliance => {
            fx::try_drive_compliance(model, trace, base, opts)?.map(|f| Found {
                name: "drive_compliance",
                params: vec![
                    ("inertia_kgm2", json!(f.inertia_kgm2)),
                    ("inertia_kgm2_ci95", json!(f.inertia_ci95_kgm2)),
                    ("stiffness_nm_per_rad", json!(f.stiffness_nm_per_rad)),
                    (
                        "stiffness_nm_per_rad_ci95",
                        json!(f.stiffness_ci95_nm_per_rad),
                    ),
                    ("damping_nms_per_rad", json!(f.damping_nms_per_rad)),
                    (
                        "damping_nms_per_rad_ci95",
                        json!(f.damping_ci95_nms_per_rad),
                    ),
                ],
                excess_ratio: f.excess_ratio,
                fit: f.fit,
                opts: fx::compliance_options(opts),
            })
        }
    })
}

/// The vocabulary's lift effects (`lift::effects`).
#[derive(Debug, Clone, Copy)]
pub(super) enum Candidate {
    Drag,
    Delay,
    Offset,
    Stribeck,
    Compliance,
}

/// A passing candidate whose refit leaves its residual within this ratio to the noise ends the
/// search. Measured (`examples/lift_effects_probe`): right effects leave 0.71–0.88 at the
/// stand's noise and 0.99–1.10 at twice it; a wrong one that passed the margins, 1.44–1.71
/// (`quadratic_drag` on a −10 mm H offset).
pub(super) const STOP_RATIO: f64 = 1.15;

impl Candidate {
    /// Its contract name.
    pub(super) fn name(self) -> &'static str {
        match self {
            Candidate::Drag => "quadratic_drag",
            Candidate::Delay => "sensor_delay",
            Candidate::Offset => "sensor_offset",
            Candidate::Stribeck => "stribeck",
            Candidate::Compliance => "drive_compliance",
        }
    }
    pub(super) const ALL: [Candidate; 5] = [
        Candidate::Drag,
        Candidate::Delay,
        Candidate::Offset,
        Candidate::Stribeck,
        Candidate::Compliance,
    ];
}

use super::*;
use crate::lift::geometry::builtin_160ec;
use crate::lift::protocol::{LiftProtocol, record};
use crate::lift::sensors::LiftSensorNoise;

/// A lift with a Stribeck excess of 0.1 at J3 (the effects probe's `stribeck:0.1`, seed 0):
/// the plain model's fit leaves 2.2 mm. With the floor measured in the residual's own scale
/// (s² = 2·cost/m, uncapped), a rejected step early in the whole-trace fit, when the misfit
/// was large, looked "within 3 sd" and the fit stopped at 60 mm.
#[test]
fn the_noise_floor_never_stops_a_fit_far_from_its_minimum() {
    let g = builtin_160ec();
    let base = LiftModel::new(g);
    let mut m = base.clone();
    m.stribeck_excess[RevJoint::J3.index()] = 0.1;
    let protocol = LiftProtocol::raise_and_lower(&base, g).unwrap();
    let clean = record(&m, &protocol, &SimOptions::default()).unwrap();
    let rec = LiftSensorNoise::realistic().apply(&clean, 7000);
    let trace = rec.trace();
    let fit = fit_map(&base, &[trace], &LiftFitOptions::default()).unwrap();
    assert!(
        fit.rmse_m[0] < 4e-3,
        "plain fit stopped at {:.1} mm ({:?})",
        fit.rmse_m[0] * 1e3,
        fit.termination
    );
}

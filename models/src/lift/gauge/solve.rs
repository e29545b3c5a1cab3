//! The gauge's readings predicted by the statics: exactly ([`predicted_forces_n`], the
//! characteristic's solver) or near a known solution (the fit's fast path, warm-started).
//!
//! [`super::super::static_force::strip_force_n`] finds α for each trial force by a 64-point
//! scan and bisection; a fit evaluates every reading some hundred times with μ close to where it
//! was, so here α and F are found by the secant method from the baseline's solution of the same
//! reading, falling back to the exact solver whenever the secant fails or leaves the range.

use super::super::dynamics::{DynamicsError, LiftModel};
use super::super::static_force::{DriveLine, StaticForceError, strip_force_n};
use super::super::statics::{
    StaticFriction, StaticsError, alpha_at_height, static_h_m, static_point,
};
use super::{GaugeError, GaugeRecord};

/// One reading's solution: the lower-arm angle and the strip force, where a search starts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Warm {
    pub alpha_rad: f64,
    pub force_n: f64,
}

/// The gauge readings of `record`'s heights and branches predicted for `model` driven by `drive`
/// (no noise, no gauge effect), by the characteristic's exact solver.
pub fn predicted_forces_n(
    model: &LiftModel,
    alpha_range_rad: (f64, f64),
    drive: &DriveLine,
    record: &GaugeRecord,
) -> Result<Vec<f64>, GaugeError> {
    Ok(warm_starts(model, alpha_range_rad, drive, record)?
        .iter()
        .map(|w| w.force_n)
        .collect())
}

/// Every reading's exact solution for `model` (the fit's starts).
pub(crate) fn warm_starts(
    model: &LiftModel,
    alpha_range_rad: (f64, f64),
    drive: &DriveLine,
    record: &GaugeRecord,
) -> Result<Vec<Warm>, GaugeError> {
    record
        .heights_m
        .iter()
        .enumerate()
        .map(|(k, &h)| {
            let t = drive.torque_nm(h);
            let f = strip_force_n(model, alpha_range_rad, h, t, record.direction(k))?;
            let a = alpha_at_height(model, h, f, alpha_range_rad)
                .map_err(|e| GaugeError::Model(e.to_string()))?;
            Ok(Warm {
                alpha_rad: a,
                force_n: f,
            })
        })
        .collect()
}

/// The readings of `record` predicted for `model` driven by `drive`, each searched from its
/// `warm` solution; the exact solver where the search fails.
pub(crate) fn forces_near(
    model: &LiftModel,
    alpha_range_rad: (f64, f64),
    drive: &DriveLine,
    record: &GaugeRecord,
    warm: &[Warm],
) -> Result<Vec<f64>, StaticForceError> {
    record
        .heights_m
        .iter()
        .zip(warm)
        .enumerate()
        .map(|(k, (&h, w))| {
            let t = drive.torque_nm(h);
            let dir = record.direction(k);
            force_near(model, alpha_range_rad, h, t, dir, *w)
                .or_else(|_| strip_force_n(model, alpha_range_rad, h, t, dir))
        })
        .collect()
}

/// The strip force at `strip_height_m` under `drive_torque_nm`, by the secant method in F from
/// `warm` (what [`strip_force_n`] solves, to the same tolerance).
fn force_near(
    model: &LiftModel,
    alpha_range_rad: (f64, f64),
    strip_height_m: f64,
    drive_torque_nm: f64,
    friction: StaticFriction,
    warm: Warm,
) -> Result<f64, StaticForceError> {
    let mut alpha = warm.alpha_rad;
    let mut residual = |f_n: f64| -> Result<f64, StaticForceError> {
        alpha = alpha_near(model, strip_height_m, f_n, alpha, alpha_range_rad)?;
        Ok(static_point(model, alpha, f_n, friction)?.drive_torque_nm - drive_torque_nm)
    };
    let (mut f0, mut f1) = (warm.force_n, warm.force_n + 1.0);
    let (mut r0, mut r1) = (residual(f0)?, residual(f1)?);
    for _ in 0..40 {
        if r1 == 0.0 {
            return Ok(f1);
        }
        let slope = (r1 - r0) / (f1 - f0);
        if !slope.is_finite() || slope == 0.0 {
            break;
        }
        let f2 = f1 - r1 / slope;
        if !f2.is_finite() {
            break;
        }
        (f0, r0) = (f1, r1);
        f1 = f2;
        r1 = residual(f1)?;
        if (f1 - f0).abs() < 1e-9 * (1.0 + f1.abs()) {
            return Ok(f1);
        }
    }
    Err(StaticForceError::NotConverged { strip_height_m })
}

/// Strip heights closer than this to the target count as on it, m (a picometre: far below any
/// force the gauge resolves, dF/dH being tens of N/m).
const HEIGHT_TOL_M: f64 = 1e-12;

/// α with the strip at `strip_height_m` under `strip_load_n`, by the secant method from `a0`;
/// the exact scan ([`alpha_at_height`]) where it fails or leaves `alpha_range_rad`.
fn alpha_near(
    model: &LiftModel,
    strip_height_m: f64,
    strip_load_n: f64,
    a0: f64,
    alpha_range_rad: (f64, f64),
) -> Result<f64, StaticsError> {
    let g = |a: f64| -> Result<f64, StaticsError> {
        let pose = model.linkage.pose(a).map_err(DynamicsError::from)?;
        let h = static_h_m(model, &pose, strip_load_n);
        Ok(model.linkage.head(&pose, h, 0.0, 0.0).strip.y - strip_height_m)
    };
    let (lo, hi) = alpha_range_rad;
    if (lo..=hi).contains(&a0) {
        let (mut a_prev, mut a) = (a0, (a0 + 1e-6).min(hi));
        if a == a_prev {
            a = a0 - 1e-6;
        }
        let (mut g_prev, mut g_a) = (g(a_prev)?, g(a)?);
        for _ in 0..30 {
            if g_a.abs() <= HEIGHT_TOL_M {
                return Ok(a);
            }
            let slope = (g_a - g_prev) / (a - a_prev);
            if !slope.is_finite() || slope == 0.0 {
                break;
            }
            let next = a - g_a / slope;
            if !(lo..=hi).contains(&next) {
                break;
            }
            (a_prev, g_prev) = (a, g_a);
            a = next;
            g_a = g(a)?;
        }
    }
    alpha_at_height(model, strip_height_m, strip_load_n, alpha_range_rad)
}

//! Statics of the complete pantograph: the drive torque that holds (or just moves) it at a
//! given lower-arm angle and strip load, the equilibrium angle for a torque, α for a height.
//!
//! The head rests at its frictionless slide equilibrium (J8's dry friction could hold it
//! anywhere in a ±0.5 mm band, which no lift statics resolves). With friction, the dry torques
//! take the exact sign of the impending motion and their normal forces are the reactions, which
//! depend on them: solved by the same fixed-point iteration as the dynamics.

use super::dynamics::{DynamicsError, LiftModel, Loads, State, sign0};
use super::kinematics::LinkagePose;
use super::topology::{BodyId, N_REV, RevJoint};

/// Which friction acts in a static state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StaticFriction {
    /// None: the balance of gravity, drive and loads alone.
    None,
    /// Impending raise: the torque needed to start raising (dry friction opposes it).
    Raising,
    /// Impending lowering: the least torque that still holds the pantograph.
    Lowering,
}

/// A static state of the pantograph.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StaticPoint {
    pub alpha_rad: f64,
    pub h_m: f64,
    pub strip_height_m: f64,
    pub drive_torque_nm: f64,
    /// Normal forces of the revolute joints (reaction magnitudes), N.
    pub normal_n: [f64; N_REV],
    /// Dry friction torques about each joint (opposing the impending motion), N·m.
    pub dry_torque_nm: [f64; N_REV],
}

/// Statics failed: no assembly, no convergence, or no equilibrium in the range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StaticsError {
    #[error(transparent)]
    Dynamics(#[from] DynamicsError),
    #[error("no static equilibrium for {what} inside alpha [{lo}, {hi}] rad")]
    NoEquilibrium { what: String, lo: f64, hi: f64 },
}

/// Head travel at rest under `strip_load_n` with the slide frictionless:
/// h = (preload + u·(m_head g) − load·u_y)/k.
pub fn static_h_m(model: &LiftModel, pose: &LinkagePose, strip_load_n: f64) -> f64 {
    let head = model.linkage.head(pose, 0.0, 0.0, 0.0);
    let mh = model.mass_kg[BodyId::Head.index()];
    (model.preload_n + head.u.dot(model.gravity * mh) - strip_load_n * head.u.y)
        / model.j9_stiffness_n_per_m()
}

/// The static state at `alpha_rad` under `strip_load_n`.
pub fn static_point(
    model: &LiftModel,
    alpha_rad: f64,
    strip_load_n: f64,
    friction: StaticFriction,
) -> Result<StaticPoint, StaticsError> {
    let pose = model.linkage.pose(alpha_rad).map_err(DynamicsError::from)?;
    let h_m = static_h_m(model, &pose, strip_load_n);
    let s = State {
        alpha_rad,
        h_m,
        ..Default::default()
    };
    let head = model.linkage.head(&pose, h_m, 0.0, 0.0);
    let loads = Loads {
        drive_torque_nm: 0.0,
        strip_load_n,
    };
    // At rest the slide carries no friction; the drive torque does not enter any reaction (it
    // is a couple on the lower arm reacted by the frame).
    let k = model.kane(&pose, &head, &s, &loads);
    let direction = match friction {
        StaticFriction::None => 0.0,
        StaticFriction::Raising => 1.0,
        StaticFriction::Lowering => -1.0,
    };
    let mut rate = [0.0; N_REV];
    let mut sgn = [0.0; N_REV];
    for j in RevJoint::ALL {
        let i = j.index();
        rate[i] = pose.rel_rate(j);
        if j != RevJoint::J6 {
            sgn[i] = sign0(rate[i] * direction);
        }
    }
    let mut torque = [0.0; N_REV];
    let mut normal = [0.0; N_REV];
    for _ in 0..60 {
        let r = model.reactions(&pose, &head, 0.0, 0.0, 0.0, &torque, &loads, k.f_axial);
        let mut change: f64 = 0.0;
        for i in 0..N_REV {
            normal[i] = r.force_n[i].norm();
            let t = model.friction.dry_mu[i] * model.pin_radius_m[i] * normal[i] * sgn[i];
            change = change.max((t - torque[i]).abs());
            torque[i] = t;
        }
        if change <= 1e-13 * (1.0 + normal.iter().fold(0.0f64, |a, b| a.max(*b))) {
            // T·1 + b_a − Σ T_j r_j = 0 at rest.
            let drive_torque_nm = -k.b_a + (0..N_REV).map(|i| torque[i] * rate[i]).sum::<f64>();
            return Ok(StaticPoint {
                alpha_rad,
                h_m,
                strip_height_m: head.strip.y,
                drive_torque_nm,
                normal_n: normal,
                dry_torque_nm: torque,
            });
        }
    }
    Err(DynamicsError::FrictionNotConverged { alpha_rad }.into())
}

/// Find α in [lo, hi] with f(α) = 0: a scan for the first sign change, then bisection to the
/// last bit (f is smooth; bisection keeps it simple and certain).
pub(super) fn root_in_range(
    lo: f64,
    hi: f64,
    what: &str,
    mut f: impl FnMut(f64) -> Result<f64, StaticsError>,
) -> Result<f64, StaticsError> {
    let n = 64;
    let mut a = lo;
    let mut fa = f(a)?;
    for k in 1..=n {
        let b = lo + (hi - lo) * k as f64 / n as f64;
        let fb = f(b)?;
        if fa == 0.0 {
            return Ok(a);
        }
        if fa * fb <= 0.0 {
            let (mut x0, mut x1, mut f0) = (a, b, fa);
            for _ in 0..200 {
                let m = 0.5 * (x0 + x1);
                if m <= x0 || m >= x1 {
                    break;
                }
                let fm = f(m)?;
                if fm == 0.0 {
                    return Ok(m);
                }
                if f0 * fm < 0.0 {
                    x1 = m;
                } else {
                    (x0, f0) = (m, fm);
                }
            }
            return Ok(0.5 * (x0 + x1));
        }
        (a, fa) = (b, fb);
    }
    Err(StaticsError::NoEquilibrium {
        what: what.to_string(),
        lo,
        hi,
    })
}

/// The lower-arm angle at which `drive_torque_nm` holds the pantograph under `strip_load_n`
/// (first solution from the folded end of `alpha_range`).
pub fn equilibrium_alpha(
    model: &LiftModel,
    drive_torque_nm: f64,
    strip_load_n: f64,
    friction: StaticFriction,
    alpha_range: (f64, f64),
) -> Result<f64, StaticsError> {
    root_in_range(
        alpha_range.0,
        alpha_range.1,
        &format!("T = {drive_torque_nm} N·m, strip load {strip_load_n} N"),
        |a| Ok(static_point(model, a, strip_load_n, friction)?.drive_torque_nm - drive_torque_nm),
    )
}

/// The lower-arm angle at which the strip stands at `strip_height_m` under `strip_load_n`
/// (head at its static travel).
pub fn alpha_at_height(
    model: &LiftModel,
    strip_height_m: f64,
    strip_load_n: f64,
    alpha_range: (f64, f64),
) -> Result<f64, StaticsError> {
    root_in_range(
        alpha_range.0,
        alpha_range.1,
        &format!("H = {strip_height_m} m"),
        |a| {
            let pose = model.linkage.pose(a).map_err(DynamicsError::from)?;
            let h = static_h_m(model, &pose, strip_load_n);
            Ok(model.linkage.head(&pose, h, 0.0, 0.0).strip.y - strip_height_m)
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lift::geometry::builtin_160ec;

    /// `[checks]`: the frictionless static torque passes through both lift-test states of the
    /// paper (1110 N·m at H = 1.04 m under 96.5 N; 986 N·m at H = 1.84 m under 89.5 N).
    #[test]
    fn static_torque_passes_through_the_lift_test_states() {
        let g = builtin_160ec();
        let m = LiftModel::new(g);
        let range = (g.alpha_min_rad, g.alpha_max_rad);
        let c = &g.checks;
        for (state, t_check, a_check, h_check) in [
            (
                g.lift_test.initial,
                c.t_eq_initial_nm,
                c.alpha_initial_rad,
                c.h_initial_m,
            ),
            (
                g.lift_test.final_,
                c.t_eq_final_nm,
                c.alpha_final_rad,
                c.h_final_m,
            ),
        ] {
            let load = state.strip_load_n();
            let a = alpha_at_height(&m, state.h_m, load, range).unwrap();
            let p = static_point(&m, a, load, StaticFriction::None).unwrap();
            eprintln!(
                "H {} m: alpha {a:.10} rad, h {:.4} mm, T_eq {:.6} N·m (paper {})",
                state.h_m,
                p.h_m * 1e3,
                p.drive_torque_nm,
                state.t_nm
            );
            assert!(
                (p.drive_torque_nm - t_check.unwrap()).abs() < 0.1,
                "{}",
                p.drive_torque_nm
            );
            assert!((a - a_check.unwrap()).abs() < 1e-7, "alpha {a}");
            // `[checks]` rounds h to 10⁻⁸ m.
            assert!((p.h_m - h_check.unwrap()).abs() < 1e-8, "h {}", p.h_m);
            // And back: the equilibrium angle of that torque.
            let a2 = equilibrium_alpha(&m, p.drive_torque_nm, load, StaticFriction::None, range)
                .unwrap();
            assert!((a2 - a).abs() < 1e-9, "{a2} vs {a}");
            // Friction: a dead band around the frictionless torque, raising above lowering.
            let up = static_point(&m, a, load, StaticFriction::Raising).unwrap();
            let down = static_point(&m, a, load, StaticFriction::Lowering).unwrap();
            eprintln!(
                "  dead band: raise {:.2} N·m, lower {:.2} N·m (half-width {:.2} N·m)",
                up.drive_torque_nm,
                down.drive_torque_nm,
                0.5 * (up.drive_torque_nm - down.drive_torque_nm)
            );
            assert!(
                up.drive_torque_nm > p.drive_torque_nm && down.drive_torque_nm < p.drive_torque_nm
            );
        }
    }
}

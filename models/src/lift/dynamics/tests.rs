use super::*;
use crate::lift::geometry::builtin_160ec;

fn model() -> LiftModel {
    LiftModel::new(builtin_160ec())
}

#[test]
fn reactions_satisfy_the_unused_equations_with_friction() {
    let m = model();
    for (a, ad, h, hd) in [
        (0.2, 0.4, -0.005, 0.03),
        (0.45, -0.7, 0.002, -0.05),
        (0.0, 0.0, 0.0, 0.0),
    ] {
        let pose = m.linkage.pose(a).unwrap();
        let s = State {
            alpha_rad: a,
            h_m: h,
            alpha_dot_rad_s: ad,
            h_dot_m_s: hd,
        };
        let loads = Loads {
            drive_torque_nm: 1050.0,
            strip_load_n: 90.0,
        };
        let e = m.eval(&pose, &s, &loads).unwrap();
        let (r_moment, r_slide) = m.unused_equations(&pose, &s, &loads, &e);
        assert!(
            r_moment.abs() < 1e-9,
            "lower-arm moment residual {r_moment}"
        );
        assert!(r_slide.abs() < 1e-9, "slide residual {r_slide}");
        assert!(e.iterations < 15, "{} iterations", e.iterations);
    }
}

/// The drive torque's power equals the rate of change of energy plus friction's: checks
/// the mass matrix and the generalised forces against the energy function.
#[test]
fn power_balance_holds() {
    let m = model();
    let s = State {
        alpha_rad: 0.3,
        h_m: -0.004,
        alpha_dot_rad_s: 0.5,
        h_dot_m_s: 0.02,
    };
    let loads = Loads {
        drive_torque_nm: 1000.0,
        strip_load_n: 0.0,
    };
    let pose = m.linkage.pose(s.alpha_rad).unwrap();
    let e = m.eval(&pose, &s, &loads).unwrap();
    let dt = 1e-6;
    let step = |k: f64| {
        let st = State {
            alpha_rad: s.alpha_rad
                + k * dt * s.alpha_dot_rad_s
                + 0.5 * (k * dt).powi(2) * e.alpha_ddot_rad_s2,
            h_m: s.h_m + k * dt * s.h_dot_m_s + 0.5 * (k * dt).powi(2) * e.h_ddot_m_s2,
            alpha_dot_rad_s: s.alpha_dot_rad_s + k * dt * e.alpha_ddot_rad_s2,
            h_dot_m_s: s.h_dot_m_s + k * dt * e.h_ddot_m_s2,
        };
        m.energy_j(&m.linkage.pose(st.alpha_rad).unwrap(), &st)
    };
    let de_dt = (step(1.0) - step(-1.0)) / (2.0 * dt);
    let mut loss = (e.j8_viscous_n + e.j8_dry_n + e.j9_damping_n) * s.h_dot_m_s;
    for j in RevJoint::ALL {
        let (v, d) = e.revolute_power_w(j);
        loss += v + d;
    }
    let drive = loads.drive_torque_nm * s.alpha_dot_rad_s;
    assert!(
        (de_dt - (drive - loss)).abs() < 1e-5 * drive.abs(),
        "dE/dt {de_dt} vs drive {drive} − loss {loss}"
    );
}

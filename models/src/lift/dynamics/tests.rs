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

/// `eval_with_kane` hands the response the Kane it solved: at moving, resting and
/// head-bouncing states (a Stribeck excess on J3, head drag on) the Kane, the evaluation and
/// Φ are the same to the bit as assembled afresh (`kane`, `eval_with_head`), so the
/// sensitivities a fit reads are those of before.
#[test]
fn the_kane_handed_to_the_response_is_the_one_it_would_assemble() {
    let mut m = model();
    m.stribeck_excess[RevJoint::J3.index()] = 0.3;
    m.head_drag_ns2_per_m2 = 3.0;
    for (a, ad, h, hd) in [
        (0.2, 0.4, -0.005, 0.03),
        (0.45, -0.7, 0.002, -0.05),
        (0.3, 1e-5, 0.0, -1e-4),
    ] {
        let pose = m.linkage.pose(a).unwrap();
        let s = State {
            alpha_rad: a,
            h_m: h,
            alpha_dot_rad_s: ad,
            h_dot_m_s: hd,
        };
        let head = m.linkage.head(&pose, h, ad, hd);
        let loads = Loads {
            drive_torque_nm: 1050.0,
            strip_load_n: 90.0,
        };
        let (e, k) = m.eval_with_kane(&pose, &head, &s, &loads, None).unwrap();
        let fresh = m.kane(&pose, &head, &s, &loads);
        let bits = |k: &Kane| [k.m_aa, k.m_ah, k.m_hh, k.b_a, k.b_h, k.f_axial].map(f64::to_bits);
        assert_eq!(bits(&k), bits(&fresh));
        let e0 = m.eval_with_head(&pose, &head, &s, &loads, None).unwrap();
        assert_eq!(
            e.alpha_ddot_rad_s2.to_bits(),
            e0.alpha_ddot_rad_s2.to_bits()
        );
        assert_eq!(e.h_ddot_m_s2.to_bits(), e0.h_ddot_m_s2.to_bits());
        let phi = m.response(&pose, &head, &s, &loads, &e, &k).unwrap();
        let phi0 = m.response(&pose, &head, &s, &loads, &e0, &fresh).unwrap();
        assert_eq!(
            phi.as_flattened()
                .iter()
                .map(|v| v.to_bits())
                .collect::<Vec<_>>(),
            phi0.as_flattened()
                .iter()
                .map(|v| v.to_bits())
                .collect::<Vec<_>>()
        );
        assert!(phi.as_flattened().iter().all(|v| v.is_finite()));
    }
}

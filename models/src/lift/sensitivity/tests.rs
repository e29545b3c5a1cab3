use super::*;
use crate::lift::geometry::builtin_160ec;
use crate::lift::simulate::simulate;
use crate::lift::topology::RevJoint;

/// A short lift: the first second of the reference protocol, 250 Hz.
fn short_lift() -> (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>) {
    let n = 301;
    let t: Vec<f64> = (0..n).map(|k| -0.2 + k as f64 * 0.004).collect();
    let tq = t
        .iter()
        .map(|&t| {
            if t < 0.0 {
                1110.0
            } else {
                986.0 + 124.0 * (-t / 0.8f64).exp() - 40.0 * t
            }
        })
        .collect();
    let fs = t.iter().map(|&t| 18.0 + 30.0 * t.max(0.0)).collect();
    let fm = t
        .iter()
        .map(|&t| if t < 0.0 { 78.5 } else { 0.0 })
        .collect();
    (t, tq, fs, fm)
}

/// At the fit's tolerance (`LiftFitOptions::default().sim`: rtol 10⁻⁵, error control on
/// the state only, the rates' atol ×10, steps ≤ 50 ms) over a whole raise-and-lower test:
/// H within 0.2 mm (1/5 of the 1 mm H noise; measured 8.9·10⁻⁵ m, DOPRI5 at rtol 10⁻⁵
/// 1.1·10⁻⁴)
/// of a tight run of the same model and inputs, and every sensitivity within 2 % of its
/// largest value of the tightly integrated one (measured: ≤ 5·10⁻⁵ but J8's, the
/// smallest, 1.2 %): a Jacobian off by 2 % moves a posterior sd by at most 2 %.
#[test]
fn at_the_fit_tolerance_h_and_sensitivities_are_close_to_tight_runs() {
    use crate::lift::identify::LiftFitOptions;
    use crate::lift::protocol::{LiftProtocol, record};
    let g = builtin_160ec();
    let model = LiftModel::new(g);
    let tight = SimOptions::default();
    let protocol = LiftProtocol::raise_and_lower(&model, g).unwrap();
    let rec = record(&model, &protocol, &tight).unwrap();
    let inputs = rec.inputs();
    let params = LiftParam::all();
    let fit_opts = LiftFitOptions::default().sim;
    let fit = simulate_sensitivities(&model, &inputs, &params, 0.0, &fit_opts).unwrap();
    // The reference runs on the same sampled inputs (the record's H came from the
    // protocol's continuous torque: 0.1–0.3 mm apart from any run on the samples).
    let s0 = initial_state(&model, &inputs, &tight).unwrap();
    let exact = simulate(&model, &inputs, s0, &tight).unwrap();
    let h_err = fit
        .strip_height_m
        .iter()
        .zip(&exact.strip_height_m)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    eprintln!("H: worst {h_err:.2e} m, {} steps", fit.steps);
    // The worst is at the end of the lowering, where the open-loop drift has gathered
    // every local error.
    assert!(h_err < 0.2e-3, "H off by {h_err} m");
    let sens_tight = SimOptions {
        rtol: 1e-9,
        atol: 1e-11,
        ..tight
    };
    let reference = simulate_sensitivities(&model, &inputs, &params, 0.0, &sens_tight).unwrap();
    let p = params.len();
    for (i, prm) in params.iter().enumerate() {
        let (mut worst, mut scale): (f64, f64) = (0.0, 0.0);
        for k in 0..rec.t_s.len() {
            let (a, b) = (fit.d_height[k * p + i], reference.d_height[k * p + i]);
            worst = worst.max((a - b).abs());
            scale = scale.max(b.abs());
        }
        eprintln!(
            "{}.{}: {:.1e} of {scale:.2e}",
            prm.joint(),
            prm.kind(),
            worst / scale
        );
        assert!(worst <= 2e-2 * scale, "{prm:?}: {worst} of {scale}");
    }
}

/// With `quadratic_drag` on (c_a = 3 N/(m/s)², so its state dependence enters every
/// column) and c_a among the parameters.
#[test]
fn sensitivities_match_finite_differences_of_whole_runs() {
    sensitivities_match_finite_differences(false);
}

/// The same with a compliant drive (`drive_compliance`: six state components, its three
/// parameters among the fitted, the offset acting on the drive side).
#[test]
fn sensitivities_with_a_compliant_drive_match_finite_differences() {
    sensitivities_match_finite_differences(true);
}

fn sensitivities_match_finite_differences(compliant: bool) {
    let mut base = LiftModel::new(builtin_160ec());
    base.head_drag_ns2_per_m2 = 3.0;
    base.stribeck_excess[RevJoint::J3.index()] = 0.2;
    if compliant {
        base.drive_compliance = Some(crate::lift::dynamics::DriveCompliance {
            stiffness_nm_per_rad: 3000.0,
            damping_nms_per_rad: 15.0,
            inertia_kgm2: 0.8,
        });
    }
    let (t, tq, fs, fm) = short_lift();
    let inputs = LiftInputs {
        t_s: &t,
        torque_nm: &tq,
        fs_n: &fs,
        fm_n: &fm,
    };
    let opts = SimOptions {
        rtol: 1e-11,
        atol: 1e-13,
        ..Default::default()
    };
    let mut params = LiftParam::all();
    params.extend([
        LiftParam::HeadDrag,
        LiftParam::StribeckExcess(RevJoint::J3),
        LiftParam::StribeckSpeed(RevJoint::J3),
    ]);
    if compliant {
        params.extend([
            LiftParam::DriveInertia,
            LiftParam::DriveStiffness,
            LiftParam::DriveDamping,
        ]);
    }
    let offset = 2.0;
    // Sensitivities are error-controlled with the state: 10⁻⁹ suffices against 10⁻⁴.
    let sens_opts = SimOptions {
        rtol: 1e-9,
        atol: 1e-11,
        ..opts
    };
    let sens = simulate_sensitivities(&base, &inputs, &params, offset, &sens_opts).unwrap();
    let p = params.len();
    for (i, prm) in params.iter().enumerate() {
        let v = prm.get(&base, offset);
        // 1 % of the value (of 0.1 for the small ones); the Stribeck speed (0.05 rad/s)
        // at 1 % of itself, where the Gaussian's curvature keeps the difference's error
        // under the tolerance.
        let d = if matches!(prm, LiftParam::StribeckSpeed(_)) {
            1e-2 * v.abs()
        } else {
            1e-2 * v.abs().max(1e-1)
        };
        let run_at = |x: f64| {
            let (mut m, mut o) = (base.clone(), offset);
            prm.set(&mut m, &mut o, x);
            let so = SimOptions {
                torque_offset_nm: o,
                ..opts
            };
            let s0 = initial_state(&m, &inputs, &so).unwrap();
            simulate(&m, &inputs, s0, &so).unwrap().strip_height_m
        };
        let (hp, hm) = (run_at(v + d), run_at(v - d));
        let (mut worst, mut scale): (f64, f64) = (0.0, 0.0);
        for k in 0..t.len() {
            let fd = (hp[k] - hm[k]) / (2.0 * d);
            let an = sens.d_height[k * p + i];
            worst = worst.max((fd - an).abs());
            scale = scale.max(fd.abs());
        }
        eprintln!(
            "{}.{}: max |dH/dθ| {scale:.3e}, max error {worst:.1e}",
            prm.joint(),
            prm.kind()
        );
        assert!(
            worst <= 1e-4 * scale + 1e-9,
            "{prm:?}: error {worst} of {scale}"
        );
    }
}

/// The stepper's split (a step's stages computed for the state first, their sensitivities
/// only once the state's error accepts the step) changes no number: at the fit's tolerance,
/// where rejected steps are many, a raise and lower with every parameter and the drag's (on a
/// model with drag, rigid or with a compliant drive, recorded by itself) gives the same H,
/// sensitivities, steps and evaluations to the bit split or not; and a run that fails (the
/// drag model on a drag-free record: a step-size underflow near the end of the lowering)
/// fails the same way after reading out the same values.
#[test]
fn the_split_stepper_gives_every_number_to_the_bit() {
    use crate::lift::identify::LiftFitOptions;
    use crate::lift::protocol::{LiftProtocol, record};
    let g = builtin_160ec();
    let opts = LiftFitOptions::default().sim;
    let plain = LiftModel::new(g);
    for (compliant, recorded_with_drag) in [(false, true), (true, true), (false, false)] {
        let mut model = plain.clone();
        model.head_drag_ns2_per_m2 = 3.0;
        let mut params = LiftParam::all();
        params.push(LiftParam::HeadDrag);
        if compliant {
            model.drive_compliance = Some(crate::lift::dynamics::DriveCompliance {
                stiffness_nm_per_rad: 3000.0,
                damping_nms_per_rad: 15.0,
                inertia_kgm2: 0.8,
            });
            params.extend([LiftParam::DriveStiffness, LiftParam::DriveDamping]);
        }
        let recorder = if recorded_with_drag { &model } else { &plain };
        let protocol = LiftProtocol::raise_and_lower(recorder, g).unwrap();
        let rec = record(recorder, &protocol, &SimOptions::default()).unwrap();
        let inputs = rec.inputs();
        let runs: Vec<(String, SensitivityRun)> = [false, true]
            .into_iter()
            .map(|split| {
                let mut ws = SensWorkspace::default();
                let r = sensitivities_in(&mut ws, &model, &inputs, &params, 0.0, &opts, split)
                    .map(|_| ())
                    .map_err(|e| format!("{e:?}"));
                (format!("{r:?}"), ws.run)
            })
            .collect();
        let case = format!("compliant {compliant}, recorded with drag {recorded_with_drag}");
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        let ((r_whole, whole), (r_split, split)) = (&runs[0], &runs[1]);
        assert_eq!(r_whole, r_split, "{case}");
        assert_eq!(r_whole == "Ok(())", recorded_with_drag, "{case}: {r_whole}");
        assert_eq!(
            bits(&whole.strip_height_m),
            bits(&split.strip_height_m),
            "{case}"
        );
        assert_eq!(bits(&whole.d_height), bits(&split.d_height), "{case}");
        assert!(whole.strip_height_m.len() > 100, "{case}");
        if recorded_with_drag {
            assert_eq!(
                (whole.steps, whole.rhs_evaluations),
                (split.steps, split.rhs_evaluations),
                "{case}"
            );
            // Rejected steps happened (else the split was not exercised): an accepted step
            // costs 4 evaluations, a rejected one 3, a restart at a breakpoint 1.
            eprintln!(
                "{case}: {} evaluations, {} steps",
                whole.rhs_evaluations, whole.steps
            );
            assert!(whole.rhs_evaluations > 4 * whole.steps + 10, "{case}");
        }
    }
}

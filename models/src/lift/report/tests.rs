use super::*;
use crate::lift::geometry::builtin_160ec;
use crate::lift::protocol::{LiftProtocol, record};

/// The reference protocol on the Table 4 model: every joint is reported, J1…J9, uninformed
/// ones at baseline and `unknown`, informed ones `ok`; nothing is flagged.
#[test]
fn baseline_lift_maps_to_every_joint_ok_or_unknown() {
    let g = builtin_160ec();
    let m = LiftModel::new(g);
    let rec = record(
        &m,
        &LiftProtocol::reference(g),
        &crate::lift::simulate::SimOptions::default(),
    )
    .unwrap();
    let ch = LiftChannels::from(&rec);
    let rep = fit_lift_trace(&ch, &DriftThresholds::default(), "ref").unwrap();
    let r = &rep.result;
    let names: Vec<&str> = r.joints.iter().map(|j| j.joint.as_str()).collect();
    assert_eq!(
        names[..10],
        ["J1", "J2", "J2'", "J3", "J4", "J5", "J6", "J7", "J8", "J9"]
    );
    // After them, each combination the lift informs (issue 15): J3 dry with J1's, which
    // the lift cannot tell apart; J3 is then not separately identified.
    assert_eq!(names[10..], ["J1+J3"], "{:?}", r.combinations);
    let c = &r.combinations[0];
    assert_eq!(c.label, "J1+J3 dry");
    let share: f64 = c.members.iter().map(|m| m.weight).sum();
    assert!((share - 1.0).abs() < 1e-9);
    for j in &r.joints {
        assert!(
            matches!(j.status, Status::Ok | Status::Unknown),
            "{}: {:?}",
            j.joint,
            j.status
        );
        for p in [&j.viscous, &j.dry] {
            if !p.identifiable {
                assert_eq!(p.status, Status::Unknown);
                assert_eq!(Some(p.value), p.baseline.or(Some(0.0)));
            }
            assert!(p.ci95[0] <= p.value && p.value <= p.ci95[1], "{}", j.joint);
        }
    }
    let j3 = r.joints.iter().find(|j| j.joint == "J3").unwrap();
    assert!(!j3.dry.identifiable && j3.dry.combination.as_deref() == Some("J1+J3 dry"));
    let both = r.joints.iter().find(|j| j.joint == "J1+J3").unwrap();
    assert!(both.identifiable && both.dry.identifiable && both.status == Status::Ok);
    assert_eq!(both.dry.baseline, Some(1.0));
    assert_eq!(r.rmse.unit, "m");
    assert!(r.rmse.value < 1e-4, "noise-free: {}", r.rmse.value);
    assert_eq!(rep.fitted_height_m.len(), rec.t_s.len());
    let json = serde_json::to_value(r).unwrap();
    assert_eq!(json["joints"][8]["viscous"]["unit"], "N·s/m");
}

/// Issue 18: a lift's H, Fs and Fm are held to the type's working heights and the strip
/// loads its drive can hold — 1e308 m, 1e308 N or −5 kN are refused naming the sample; the
/// simulated reference lift, every channel, lies inside.
#[test]
fn absurd_lift_channels_are_refused_naming_the_sample() {
    let g = builtin_160ec();
    let rec = record(
        &LiftModel::new(g),
        &LiftProtocol::reference(g),
        &crate::lift::simulate::SimOptions::default(),
    )
    .unwrap();
    let ch = LiftChannels::from(&rec);
    ch.check_limits().expect("the reference lift is plausible");
    let n = rec.t_s.len();
    let spoil = |v: &[f64], x: f64| {
        let mut v = v.to_vec();
        v[n / 2] = x;
        v
    };
    let h = spoil(&rec.strip_height_m, 1e308);
    let fs = spoil(&rec.fs_n, 1e308);
    let fm = spoil(&rec.fm_n, -5000.0);
    let t = spoil(&rec.torque_nm, -1.0);
    for (c, field) in [
        (
            LiftChannels {
                strip_height_m: &h,
                ..ch
            },
            "H_m",
        ),
        (LiftChannels { fs_n: &fs, ..ch }, "Fs_N"),
        (LiftChannels { fm_n: &fm, ..ch }, "Fm_N"),
        (
            LiftChannels {
                torque_nm: &t,
                ..ch
            },
            "T_Nm",
        ),
    ] {
        let (f, why) = c.check_limits().unwrap_err();
        assert_eq!(f, format!("channels.{field}[{}]", n / 2), "{why}");
    }
}

/// The candidates tried ahead (`candidates::tried_in_order`) reach the loop in its order, each
/// once, until it stops; their work is counted on the loop's thread before it judges them, and
/// the ones it never judged come back as spare, not counted.
#[test]
fn candidates_tried_ahead_are_judged_in_order_and_the_rest_is_spare() {
    use super::candidates::{Candidate, tried_in_order};
    use crate::lift::identify::work_on_this_thread;
    use std::ops::ControlFlow;
    // Each "refit" stands for work: one evaluation, as many steps as its place in ALL + 1.
    let place = |c: Candidate| {
        Candidate::ALL
            .iter()
            .position(|d| d.name() == c.name())
            .unwrap()
    };
    let try_one = |c: Candidate| {
        crate::lift::identify::count_on_this_thread(crate::lift::identify::FitWork {
            evaluations: 1,
            steps: place(c) + 1,
        });
        c.name()
    };
    let start = work_on_this_thread();
    let mut seen = Vec::new();
    let mut counted = Vec::new();
    let spare = tried_in_order(&Candidate::ALL, try_one, |c, r| {
        assert_eq!(c.name(), r);
        seen.push(r);
        counted.push((work_on_this_thread() - start).steps);
        Ok(if r == "sensor_offset" {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        })
    })
    .unwrap();
    assert_eq!(seen, ["quadratic_drag", "sensor_delay", "sensor_offset"]);
    // Counted as if run here one after the other: 1, 1 + 2, 1 + 2 + 3 steps.
    assert_eq!(counted, [1, 3, 6]);
    assert_eq!((work_on_this_thread() - start).steps, 6);
    for s in &spare {
        assert!(place(s.candidate) > 2, "{} is spare", s.candidate.name());
        assert_eq!(s.work.steps, place(s.candidate) + 1);
    }
    // An error from the loop ends it and is returned.
    let err = tried_in_order(
        &Candidate::ALL,
        |c| c.name(),
        |_, _| Err(LiftFitError::Failed("judged".into())),
    );
    assert!(err.is_err());
}

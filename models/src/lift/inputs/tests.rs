//! Tests of the input reconstruction: a known signal with a step under stated noise, clean
//! records unchanged, bad input named, and noisy-input lift fits that still flag a J3 drift.

use super::*;
use crate::contract::drift::Status;
use crate::lift::dynamics::LiftModel;
use crate::lift::geometry::builtin_160ec;
use crate::lift::identify::{LiftFitOptions, fit_map};
use crate::lift::protocol::{LiftProtocol, LiftRecord, record};
use crate::lift::sensitivity::LiftParam;
use crate::lift::sensors::LiftSensorNoise;
use crate::lift::simulate::SimOptions;
use crate::lift::topology::RevJoint;
use crate::numerics::noise::Noise;

/// 8 s at 500 Hz from t = −0.5 s, as the lift protocol samples.
fn times() -> Vec<f64> {
    (0..4000).map(|k| -0.5 + k as f64 / 500.0).collect()
}

/// A torque-like channel: a 1 Hz swing of 40 N·m on 1000 N·m, a 0.8 s decay of 120 N·m from
/// t = 0, so a step of 180 N·m at t = 0 (sample 250).
fn smooth_with_step(t: f64) -> f64 {
    let decay = if t >= 0.0 {
        60.0 + 120.0 * (-t / 0.8).exp()
    } else {
        0.0
    };
    1000.0 + 40.0 * (2.0 * std::f64::consts::PI * t).sin() + decay
}

/// The reconstruction of a known smooth signal with a step, under white noise of σ = 1 and 2
/// (N·m) on the logger's 0.05 grid, over 10 seeds each: the noise sd is estimated within 10 %,
/// exactly one step is found, at its sample, and the reconstruction's RMS error is below 0.35 σ
/// (a Gaussian kernel of sd 6.6 samples averages ~23 samples: √(1/23) ≈ 0.21 σ inside a
/// segment, more at the segment ends; the 1 Hz swing loses 0.4 % of its amplitude at 10 Hz),
/// its largest error below 1.5 σ. The held channel (a weight, cut at t = 0) comes back as two
/// constants within 0.05 N of the truth.
#[test]
fn a_smooth_signal_and_its_step_are_recovered_under_noise() {
    let t = times();
    let truth: Vec<f64> = t.iter().map(|&t| smooth_with_step(t)).collect();
    let weight: Vec<f64> = t
        .iter()
        .map(|&t| if t < 0.0 { 78.5 } else { 0.0 })
        .collect();
    let opts = InputOptions::default();
    for sigma in [1.0, 2.0] {
        for seed in 0..10 {
            let mut rng = Noise::new(seed);
            let mut noisy = |x: &[f64], sd: f64, step: f64| -> Vec<f64> {
                x.iter()
                    .map(|v| ((v + sd * rng.normal()) / step).round() * step)
                    .collect()
            };
            let torque = noisy(&truth, sigma, 0.05);
            let fs = noisy(&vec![18.0; t.len()], 0.2 * sigma, 0.02);
            let fm = noisy(&weight, 0.2 * sigma, 0.02);
            let inputs = LiftInputs {
                t_s: &t,
                torque_nm: &torque,
                fs_n: &fs,
                fm_n: &fm,
            };
            let r = reconstruct(&inputs, &opts).unwrap();
            let i = r.info;
            assert!((i.sample_hz - 500.0).abs() < 1e-6, "{}", i.sample_hz);
            assert!((i.cutoff_hz - 10.0).abs() < 1e-12);
            assert!(
                (i.torque.noise_sd / sigma - 1.0).abs() < 0.1,
                "σ {sigma} seed {seed}: T sd {}",
                i.torque.noise_sd
            );
            assert!((i.fm.noise_sd / (0.2 * sigma) - 1.0).abs() < 0.1);
            assert!(i.torque.smoothed && i.fs.smoothed && i.fm.smoothed);
            assert_eq!((i.torque.jumps, i.fs.jumps, i.fm.jumps), (1, 0, 1));
            // The 1 Hz swing before the step is motion, not rest: smoothed, not averaged.
            assert_eq!(i.rest_samples, 0);
            let err: Vec<f64> = r.torque_nm.iter().zip(&truth).map(|(a, b)| a - b).collect();
            let rms = (err.iter().map(|e| e * e).sum::<f64>() / err.len() as f64).sqrt();
            let worst = err.iter().fold(0.0f64, |m, e| m.max(e.abs()));
            assert!(rms < 0.35 * sigma, "σ {sigma} seed {seed}: RMS {rms}");
            assert!(worst < 1.5 * sigma, "σ {sigma} seed {seed}: worst {worst}");
            // The step stays a step: the samples either side keep its height.
            let step = r.torque_nm[250] - r.torque_nm[249];
            let true_step = truth[250] - truth[249];
            assert!(
                (step - true_step).abs() < 2.0 * sigma,
                "step {step} vs {true_step}"
            );
            assert!(r.fm_n[..250].iter().all(|v| (v - 78.5).abs() < 0.05));
            assert!(r.fm_n[250..].iter().all(|v| v.abs() < 0.05));
            assert_eq!(r.fm_n[0], r.fm_n[249]);
            assert_eq!(r.fm_n[250], r.fm_n[3999]);
        }
    }
}

/// A record that starts at rest (constant loads until the weight is cut at sample 250, then a
/// ramp): over 10 seeds at σ = 1 and 2 the rest stretch is found and the first sample's torque
/// — what the static start is computed from — is within 0.25 σ of the truth (the mean of 250
/// samples errs by σ/16; the smoother's one-sided edge alone erred by ~0.8 σ).
#[test]
fn a_record_starting_at_rest_keeps_its_first_loads() {
    let t = times();
    let torque: Vec<f64> = t.iter().map(|&t| 1110.0 - 30.0 * t.max(0.0)).collect();
    let weight: Vec<f64> = t
        .iter()
        .map(|&t| if t < 0.0 { 78.5 } else { 0.0 })
        .collect();
    for sigma in [1.0, 2.0] {
        for seed in 0..10 {
            let mut rng = Noise::new(100 + seed);
            let mut noisy = |x: &[f64], sd: f64| -> Vec<f64> {
                x.iter().map(|v| v + sd * rng.normal()).collect()
            };
            let (tq, fs, fm) = (
                noisy(&torque, sigma),
                noisy(&vec![18.0; t.len()], 0.2 * sigma),
                noisy(&weight, 0.2 * sigma),
            );
            let inputs = LiftInputs {
                t_s: &t,
                torque_nm: &tq,
                fs_n: &fs,
                fm_n: &fm,
            };
            let r = reconstruct(&inputs, &InputOptions::default()).unwrap();
            assert_eq!(r.info.rest_samples, 250);
            assert_eq!(r.info.torque.jumps, 0, "the ramp starts without a step");
            let e0 = r.torque_nm[0] - 1110.0;
            assert!(e0.abs() < 0.25 * sigma, "σ {sigma} seed {seed}: {e0}");
            assert!(r.torque_nm[..250].iter().all(|v| *v == r.torque_nm[0]));
        }
    }
}

fn raise_and_lower(j3_dry: f64) -> (LiftModel, LiftRecord) {
    let g = builtin_160ec();
    let base = LiftModel::new(g);
    let mut m = base.clone();
    m.friction.dry_mu[RevJoint::J3.index()] *= j3_dry;
    let p = LiftProtocol::raise_and_lower(&base, g).unwrap();
    (base, record(&m, &p, &SimOptions::default()).unwrap())
}

/// A clean simulated record goes through unchanged: its noise estimates are at the floor, no
/// channel is smoothed, and the channels are equal bit for bit.
#[test]
fn clean_inputs_pass_unchanged() {
    let (_, rec) = raise_and_lower(1.8);
    let r = reconstruct(&rec.inputs(), &InputOptions::default()).unwrap();
    assert_eq!(r.torque_nm, rec.torque_nm);
    assert_eq!(r.fs_n, rec.fs_n);
    assert_eq!(r.fm_n, rec.fm_n);
    assert!(!r.info.torque.smoothed && !r.info.fs.smoothed && !r.info.fm.smoothed);
    assert_eq!(r.info.cutoff_hz, 0.0);
    // Reconstruction off: the recorded channels whatever their noise.
    let noisy = LiftSensorNoise::realistic().apply(&rec, 1);
    let off = InputOptions {
        enabled: false,
        ..Default::default()
    };
    let r = reconstruct(&noisy.inputs(), &off).unwrap();
    assert_eq!(r.torque_nm, noisy.torque_nm);
    assert_eq!(r.fm_n, noisy.fm_n);
}

/// Bad channels and bad settings give an error naming what is wrong.
#[test]
fn bad_inputs_and_settings_are_named() {
    let t = times();
    let x = vec![1.0; t.len()];
    let short = LiftInputs {
        t_s: &t,
        torque_nm: &x[..10],
        fs_n: &x,
        fm_n: &[],
    };
    let e = reconstruct(&short, &InputOptions::default()).unwrap_err();
    assert!(e.to_string().contains("`T_Nm`"), "{e}");
    let ok = LiftInputs {
        t_s: &t,
        torque_nm: &x,
        fs_n: &x,
        fm_n: &[],
    };
    let bad = InputOptions {
        cutoff_hz: 0.0,
        ..Default::default()
    };
    let e = reconstruct(&ok, &bad).unwrap_err();
    assert!(e.to_string().contains("cutoff_hz"), "{e}");
    // An absent Fm stays absent.
    let r = reconstruct(&ok, &InputOptions::default()).unwrap();
    assert!(r.fm_n.is_empty());
}

/// Issue 15: with realistic sensor noise on every channel (inputs included) and twice that,
/// a raise-and-lower lift with J3 dry friction at 1.8 × Table 4 is fitted on reconstructed
/// inputs; over seeds 1–5 per level J3 dry's 95 % interval holds the truth in at least 4 of 5
/// (at nominal coverage P(≥ 4 of 5) = 0.977) and no other joint is flagged. At realistic noise
/// the fit flags J3 every time; at twice that the intervals carry the inputs' noise
/// (`lift::input_noise::covariance`), which the linearised propagation overstates there
/// (J3 dry ±30–60 % against a realised scatter of ~2 % over seeds), so J3 is flagged only when
/// its interval leaves the band — a known conservatism, stated in the README. The fit records
/// the noise it estimated on each input.
#[test]
fn noisy_input_fits_flag_a_j3_dry_drift_within_its_interval() {
    let (base, clean) = raise_and_lower(1.8);
    let j3 = LiftParam::named("J3", "dry").unwrap();
    let truth = 1.8 * j3.get(&base, 0.0);
    let opts = LiftFitOptions::default();
    for k in [1.0, 2.0] {
        let noise = LiftSensorNoise::realistic().scaled(k);
        let mut covered = 0;
        for seed in 1..=5 {
            let rec = noise.apply(&clean, seed);
            let tr = rec.trace();
            let fit = fit_map(&base, &[tr], &opts).unwrap();
            // Where J3 dry's drift shows: alone or in its combination (`lift::attribution`).
            let shown = fit.shown_in(j3);
            eprintln!(
                "noise ×{k} seed {seed}: J3 dry shown in {shown:?} truth {truth:.4}, {} evaluations",
                fit.evaluations
            );
            if k == 1.0 {
                assert!(
                    shown.is_some_and(|s| s.flagged()),
                    "noise ×{k} seed {seed}: J3 not flagged"
                );
            }
            for j in fit.joints.iter().filter(|j| j.joint != "J3") {
                assert!(!j.flagged(), "noise ×{k} seed {seed}: {} flagged", j.joint);
            }
            for c in fit.combinations.iter().filter(|c| !c.params.contains(&j3)) {
                assert!(
                    !matches!(c.status, Status::Watch | Status::Alarm),
                    "noise ×{k} seed {seed}: {} flagged",
                    c.label()
                );
            }
            let mut drifted = base.clone();
            j3.set(&mut drifted, &mut 0.0, truth);
            // Not informed at all: reported with the prior's interval, which holds it.
            if shown.is_none_or(|s| s.covers(&drifted, &base)) {
                covered += 1;
            }
            let i = &fit.inputs[0];
            assert!((i.torque.noise_sd / (k * noise_base_torque()) - 1.0).abs() < 0.15);
            assert!(i.torque.smoothed && i.fm.jumps == 1);
            assert_eq!(i.rest_samples, 250, "the 0.5 s before the cut");
        }
        assert!(
            covered >= 4,
            "noise ×{k}: truth in {covered} of 5 intervals"
        );
    }
}

fn noise_base_torque() -> f64 {
    LiftSensorNoise::realistic().torque_sd_nm
}

/// `reconstruct_cached` gives `reconstruct`'s answer to the bit, from its store or not, for
/// noisy records (σ 1 N·m on T, 0.2 N on Fs and Fm, seeds 0–2, each asked twice, the seeds
/// interleaved); a record one torque sample apart (0.05 N·m, the logger's step) is not taken
/// for a stored one; nor are other options.
#[test]
fn cached_reconstructions_are_the_same_to_the_bit() {
    let t = times();
    let truth: Vec<f64> = t.iter().map(|&t| smooth_with_step(t)).collect();
    let weight: Vec<f64> = t
        .iter()
        .map(|&t| if t < 0.0 { 78.5 } else { 0.0 })
        .collect();
    let records: Vec<[Vec<f64>; 3]> = (0..3)
        .map(|seed| {
            let mut rng = Noise::new(100 + seed);
            let mut noisy = |x: &[f64], sd: f64, step: f64| -> Vec<f64> {
                x.iter()
                    .map(|v| ((v + sd * rng.normal()) / step).round() * step)
                    .collect()
            };
            [
                noisy(&truth, 1.0, 0.05),
                noisy(&vec![18.0; t.len()], 0.2, 0.02),
                noisy(&weight, 0.2, 0.02),
            ]
        })
        .collect();
    let bits = |r: &ReconstructedInputs| -> Vec<u64> {
        [&r.t_s, &r.torque_nm, &r.fs_n, &r.fm_n]
            .iter()
            .flat_map(|v| v.iter().map(|x| x.to_bits()))
            .collect()
    };
    fn view<'a>(t: &'a [f64], r: &'a [Vec<f64>; 3]) -> LiftInputs<'a> {
        LiftInputs {
            t_s: t,
            torque_nm: &r[0],
            fs_n: &r[1],
            fm_n: &r[2],
        }
    }
    let opts = InputOptions::default();
    for _ in 0..2 {
        for r in &records {
            let fresh = reconstruct(&view(&t, r), &opts).unwrap();
            let cached = reconstruct_cached(&view(&t, r), &opts).unwrap();
            assert_eq!(bits(&fresh), bits(&cached));
            assert_eq!(fresh.info, cached.info);
        }
    }
    let mut moved = records[0].clone();
    moved[0][2000] += 0.05;
    let fresh = reconstruct(&view(&t, &moved), &opts).unwrap();
    let cached = reconstruct_cached(&view(&t, &moved), &opts).unwrap();
    assert_eq!(bits(&fresh), bits(&cached));
    let stored = reconstruct_cached(&view(&t, &records[0]), &opts).unwrap();
    assert_ne!(
        bits(&stored),
        bits(&cached),
        "a moved sample changes the answer"
    );
    let other = InputOptions {
        cutoff_hz: 5.0,
        ..opts
    };
    let fresh = reconstruct(&view(&t, &records[0]), &other).unwrap();
    let cached = reconstruct_cached(&view(&t, &records[0]), &other).unwrap();
    assert_eq!(bits(&fresh), bits(&cached));
    assert_ne!(
        bits(&stored),
        bits(&cached),
        "other options, another answer"
    );
}

//! `pantowatch simulate`: write a trace document of a pendulum, slider, lift, lower-quadrangle
//! swing or force-gauge (`static_force`) test with chosen
//! friction, release, noise, sample rate and seed — what the tests and the demo use.

pub mod docs;

use std::path::PathBuf;

use anyhow::Context;
use pantowatch_models::data::builtin_160ec;
use pantowatch_models::friction::{FrictionLaw, PositionProfile, Stribeck};
use pantowatch_models::identify::Readout;
use pantowatch_models::synth::{Sensor, Truth, grid, measure_truth};
use serde_json::json;

use crate::trace::{FORMAT, TraceDoc};

#[derive(Debug, Clone, clap::Args)]
pub struct SimulateArgs {
    /// Test kind: pendulum, slider, lift, quadrangle_swing or static_force.
    #[arg(long, default_value = "pendulum")]
    pub kind: String,
    /// Joint: J1 J2 J2' J3 J4 J5 J6 J7 (pendulum), J8 (slider).
    #[arg(long, default_value = "J1")]
    pub joint: String,
    /// Viscous coefficient (N·m·s/rad or N·s/m); default Table 4.
    #[arg(long)]
    pub viscous: Option<f64>,
    /// Dry friction coefficient μ; default Table 4.
    #[arg(long)]
    pub dry: Option<f64>,
    /// Release angle (deg, pendulum; lower-arm α, quadrangle_swing) or displacement (mm,
    /// slider); default the paper rig's (quadrangle_swing: 10.1° below the loop's rest angle,
    /// the paper's Fig 12 deflection).
    #[arg(long)]
    pub release: Option<f64>,
    /// Sensor noise, standard deviation in channel units (deg or mm).
    #[arg(long, default_value_t = 0.05)]
    pub noise: f64,
    /// Sensor quantisation step in channel units (0: none).
    #[arg(long, default_value_t = 0.01)]
    pub quantum: f64,
    /// Sensor zero added to the readings, channel units (quadrangle_swing: the α channel's).
    #[arg(long, default_value_t = 0.0)]
    pub offset: f64,
    /// Sample rate, Hz.
    #[arg(long, default_value_t = 500.0)]
    pub fs: f64,
    /// Duration, s.
    #[arg(long, default_value_t = 30.0)]
    pub duration: f64,
    /// Noise seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    #[arg(long, default_value = "SIM-0001")]
    pub vehicle: String,
    #[arg(long, default_value = "160EC-SIM-0001")]
    pub serial: String,
    #[arg(long)]
    pub trace_id: Option<String>,
    #[arg(long, default_value = "2026-01-01T00:00:00Z")]
    pub recorded_at: String,
    /// An effect the paper's model lacks, `NAME:key=value,…` (repeatable). Vocabulary:
    /// `stribeck:ratio=2,speed=0.3` (μs/μ, rad/s or m/s), `quadratic_drag:c=0.02`,
    /// `position_friction:linear=0.5,quadratic=1.5` (μ·(1 + a·u + b·u²), u = q/(1 rad or 10 mm)),
    /// or a band `position_friction:gain=1,from=10,to=30[,edge=0.5]` (μ·(1 + gain) between
    /// `from` and `to`, channel units), or a cosine
    /// `position_friction:amplitude=0.3,period=120[,phase=0]` (μ·(1 + A·cos(2π·q/period + φ))),
    /// `asymmetric_friction:delta=0.3` (μ·(1 ± δ) by direction), `backlash:half_width=0.3` (channel units), `sensor_offset:offset=0.5` (channel units),
    /// `sensor_delay:delay_s=0.008`; outside it: `torsional_spring:k=4` (N·m/rad or N/m),
    /// `fading_friction:fade=0.5` (share of μ lost over the trace). A lift (`--kind lift`)
    /// takes `quadratic_drag:c_a=4` (N/(m/s)² on the head), `sensor_delay:delay_s=0.02`,
    /// `sensor_offset:offset=0.02` (m, on H), `stribeck:ratio=1.2,speed=0.05` (at J3, v_s in
    /// rad/s) and `drive_compliance:inertia=5,stiffness=15000,damping=2` (the bellows between
    /// the drive side, kg·m², and the lower arm: N·m/rad, N·m·s/rad).
    #[arg(long = "effect")]
    pub effects: Vec<String>,
    /// Slider only: hold the part with this pull (N) and release it at `--release-at` (the
    /// paper's head test, Fig 14): adds the input channel `F_N`.
    #[arg(long)]
    pub pull: Option<f64>,
    #[arg(long, default_value_t = 0.5)]
    pub release_at: f64,
    /// Lift only: `raise-and-lower` (default) or `raise` (the paper's raise alone), 8 s from
    /// t = −0.5 s at `--fs`; or a protocol file as `pantowatch design-test --out` writes it
    /// (JSON, checked against the stand's limits; stated in the trace as `test.protocol`).
    #[arg(long, default_value = "raise-and-lower")]
    pub protocol: String,
    /// Lift, quadrangle_swing and static_force: scale a joint's friction from Table 4,
    /// `JOINT:dry=1.8,viscous=1.2` (repeatable; lift: J1 J2 J2' J3 J4 J5 J7 J8 viscous/dry, J9
    /// viscous; quadrangle_swing: J1 J2 J2' J3; static_force: dry of J1 J2 J2' J3 J4 J5 J6 J7).
    #[arg(long = "scale-joint")]
    pub scale_joints: Vec<String>,
    /// Lift only: noise of the H channel, standard deviation in mm.
    #[arg(long, default_value_t = 1.0)]
    pub h_noise_mm: f64,
    /// Lift only: sensor noise on every channel, inputs included, as K × the assumed stand:
    /// K = 1 is H 0.5 mm, T 1 N·m, Fs and Fm 0.2 N (white, one sd per sample) plus the 16-bit
    /// logger's steps (`lift::sensors`); 2 doubles every sd; 0 (default) adds none. Applied
    /// before `--h-noise-mm`, which still adds its own H noise.
    #[arg(long, default_value_t = 0.0, value_name = "K")]
    pub sensor_noise: f64,
    /// Static_force only: the force gauge's noise, standard deviation in N (white, one draw per
    /// reading).
    #[arg(long, default_value_t = 0.2)]
    pub gauge_noise_n: f64,
    /// Static_force only: the gauge's resolution, N: every reading is rounded to it, and the
    /// trace states it (`test.gauge_resolution_n`).
    #[arg(long, default_value_t = 0.1)]
    pub gauge_resolution_n: f64,
    /// Static_force only: readings raising the strip from 0.85 m to 1.8 m; the lowering branch
    /// reads at the same heights below the top (one fewer). One reading a second.
    #[arg(long, default_value_t = 15)]
    pub gauge_readings: usize,
    /// Quadrangle_swing only: the frame plane's incline to the horizontal, deg (paper: 70).
    #[arg(long, default_value_t = 70.0)]
    pub incline: f64,
    /// Quadrangle_swing only: sensor zero of the β channel, deg.
    #[arg(long, default_value_t = 0.0)]
    pub beta_offset: f64,
    /// Output file (default: stdout).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
}

/// Build the trace document (validated like any upload).
pub fn simulate_doc(a: &SimulateArgs) -> anyhow::Result<TraceDoc> {
    if a.kind == "lift" {
        return simulate_lift(a);
    }
    if a.kind == crate::trace::QUADRANGLE_SWING {
        return simulate_quadrangle(a);
    }
    if a.kind == crate::trace::STATIC_FORCE {
        return simulate_static_force(a);
    }
    let data = builtin_160ec();
    let (test_json, channel) = match a.kind.as_str() {
        "pendulum" => (
            json!({"kind": "pendulum", "joint": a.joint, "rig": {}}),
            "alpha_deg",
        ),
        "slider" => (json!({"kind": "slider", "joint": "J8", "rig": {}}), "h_mm"),
        k => anyhow::bail!(
            "--kind: `{k}` (pendulum, slider, lift, quadrangle_swing or static_force)"
        ),
    };
    if !(a.fs > 0.0 && a.duration > 0.0 && a.noise >= 0.0 && a.quantum >= 0.0) {
        anyhow::bail!("--fs and --duration must be > 0, --noise and --quantum >= 0");
    }
    let t = grid(a.duration, a.fs);
    // A skeleton document gives the rig (the same defaults a fit will use).
    let skeleton = json!({"format": FORMAT, "vehicle_id": a.vehicle, "pantograph": {"model": "160EC", "serial": a.serial},
        "recorded_at": a.recorded_at, "test": test_json, "channels": {"t_s": [0.0, 1.0], channel: [0.0, 0.0]}});
    let sk = TraceDoc::from_value(&skeleton).map_err(|e| anyhow::anyhow!("{e}"))?;
    let (mut test, baseline) = sk.joint_test().map_err(|e| anyhow::anyhow!("{e}"))?;
    test.t_s = t.clone();
    let mut truth = Truth {
        law: FrictionLaw::base(
            a.viscous.or(baseline.viscous).unwrap_or(0.0),
            a.dry.or(baseline.dry).unwrap_or(0.0),
        ),
        readout: Readout::default(),
        dry_fade: 0.0,
    };
    for e in &a.effects {
        apply_effect(
            &mut truth,
            &mut test.dof.torsion,
            e,
            test.scale,
            a.kind == "slider",
        )?;
    }
    let mut release = match a.kind.as_str() {
        "pendulum" => a
            .release
            .unwrap_or(data.rigs.get(&a.joint).map_or(60.0, |r| r.release_deg)),
        _ => a.release.unwrap_or(data.slider.release_mm),
    };
    let mut force = None;
    if let Some(pull) = a.pull {
        let pantowatch_models::dynamics::Mechanism::Slider(rig) = test.dof.mech else {
            anyhow::bail!("--pull is for slider tests")
        };
        let f: Vec<f64> = t
            .iter()
            .map(|&x| if x < a.release_at { -pull } else { 0.0 })
            .collect();
        test.dof.input = Some(pantowatch_models::dynamics::Input {
            t_s: t.clone(),
            value: f.clone(),
        });
        // At rest under the pull.
        release = -pull / rig.stiffness_n_per_m * test.scale;
        force = Some(f);
    }
    let sensor = Sensor {
        scale: test.scale,
        noise_sigma: a.noise,
        quantum: a.quantum,
        offset: a.offset,
        seed: a.seed,
    };
    let y = measure_truth(&test.dof, &truth, release / test.scale, 0.0, &t, &sensor)
        .context("simulation")?;
    let mut doc_json = skeleton;
    doc_json["channels"] = json!({"t_s": t, channel: y});
    if let Some(f) = force {
        doc_json["channels"]["F_N"] = json!(f);
    }
    if let Some(id) = &a.trace_id {
        doc_json["trace_id"] = json!(id);
    }
    TraceDoc::from_value(&doc_json).map_err(|e| anyhow::anyhow!("{e}"))
}

/// A lift test of the complete pantograph (`lift::protocol`), friction scaled by
/// `--scale-joint`, H with Gaussian noise; the inputs T, Fs, Fm as the stand records them.
fn simulate_lift(a: &SimulateArgs) -> anyhow::Result<TraceDoc> {
    use pantowatch_models::lift::dynamics::LiftModel;
    use pantowatch_models::lift::protocol::{LiftProtocol, record};
    use pantowatch_models::lift::sensitivity::LiftParam;
    use pantowatch_models::lift::simulate::SimOptions;
    anyhow::ensure!(
        a.fs > 0.0 && a.fs <= 10_000.0 && a.h_noise_mm >= 0.0 && a.h_noise_mm.is_finite(),
        "--fs must be in (0, 10000] Hz and --h-noise-mm >= 0"
    );
    anyhow::ensure!(
        a.sensor_noise >= 0.0 && a.sensor_noise.is_finite(),
        "--sensor-noise must be finite and >= 0 (K × the stand's realistic noise)"
    );
    let g = pantowatch_models::lift::geometry::builtin_160ec();
    let base = LiftModel::new(g);
    let mut model = base.clone();
    for spec in &a.scale_joints {
        let (joint, rest) = spec
            .split_once(':')
            .ok_or_else(|| anyhow::anyhow!("--scale-joint {spec}: expected JOINT:kind=factor"))?;
        for pair in rest.split(',').filter(|p| !p.is_empty()) {
            let (kind, v) = pair.split_once('=').ok_or_else(|| {
                anyhow::anyhow!("--scale-joint {spec}: `{pair}` is not kind=factor")
            })?;
            let f: f64 = v
                .parse()
                .map_err(|_| anyhow::anyhow!("--scale-joint {spec}: `{v}` is not a number"))?;
            anyhow::ensure!(
                f.is_finite() && f >= 0.0,
                "--scale-joint {spec}: factor must be finite and >= 0"
            );
            let p = LiftParam::named(joint, kind).ok_or_else(|| {
                anyhow::anyhow!(
                    "--scale-joint {spec}: no `{kind}` friction of `{joint}` in a lift (J6 is locked, J9 has no dry friction)"
                )
            })?;
            let mut offset = 0.0;
            let v0 = p.get(&model, 0.0);
            p.set(&mut model, &mut offset, v0 * f);
        }
    }
    let (mut protocol, stated) = match a.protocol.as_str() {
        "raise-and-lower" => (LiftProtocol::raise_and_lower(&base, g)?, false),
        "raise" => (LiftProtocol::reference(g), false),
        p if std::path::Path::new(p).is_file() => {
            let text = std::fs::read(p).with_context(|| format!("reading --protocol {p}"))?;
            let proto: LiftProtocol = serde_json::from_slice(&text)
                .map_err(|e| anyhow::anyhow!("--protocol {p}: {e}"))?;
            pantowatch_models::lift::design::ProtocolLimits::stand(g)
                .check(&proto)
                .map_err(|e| anyhow::anyhow!("--protocol {p}: {e}"))?;
            (proto, true)
        }
        p => anyhow::bail!("--protocol: `{p}` (raise-and-lower, raise, or a protocol file)"),
    };
    if !stated {
        protocol.sample_hz = a.fs;
    }
    // Lift effects (issue 16): `quadratic_drag:c_a=…` (N/(m/s)², on the head) and
    // `stribeck:ratio=…[,speed=…]` (μs/μk ≥ 1 and v_s in rad/s at J3, the joint the lift's
    // vocabulary tries) and `drive_compliance:inertia=…,stiffness=…[,damping=…]` (the bellows
    // between the drive side and the lower arm) are physics and go into the model;
    // `sensor_delay:delay_s=…` delays the
    // logged H after the noise, `sensor_offset:offset=…` (m) shifts it.
    let (mut delay_s, mut h_offset_m) = (0.0, 0.0);
    for spec in &a.effects {
        let (name, kv) = parse_effect(spec)?;
        let only =
            |key: &str| -> Option<f64> { (kv.len() == 1).then(|| kv.get(key).copied()).flatten() };
        let stribeck = (name == "stribeck" && kv.keys().all(|k| k == "ratio" || k == "speed"))
            .then(|| kv.get("ratio").copied())
            .flatten()
            .filter(|r| *r >= 1.0)
            .zip(Some(kv.get("speed").copied().unwrap_or(
                pantowatch_models::lift::dynamics::DEFAULT_STRIBECK_SPEED_RAD_S,
            )))
            .filter(|(_, vs)| *vs > 0.0);
        // `drive_compliance:inertia=…,stiffness=…[,damping=…]` (kg·m², N·m/rad, N·m·s/rad).
        let compliance = (name == "drive_compliance"
            && kv
                .keys()
                .all(|k| k == "inertia" || k == "stiffness" || k == "damping"))
        .then(|| {
            Some(pantowatch_models::lift::dynamics::DriveCompliance {
                inertia_kgm2: *kv.get("inertia")?,
                stiffness_nm_per_rad: *kv.get("stiffness")?,
                damping_nms_per_rad: kv.get("damping").copied().unwrap_or(0.0),
            })
        })
        .flatten()
        .filter(|c| {
            c.inertia_kgm2 > 0.0 && c.stiffness_nm_per_rad > 0.0 && c.damping_nms_per_rad >= 0.0
        });
        if let Some(c) = compliance {
            model.drive_compliance = Some(c);
            continue;
        }
        match (name, only("c_a"), only("delay_s"), stribeck) {
            ("quadratic_drag", Some(v), _, _) if v >= 0.0 => model.head_drag_ns2_per_m2 = v,
            ("sensor_delay", _, Some(v), _) if v >= 0.0 => delay_s = v,
            ("sensor_offset", _, _, _) if only("offset").is_some() => {
                h_offset_m = only("offset").unwrap_or(0.0);
            }
            ("stribeck", _, _, Some((ratio, vs))) => {
                let j = pantowatch_models::lift::effects::STRIBECK_JOINT.index();
                model.stribeck_excess[j] = ratio - 1.0;
                model.stribeck_speed_rad_s[j] = vs;
            }
            _ => anyhow::bail!(
                "--effect {spec}: a lift takes `quadratic_drag:c_a=<N/(m/s)², >= 0>`, \
                 `sensor_delay:delay_s=<s, >= 0>`, `sensor_offset:offset=<m>` or \
                 `stribeck:ratio=<μs/μk, >= 1>[,speed=<rad/s, > 0>]` (at J3) or \
                 `drive_compliance:inertia=<kg·m², > 0>,stiffness=<N·m/rad, > 0>[,damping=<N·m·s/rad, >= 0>]` \
                 (unknown effect or key for a lift)"
            ),
        }
    }
    let mut rec = record(&model, &protocol, &SimOptions::default()).context("lift simulation")?;
    if a.sensor_noise > 0.0 {
        // Its own stream (seed offset), so `--h-noise-mm`'s draws stay those of the same seed.
        let stand = pantowatch_models::lift::sensors::LiftSensorNoise::realistic();
        rec = stand
            .scaled(a.sensor_noise)
            .apply(&rec, a.seed ^ 0x5e75_0a15_e000_0001);
    }
    let mut rng = pantowatch_models::noise::Noise::new(a.seed);
    for h in &mut rec.strip_height_m {
        *h += a.h_noise_mm * 1e-3 * rng.normal();
    }
    for h in &mut rec.strip_height_m {
        *h += h_offset_m;
    }
    if delay_s > 0.0 {
        let lag = (delay_s * protocol.sample_hz).round() as usize;
        let h = rec.strip_height_m.clone();
        for (i, v) in rec.strip_height_m.iter_mut().enumerate() {
            *v = h[i.saturating_sub(lag)];
        }
    }
    let mut test = json!({"kind": "lift", "rig": {}});
    if stated {
        test["protocol"] = serde_json::to_value(&protocol)?;
    }
    let mut doc = json!({"format": FORMAT, "vehicle_id": a.vehicle, "pantograph": {"model": "160EC", "serial": a.serial},
        "recorded_at": a.recorded_at, "test": test,
        "channels": {"t_s": rec.t_s, "H_m": rec.strip_height_m, "T_Nm": rec.torque_nm, "Fs_N": rec.fs_n, "Fm_N": rec.fm_n}});
    if let Some(id) = &a.trace_id {
        doc["trace_id"] = json!(id);
    }
    TraceDoc::from_value(&doc).map_err(|e| anyhow::anyhow!("{e}"))
}

/// Parse `--scale-joint JOINT:kind=factor,…` into (joint, kind, factor) triples.
fn scale_specs(specs: &[String]) -> anyhow::Result<Vec<(String, String, f64)>> {
    let mut out = Vec::new();
    for spec in specs {
        let (joint, rest) = spec
            .split_once(':')
            .ok_or_else(|| anyhow::anyhow!("--scale-joint {spec}: expected JOINT:kind=factor"))?;
        for pair in rest.split(',').filter(|p| !p.is_empty()) {
            let (kind, v) = pair.split_once('=').ok_or_else(|| {
                anyhow::anyhow!("--scale-joint {spec}: `{pair}` is not kind=factor")
            })?;
            let f: f64 = v
                .parse()
                .map_err(|_| anyhow::anyhow!("--scale-joint {spec}: `{v}` is not a number"))?;
            anyhow::ensure!(
                f.is_finite() && f >= 0.0,
                "--scale-joint {spec}: factor must be finite and >= 0"
            );
            out.push((joint.to_string(), kind.to_string(), f));
        }
    }
    Ok(out)
}

/// A lower-quadrangle swing (paper Fig 12) on a frame inclined at `--incline`, released at rest
/// from α = `--release`, friction scaled by `--scale-joint`, both angle channels with
/// `--noise` and their sensor zeros (`--offset`, `--beta-offset`).
fn simulate_quadrangle(a: &SimulateArgs) -> anyhow::Result<TraceDoc> {
    use pantowatch_models::quadrangle::identify::QuadParam;
    use pantowatch_models::quadrangle::model::QJoint;
    use pantowatch_models::quadrangle::report::{QuadRig, SwingRecipe, record_swing};
    anyhow::ensure!(
        a.fs > 0.0 && a.fs <= 10_000.0 && a.duration > 0.0 && a.duration <= 600.0,
        "--fs must be in (0, 10000] Hz and --duration in (0, 600] s"
    );
    anyhow::ensure!(
        a.noise >= 0.0 && a.noise.is_finite() && a.offset.is_finite() && a.beta_offset.is_finite(),
        "--noise must be >= 0, --offset and --beta-offset finite"
    );
    let mut scale = Vec::new();
    for (joint, kind, f) in scale_specs(&a.scale_joints)? {
        let j = QJoint::ALL
            .into_iter()
            .find(|j| j.name() == joint)
            .ok_or_else(|| {
                anyhow::anyhow!("--scale-joint: `{joint}` is not a quadrangle joint (J1 J2 J2' J3)")
            })?;
        let p = match kind.as_str() {
            "viscous" => QuadParam::Viscous(j),
            "dry" => QuadParam::Dry(j),
            k => anyhow::bail!("--scale-joint: `{k}` is not viscous or dry"),
        };
        scale.push((p, f));
    }
    let rig = QuadRig {
        incline_deg: a.incline,
        ..QuadRig::default()
    };
    let rec = record_swing(&SwingRecipe {
        rig,
        scale,
        release_deg: a.release,
        fs_hz: a.fs,
        duration_s: a.duration,
        noise_deg: a.noise,
        zeros_deg: (a.offset, a.beta_offset),
        seed: a.seed,
    })
    .context("quadrangle swing simulation")?;
    let mut doc = json!({"format": FORMAT, "vehicle_id": a.vehicle, "pantograph": {"model": "160EC", "serial": a.serial},
        "recorded_at": a.recorded_at, "test": {"kind": crate::trace::QUADRANGLE_SWING, "rig": {"incline_deg": a.incline}},
        "channels": {"t_s": rec.t_s, "alpha_deg": rec.alpha_deg, "beta_deg": rec.beta_deg}});
    if let Some(id) = &a.trace_id {
        doc["trace_id"] = json!(id);
    }
    TraceDoc::from_value(&doc).map_err(|e| anyhow::anyhow!("{e}"))
}

/// Strip heights of a simulated gauge test, m: the lowest and the highest reading.
pub const GAUGE_HEIGHTS_M: [f64; 2] = [0.85, 1.8];
/// Time between two simulated gauge readings, s.
pub const GAUGE_READING_INTERVAL_S: f64 = 1.0;

/// A force-gauge measurement of the static contact force (issue 20): `--gauge-readings`
/// heights raising the strip over [`GAUGE_HEIGHTS_M`], then lowering it back (the same heights
/// below the top), one reading every [`GAUGE_READING_INTERVAL_S`]. Each reading is the
/// quasi-static strip force of `lift::static_force` (raising or lowering; Table 4 dry friction,
/// `--scale-joint J3:dry=2` scales a revolute joint's; `--effect spring_rate:factor=<k>` scales
/// the drive characteristic's slope about its first point), plus `--effect
/// sensor_offset:offset=<N>` (the gauge's zero) and `--gauge-noise-n` white noise (seeded),
/// rounded to
/// `--gauge-resolution-n`. Heights are read to the millimetre.
fn simulate_static_force(a: &SimulateArgs) -> anyhow::Result<TraceDoc> {
    use pantowatch_models::lift::static_force::{DriveLine, MuEstimate, characteristic};
    use pantowatch_models::lift::topology::{N_REV, RevJoint};
    let n = a.gauge_readings;
    anyhow::ensure!(
        (2..=200).contains(&n),
        "--gauge-readings must be 2 to 200 (readings raising the strip)"
    );
    anyhow::ensure!(
        a.gauge_noise_n.is_finite() && a.gauge_noise_n >= 0.0,
        "--gauge-noise-n must be finite and >= 0 N"
    );
    let q = a.gauge_resolution_n;
    anyhow::ensure!(
        q.is_finite() && q > 0.0,
        "--gauge-resolution-n must be finite and > 0 N"
    );
    let g = pantowatch_models::lift::geometry::builtin_160ec();
    let mut mu: [MuEstimate; N_REV] = std::array::from_fn(|i| MuEstimate {
        value: g.revolute[i].dry_mu,
        ci95: None,
    });
    for (joint, kind, f) in scale_specs(&a.scale_joints)? {
        let j = RevJoint::ALL
            .into_iter()
            .find(|j| j.name() == joint)
            .ok_or_else(|| {
                anyhow::anyhow!(
                    "--scale-joint: `{joint}` is not a revolute joint of the pantograph (J1 J2 \
                     J2' J3 J4 J5 J6 J7)"
                )
            })?;
        anyhow::ensure!(
            kind == "dry",
            "--scale-joint {joint}:{kind}: a static_force test shows dry friction only (it is \
             quasi-static: no viscous term)"
        );
        mu[j.index()].value *= f;
    }
    let (mut offset_n, mut rate_factor) = (0.0, 1.0);
    for spec in &a.effects {
        let (name, kv) = parse_effect(spec)?;
        match (name, kv.get("offset"), kv.get("factor")) {
            ("sensor_offset", Some(v), _) if kv.len() == 1 => offset_n = *v,
            ("spring_rate", _, Some(k)) if kv.len() == 1 && *k > 0.0 => rate_factor = *k,
            _ => anyhow::bail!(
                "--effect {spec}: a static_force test takes `sensor_offset:offset=<N>` (the \
                 gauge's zero) or `spring_rate:factor=<k, > 0>` (the drive characteristic's \
                 slope × k about its first point)"
            ),
        }
    }
    let [lo, hi] = GAUGE_HEIGHTS_M;
    let mm = |h: f64| (h * 1000.0).round() / 1000.0;
    let up: Vec<f64> = (0..n)
        .map(|k| mm(lo + (hi - lo) * k as f64 / (n - 1) as f64))
        .collect();
    let down: Vec<f64> = up.iter().rev().skip(1).copied().collect();
    let drive = pantowatch_models::lift::gauge::simulate::spring_rate_drive(
        &DriveLine::from_lift_test(g),
        rate_factor,
    );
    let raise = characteristic(g, &mu, &drive, &up)
        .context("static force, raising")?
        .raise_n;
    let lower = characteristic(g, &mu, &drive, &down)
        .context("static force, lowering")?
        .lower_n;
    // Rounded to the resolution; divided by 1/q when that is whole (0.1 N: by 10), so a
    // reading is the double nearest its decimal (96.3, not 96.30000000000001).
    let inv = 1.0 / q;
    let round = |f: f64| {
        let k = (f / q).round();
        if (inv - inv.round()).abs() < 1e-9 {
            k / inv.round()
        } else {
            k * q
        }
    };
    let mut rng = pantowatch_models::noise::Noise::new(a.seed);
    let f_n: Vec<f64> = raise
        .iter()
        .chain(&lower)
        .map(|f| round(f + offset_n + a.gauge_noise_n * rng.normal()))
        .collect();
    let h_m: Vec<f64> = up.iter().chain(&down).copied().collect();
    let t_s: Vec<f64> = (0..h_m.len())
        .map(|i| i as f64 * GAUGE_READING_INTERVAL_S)
        .collect();
    let mut doc = json!({"format": FORMAT, "vehicle_id": a.vehicle, "pantograph": {"model": "160EC", "serial": a.serial},
        "recorded_at": a.recorded_at, "test": {"kind": crate::trace::STATIC_FORCE, "gauge_resolution_n": q},
        "channels": {"t_s": t_s, "H_m": h_m, "F_N": f_n}});
    if let Some(id) = &a.trace_id {
        doc["trace_id"] = json!(id);
    }
    TraceDoc::from_value(&doc).map_err(|e| anyhow::anyhow!("{e}"))
}

/// Parse `--effect NAME:key=value,…`: the name and its finite values.
fn parse_effect(spec: &str) -> anyhow::Result<(&str, std::collections::BTreeMap<String, f64>)> {
    let (name, rest) = spec.split_once(':').unwrap_or((spec, ""));
    let mut kv = std::collections::BTreeMap::new();
    for pair in rest.split(',').filter(|p| !p.is_empty()) {
        let (k, v) = pair
            .split_once('=')
            .ok_or_else(|| anyhow::anyhow!("--effect {spec}: `{pair}` is not key=value"))?;
        let v: f64 = v
            .parse()
            .map_err(|_| anyhow::anyhow!("--effect {spec}: `{v}` is not a number"))?;
        anyhow::ensure!(v.is_finite(), "--effect {spec}: `{k}` must be finite");
        kv.insert(k.to_string(), v);
    }
    Ok((name, kv))
}

/// Apply one `--effect NAME:key=value,…` to the truth.
fn apply_effect(
    truth: &mut Truth,
    torsion: &mut f64,
    spec: &str,
    scale: f64,
    slider: bool,
) -> anyhow::Result<()> {
    let (name, kv) = parse_effect(spec)?;
    let get = |k: &str| {
        kv.get(k)
            .copied()
            .ok_or_else(|| anyhow::anyhow!("--effect {name}: needs `{k}=…`"))
    };
    match name {
        "stribeck" => {
            truth.law.stribeck = Some(Stribeck {
                ratio: get("ratio")?,
                speed: get("speed")?,
            })
        }
        "quadratic_drag" => truth.law.quadratic_drag = Some(get("c")?),
        "position_friction" => {
            // Positions in the channel's units (deg or mm), turned into the model's.
            let at = |k: &str| get(k).map(|x| x / scale);
            truth.law.profile = Some(if kv.contains_key("gain") {
                PositionProfile::Band {
                    gain: get("gain")?,
                    from: at("from")?,
                    to: at("to")?,
                    // Default edges: 0.5° or 0.1 mm.
                    edge: kv
                        .get("edge")
                        .copied()
                        .unwrap_or(if slider { 0.1 } else { 0.5 })
                        / scale,
                }
            } else if kv.contains_key("amplitude") {
                PositionProfile::Cosine {
                    amplitude: get("amplitude")?,
                    period: at("period")?,
                    phase: kv.get("phase").copied().unwrap_or(0.0),
                }
            } else {
                PositionProfile::Polynomial {
                    linear: kv.get("linear").copied().unwrap_or(0.0),
                    quadratic: kv.get("quadratic").copied().unwrap_or(0.0),
                    scale: if slider { 0.01 } else { 1.0 },
                }
            })
        }
        "asymmetric_friction" => truth.law.asymmetry = get("delta")?,
        "backlash" => truth.readout.backlash = get("half_width")? / scale,
        "sensor_offset" => truth.readout.offset = get("offset")?,
        "sensor_delay" => truth.readout.delay_s = get("delay_s")?,
        "torsional_spring" => *torsion = get("k")?,
        "fading_friction" => truth.dry_fade = get("fade")?,
        _ => anyhow::bail!("--effect: unknown effect `{name}`"),
    }
    Ok(())
}

pub fn run(a: SimulateArgs) -> anyhow::Result<()> {
    let doc = simulate_doc(&a)?;
    let text = serde_json::to_string(&doc.to_value())?;
    match &a.output {
        Some(p) => std::fs::write(p, text).with_context(|| format!("writing {}", p.display()))?,
        None => println!("{text}"),
    }
    Ok(())
}

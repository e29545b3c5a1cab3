//! `pantowatch simulate`: write a trace document of a pendulum or slider test with chosen
//! friction, release, noise, sample rate and seed — what the tests and the demo use.

use std::path::PathBuf;

use anyhow::Context;
use pantowatch_models::data::builtin_160ec;
use pantowatch_models::friction::FrictionLaw;
use pantowatch_models::synth::{Sensor, grid, measure};
use serde_json::json;

use crate::trace::{FORMAT, TraceDoc};

#[derive(Debug, Clone, clap::Args)]
pub struct SimulateArgs {
    /// Test kind: pendulum or slider.
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
    /// Release angle (deg, pendulum) or displacement (mm, slider); default the paper rig's.
    #[arg(long)]
    pub release: Option<f64>,
    /// Sensor noise, standard deviation in channel units (deg or mm).
    #[arg(long, default_value_t = 0.05)]
    pub noise: f64,
    /// Sensor quantisation step in channel units (0: none).
    #[arg(long, default_value_t = 0.01)]
    pub quantum: f64,
    /// Sensor zero added to the readings, channel units.
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
    /// Output file (default: stdout).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
}

/// Build the trace document (validated like any upload).
pub fn simulate_doc(a: &SimulateArgs) -> anyhow::Result<TraceDoc> {
    let data = builtin_160ec();
    let (test_json, channel) = match a.kind.as_str() {
        "pendulum" => (
            json!({"kind": "pendulum", "joint": a.joint, "rig": {}}),
            "alpha_deg",
        ),
        "slider" => (json!({"kind": "slider", "joint": "J8", "rig": {}}), "h_mm"),
        k => anyhow::bail!("--kind: `{k}` (pendulum or slider)"),
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
    let law = FrictionLaw::base(
        a.viscous.or(baseline.viscous).unwrap_or(0.0),
        a.dry.or(baseline.dry).unwrap_or(0.0),
    );
    let release = match a.kind.as_str() {
        "pendulum" => a
            .release
            .unwrap_or(data.rigs.get(&a.joint).map_or(60.0, |r| r.release_deg)),
        _ => a.release.unwrap_or(data.slider.release_mm),
    };
    let sensor = Sensor {
        scale: test.scale,
        noise_sigma: a.noise,
        quantum: a.quantum,
        offset: a.offset,
        seed: a.seed,
    };
    let (y, _) =
        measure(&test.dof, &law, release / test.scale, 0.0, &t, &sensor).context("simulation")?;
    let mut doc_json = skeleton;
    doc_json["channels"] = json!({"t_s": t, channel: y});
    if let Some(id) = &a.trace_id {
        doc_json["trace_id"] = json!(id);
    }
    TraceDoc::from_value(&doc_json).map_err(|e| anyhow::anyhow!("{e}"))
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

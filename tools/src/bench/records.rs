//! Single-joint records of the peer comparison beyond the shared examples (issue 38, point 2),
//! written as trace documents so that the SciPy peer (`bench/scipy_peer.py`) and our fit read
//! the same files: a 30 s slider (the hidden-suite slider: J8 released from its default
//! deflection, `pantowatch simulate --kind slider --joint J8` at its defaults, 500 Hz, the
//! stand's position noise 0.05 mm and 0.01 mm logger steps) and an input-driven positioning axis
//! (`synth::DrivenAxis`, 2 s at 1 kHz, the force sensor's zero at 0 because the peer's model has
//! none; 0.2 N force noise with 0.05 N steps, 0.05 mm position noise with 0.01 mm steps).

use std::path::{Path, PathBuf};

use pantowatch::cli::simulate::docs::simulate_defaults;
use pantowatch::cli::simulate::{SimulateArgs, simulate_doc};
use pantowatch_models::dynamics::Mechanism;
use serde_json::{Value, json};

/// Duration of the slider record, s (the hidden suite's J8 slider).
pub const SLIDER_S: f64 = 30.0;
/// Samples of the input-driven record (5 s at 1 kHz): the peer integrates through the recorded
/// force sample by sample: 5 s took it over 90 s of CPU.
pub const DRIVEN_SAMPLES: usize = 2_001;

/// A written record and the truth it was made with.
#[derive(Debug, Clone)]
pub struct PeerRecord {
    pub path: PathBuf,
    /// The file stem: its key in the truth map.
    pub name: String,
    pub viscous: f64,
    pub dry: f64,
}

/// Writes the records into `dir` (created) and returns them with their truth.
pub fn write(dir: &Path) -> anyhow::Result<Vec<PeerRecord>> {
    std::fs::create_dir_all(dir)?;
    let mut out = Vec::new();
    // The 30 s slider.
    let args = SimulateArgs {
        kind: "slider".into(),
        joint: "J8".into(),
        duration: SLIDER_S,
        seed: 38,
        trace_id: Some("bench-slider_30s".into()),
        ..simulate_defaults()?
    };
    let doc = simulate_doc(&args)?;
    let (test, baseline) = doc.joint_test().map_err(|e| anyhow::anyhow!("{e}"))?;
    let (Some(viscous), Some(dry)) = (baseline.viscous, baseline.dry) else {
        anyhow::bail!("J8 has no Table 4 baseline")
    };
    let Mechanism::Slider(rig) = test.dof.mech else {
        anyhow::bail!("J8 is a slider")
    };
    // The rig written out (the peer has no type data to default it from), as the example does.
    let mut value = doc.to_value();
    value["test"]["rig"] = json!({"moving_mass_kg": rig.moving_mass_kg, "springs": 1,
        "spring_stiffness_n_per_mm": rig.stiffness_n_per_m / 1000.0,
        "normal_force_n": rig.normal_force_n});
    pantowatch::trace::TraceDoc::from_value(&value).map_err(|e| anyhow::anyhow!("{e}"))?;
    let path = dir.join("slider_30s.json");
    std::fs::write(&path, serde_json::to_vec(&value)?)?;
    out.push(PeerRecord {
        path,
        name: "slider_30s".into(),
        viscous,
        dry,
    });
    // The input-driven axis.
    let axis = pantowatch_models::synth::DrivenAxis {
        input_offset_n: 0.0,
        ..super::scaling::driven_axis(DRIVEN_SAMPLES, 38)
    };
    let test = axis.record()?;
    let Mechanism::Slider(rig) = test.dof.mech else {
        anyhow::bail!("the driven axis is a slider")
    };
    let force = test
        .dof
        .input
        .as_ref()
        .map(|i| i.value.clone())
        .unwrap_or_default();
    let doc: Value = json!({
        "format": "pantograph-trace/1",
        "trace_id": "bench-driven_2s",
        "vehicle_id": "BENCH-AXIS",
        "pantograph": {"model": "160EC", "serial": "160EC-BENCH"},
        "recorded_at": "2026-01-01T00:00:00Z",
        "test": {"kind": "slider", "joint": "custom",
                 "rig": {"moving_mass_kg": rig.moving_mass_kg, "springs": 0,
                         "normal_force_n": rig.normal_force_n}},
        "channels": {"t_s": test.t_s, "h_mm": test.y, "F_N": force},
    });
    // Read back through the service's parser: the file is a valid trace.
    pantowatch::trace::TraceDoc::from_value(&doc).map_err(|e| anyhow::anyhow!("{e}"))?;
    let path = dir.join("driven_2s.json");
    std::fs::write(&path, serde_json::to_vec(&doc)?)?;
    out.push(PeerRecord {
        path,
        name: "driven_2s".into(),
        viscous: axis.viscous,
        dry: axis.dry,
    });
    Ok(out)
}

/// `truth.json` of the examples with the records' entries added (`{"viscous", "dry"}`).
pub fn truth_with(mut truth: Value, records: &[PeerRecord]) -> Value {
    if let Some(m) = truth.as_object_mut() {
        for r in records {
            m.insert(r.name.clone(), json!({"viscous": r.viscous, "dry": r.dry}));
        }
    }
    truth
}

//! Ready-made trace documents: `pantowatch simulate` with its defaults, as the demo's fleet
//! records them — what the tests fit and the bench suite (`pantowatch-tools`) fits and uploads.

use super::{SimulateArgs, simulate_doc};
use crate::trace::TraceDoc;

/// `pantowatch simulate`'s defaults for every option a caller does not set.
pub fn simulate_defaults() -> anyhow::Result<SimulateArgs> {
    #[derive(clap::Parser)]
    struct Defaults {
        #[command(flatten)]
        args: SimulateArgs,
    }
    Ok(<Defaults as clap::Parser>::try_parse_from(["simulate"])?.args)
}

/// A raise-and-lower lift trace (8 s at 500 Hz, H noise 1 mm) with J3's dry friction at
/// `j3_dry` × Table 4, as the demo's fleet records it.
pub fn lift_doc(seed: u64, j3_dry: f64, serial: &str, trace_id: &str) -> anyhow::Result<TraceDoc> {
    let d = simulate_defaults()?;
    let args = SimulateArgs {
        kind: "lift".into(),
        protocol: "raise-and-lower".into(),
        scale_joints: if j3_dry == 1.0 {
            Vec::new()
        } else {
            vec![format!("J3:dry={j3_dry}")]
        },
        h_noise_mm: 1.0,
        fs: 500.0,
        seed,
        serial: serial.into(),
        trace_id: Some(trace_id.into()),
        ..d
    };
    simulate_doc(&args)
}

/// A raise-and-lower lift trace (8 s at 500 Hz) with `scale_joints` drifted and K × the
/// stand's sensor noise on every channel (H 0.5 mm, T 1 N·m, Fs/Fm 0.2 N at K = 1). K = 0:
/// clean inputs and H with 1 mm noise, as the project's simulated lifts were before issue 15.
pub fn noisy_lift_doc(
    seed: u64,
    scale_joints: &[&str],
    sensor_noise: f64,
    serial: &str,
    trace_id: &str,
) -> anyhow::Result<TraceDoc> {
    let d = simulate_defaults()?;
    let args = SimulateArgs {
        kind: "lift".into(),
        protocol: "raise-and-lower".into(),
        scale_joints: scale_joints.iter().map(|s| s.to_string()).collect(),
        h_noise_mm: if sensor_noise > 0.0 { 0.0 } else { 1.0 },
        sensor_noise,
        fs: 500.0,
        seed,
        serial: serial.into(),
        trace_id: Some(trace_id.into()),
        ..d
    };
    simulate_doc(&args)
}

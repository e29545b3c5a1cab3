//! `pantowatch design-test`: design an on-vehicle lift test (issue 15, point 3) and print what
//! it and the raise and lower are predicted to tell, per Table 4 parameter.
//!
//! The physics (Fisher information, input-noise propagation, the greedy D-optimal search) is
//! `models::lift::design`; this layer only reads arguments, shows progress and writes the file.

use std::path::PathBuf;

use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use pantowatch_models::lift::design::{DesignSpace, Prediction, ProtocolLimits, design, predict};
use pantowatch_models::lift::dynamics::LiftModel;
use pantowatch_models::lift::identify::LiftFitOptions;
use pantowatch_models::lift::protocol::LiftProtocol;
use pantowatch_models::lift::sensors::LiftSensorNoise;

#[derive(Debug, clap::Args)]
pub struct DesignArgs {
    /// Write the designed protocol here (JSON; `simulate --kind lift --protocol FILE` runs it,
    /// and a trace may state it as `test.protocol`).
    #[arg(long, short)]
    pub out: Option<PathBuf>,
    /// Sensor noise the design is for, as K × the stand's realistic noise (H 0.5 mm, T 1 N·m,
    /// Fs/Fm 0.2 N, white, plus logger steps).
    #[arg(long, default_value_t = 1.0, value_name = "K")]
    pub noise: f64,
    /// Print the per-parameter table as JSON lines instead of a table.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: &DesignArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        a.noise.is_finite() && a.noise > 0.0,
        "--noise must be > 0 (K × the stand's realistic noise)"
    );
    let g = pantowatch_models::lift::geometry::builtin_160ec();
    let model = LiftModel::new(g);
    let limits = ProtocolLimits::stand(g);
    let space = DesignSpace::stand(&limits);
    let noise = LiftSensorNoise::realistic().scaled(a.noise);
    let opts = LiftFitOptions::default();
    eprintln!(
        "limits: heights {:?} m, drive τ {:?} s, dwell ≥ {} s, test ≤ {} s, torque {:?} N·m",
        limits.height_range_m,
        limits.tau_range_s,
        limits.dwell_min_s,
        limits.duration_max_s,
        limits.torque_range_nm
    );
    let bar = ProgressBar::new(1);
    bar.set_style(
        ProgressStyle::with_template("design [{bar:40}] move {pos}/{len} {elapsed} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let t0 = std::time::Instant::now();
    let d = design(
        &model,
        g,
        &limits,
        &space,
        &noise,
        &opts,
        None,
        &|done, total| {
            bar.set_length(total as u64);
            bar.set_position(done as u64);
        },
    )
    .context("designing the lift test")?;
    bar.finish_and_clear();
    eprintln!(
        "designed in {:.1} s ({} candidate protocols)",
        t0.elapsed().as_secs_f64(),
        d.evaluated
    );
    for (i, s) in d.steps.iter().enumerate() {
        eprintln!(
            "  move {}: at {:.1} s to {:.3} m ({:.1} N·m), τ {:.1} s, dwell {:.1} s",
            i + 1,
            s.chosen.t_s,
            s.chosen.height_m.unwrap_or(f64::NAN),
            s.chosen.torque_nm,
            s.chosen.tau_s,
            s.dwell_s
        );
    }
    let rl = LiftProtocol::raise_and_lower(&model, g)?;
    let draws = pantowatch_models::lift::design::INPUT_DRAWS;
    let a_pred = predict(&model, &rl, &noise, &opts, draws)?;
    let b_pred = predict(&model, &d.protocol, &noise, &opts, draws)?;
    print_table(a, &a_pred, &b_pred);
    if let Some(out) = &a.out {
        std::fs::write(out, serde_json::to_vec_pretty(&d.protocol)?)
            .with_context(|| format!("writing {}", out.display()))?;
        eprintln!("protocol written to {}", out.display());
    }
    Ok(())
}

fn print_table(a: &DesignArgs, rl: &Prediction, designed: &Prediction) {
    if !a.json {
        println!(
            "relative sd (× Table 4; offset N·m), H and input noise — raise and lower | designed"
        );
        println!(
            "{:<12} {:>10} {:>9} | {:>10} {:>9}",
            "parameter", "sd", "informed", "sd", "informed"
        );
    }
    for (i, p) in rl.params.iter().enumerate() {
        let name = format!("{}.{}", p.joint(), p.kind());
        if a.json {
            println!(
                "{}",
                serde_json::json!({
                    "parameter": name,
                    "raise_and_lower": {"relative_sd": rl.sd[i], "sd_h_noise_only": rl.sd_h[i], "informed": rl.informed[i]},
                    "designed": {"relative_sd": designed.sd[i], "sd_h_noise_only": designed.sd_h[i], "informed": designed.informed[i]},
                })
            );
        } else {
            let yn = |b: bool| if b { "yes" } else { "no" };
            println!(
                "{name:<12} {:>10.3} {:>9} | {:>10.3} {:>9}",
                rl.sd[i],
                yn(rl.informed[i]),
                designed.sd[i],
                yn(designed.informed[i])
            );
        }
    }
    if !a.json {
        println!(
            "D-criterion (−log det posterior covariance): {:.1} | {:.1}",
            rl.log_det, designed.log_det
        );
    }
}

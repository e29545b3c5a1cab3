//! `pantowatch design-test`: design an on-vehicle lift test (issue 15, point 3) and print what
//! it and the raise and lower are predicted to tell, per Table 4 parameter.
//!
//! Two predictions per parameter and protocol: the Fisher (linearised) posterior sd — JᵀJ/σ_H²
//! with the fit's prior, alone and with the inputs' noise propagated linearly, the design's
//! criterion — and the final one, the spread of simulated fits (`design::simulated_spread`:
//! `--fits` lifts at Table 4 with the stated noise on every channel, each fitted as the service
//! fits a lift). The linearised share of the inputs' noise overstates what fits realise (J3 dry
//! 2× on the designed protocol, 10× on the raise and lower; docs/VALIDATION.md, "A designed lift test"), so
//! the simulated spread is the one to read for "how well will a test tell this parameter".
//!
//! The physics (Fisher information, input-noise propagation, the greedy D-optimal search, the
//! simulated fits) is `models::lift::design`; this layer only reads arguments, shows progress
//! and writes the file.

use std::path::PathBuf;

use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use pantowatch_models::lift::design::{
    DesignSpace, Prediction, ProtocolLimits, SIMULATED_FITS, SIMULATED_SEED0, SimulatedSpread,
    design, predict, simulated_spread,
};
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
    /// Simulated lifts per protocol for the final prediction (seeds from 9000, fitted on all
    /// cores, ~0.1 s each).
    #[arg(long, default_value_t = SIMULATED_FITS, value_name = "K")]
    pub fits: usize,
    /// Print the per-parameter table as JSON lines instead of a table.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: &DesignArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        a.noise.is_finite() && a.noise > 0.0,
        "--noise must be > 0 (K × the stand's realistic noise)"
    );
    anyhow::ensure!(
        a.fits >= 3,
        "--fits must be at least 3 (a spread needs lifts)"
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
    let bar = ProgressBar::new(2 * a.fits as u64);
    bar.set_style(
        ProgressStyle::with_template("simulated fits [{bar:40}] {pos}/{len} {elapsed}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let t1 = std::time::Instant::now();
    let mut spreads = Vec::new();
    for (k, p) in [&rl, &d.protocol].into_iter().enumerate() {
        let done0 = (k * a.fits) as u64;
        let s = simulated_spread(
            &model,
            p,
            &a_pred.params,
            &noise,
            &opts,
            a.fits,
            SIMULATED_SEED0,
            None,
            &|done| bar.set_position(done0 + done as u64),
        )
        .context("simulating fits of the protocol")?;
        spreads.push(s);
    }
    bar.finish_and_clear();
    eprintln!(
        "{} simulated lifts per protocol fitted in {:.1} s ({} failed)",
        a.fits,
        t1.elapsed().as_secs_f64(),
        spreads.iter().map(|s| s.failed).sum::<usize>()
    );
    print_table(a, [&a_pred, &b_pred], [&spreads[0], &spreads[1]]);
    if let Some(out) = &a.out {
        std::fs::write(out, serde_json::to_vec_pretty(&d.protocol)?)
            .with_context(|| format!("writing {}", out.display()))?;
        eprintln!("protocol written to {}", out.display());
    }
    Ok(())
}

fn print_table(a: &DesignArgs, pred: [&Prediction; 2], sim: [&SimulatedSpread; 2]) {
    if !a.json {
        println!("predicted sd (× Table 4; offset N·m):");
        println!("  Fisher: linearised posterior sd — H noise alone | with the inputs' noise");
        println!(
            "  simulated: sd over {} simulated fits, realistic noise × {} on every channel \
             (the prediction to read)",
            a.fits, a.noise
        );
        println!(
            "{:<12} | {:^46} | {:^46}",
            "", "raise and lower", "designed"
        );
        println!(
            "{:<12} | {:>8} {:>8} {:>9} {:>6} {:>10} | {:>8} {:>8} {:>9} {:>6} {:>10}",
            "parameter",
            "H only",
            "H+input",
            "simulated",
            "inf.",
            "fit rep.",
            "H only",
            "H+input",
            "simulated",
            "inf.",
            "fit rep."
        );
    }
    for (i, p) in pred[0].params.iter().enumerate() {
        let name = format!("{}.{}", p.joint(), p.kind());
        if a.json {
            let col = |k: usize| {
                serde_json::json!({
                    "relative_sd": sim[k].sd[i],
                    "simulated_fit_sd": sim[k].sd[i],
                    "simulated_fit_mean": sim[k].mean[i],
                    "fisher_sd": pred[k].sd[i],
                    "sd_h_noise_only": pred[k].sd_h[i],
                    "informed": pred[k].informed[i],
                    // What the fit will report (issue 36, point 6): the share of the simulated
                    // fits that report it, and the combination it is reported in.
                    "reported_by_fit": sim[k].reported[i],
                    "reported_in": sim[k].reported_in[i],
                })
            };
            println!(
                "{}",
                serde_json::json!({
                    "parameter": name,
                    "raise_and_lower": col(0),
                    "designed": col(1),
                    "simulated_fits": a.fits,
                })
            );
        } else {
            let yn = |b: bool| if b { "yes" } else { "no" };
            let rep = |k: usize| reported_cell(sim[k].reported[i], &sim[k].reported_in[i]);
            println!(
                "{name:<12} | {:>8.3} {:>8.3} {:>9.3} {:>6} {:>10} | {:>8.3} {:>8.3} {:>9.3} {:>6} {:>10}",
                pred[0].sd_h[i],
                pred[0].sd[i],
                sim[0].sd[i],
                yn(pred[0].informed[i]),
                rep(0),
                pred[1].sd_h[i],
                pred[1].sd[i],
                sim[1].sd[i],
                yn(pred[1].informed[i]),
                rep(1)
            );
        }
    }
    if !a.json {
        println!(
            "D-criterion (−log det of the linearised posterior covariance): {:.1} | {:.1}",
            pred[0].log_det, pred[1].log_det
        );
        println!(
            "\"inf.\" (informed): Fisher sd with the inputs' noise under the prior's / 2. The \
             simulated sd of a parameter the prior holds is small because the lifts are simulated \
             at Table 4, the prior's mean; it does not make the parameter informed."
        );
        println!(
            "\"fit rep.\" (what the fit will report): the share of the simulated fits whose result \
             judges the parameter — alone or in the combination named (J1+J3 = the J1+J3 dry \
             level). A parameter the information informs but the fit does not report is not \
             judged by a lift of this protocol: a drift there is never a level or an alert; where \
             the lift cannot reach the noise without it, the fit ends `unexplained` with its \
             joints withheld (fit.absorption, lift::absorbed)."
        );
    }
}

/// The "fit rep." cell: the combination it is reported in (or "alone"), with the share of the
/// simulated fits that report it; "no" under half.
fn reported_cell(share: f64, within: &Option<String>) -> String {
    if share < 0.5 {
        return "no".into();
    }
    let what = within.as_deref().map_or("alone".to_string(), |l| {
        l.split(' ').next().unwrap_or(l).to_string()
    });
    format!("{what} {:.0}%", share * 100.0)
}

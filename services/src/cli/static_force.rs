//! `pantowatch static-force (--trace TRACE.json | --fit FIT.json) [--json]`: the predicted static
//! contact force over the working range, raising and lowering, with 95 % bands (issue 20).
//!
//! A trace is fitted first; a fit result (the contract's JSON, e.g. `pantowatch fit --json`) is
//! read as is. The joints that fit informs take its values and intervals; the rest stay at the
//! type's baseline (no band), as for a stored pantograph with that one test. A force-gauge
//! record's fit that names `spring_rate` sets the drive spring's rate (with its interval in the
//! band); otherwise the type's spring (issue 39, point 5).

use std::path::PathBuf;

use anyhow::Context;
use chrono::Utc;
use pantowatch_models::drift::DriftThresholds;

use crate::static_force::{
    SpringSource, StaticForceView, current_mu, predict_blocking, type_models,
};
use crate::store::{JointPoint, NewFit};

/// Exactly one of `--trace` and `--fit`; `--model` and `--json` go with either.
#[derive(Debug, clap::Args)]
pub struct StaticForceArgs {
    /// A trace document to fit first (pantograph-trace/1 JSON).
    #[arg(long, required_unless_present = "fit", conflicts_with = "fit")]
    pub trace: Option<PathBuf>,
    /// A fit result (the contract's JSON, `pantowatch fit --json`).
    #[arg(long)]
    pub fit: Option<PathBuf>,
    /// Pantograph type of a `--fit` result (a trace names its own).
    #[arg(long, default_value = "160EC")]
    pub model: String,
    /// Print the prediction as the API's JSON.
    #[arg(long)]
    pub json: bool,
}

/// The table: H, raise and lower with their bands, the limits, the findings.
pub fn table(v: &StaticForceView) -> String {
    let mut s = format!(
        "static contact force of {} ({}), quasi-static, N on the strip; [95 % band]\n",
        v.serial, v.model
    );
    s += "dry μ: ";
    for p in &v.parameters {
        s += &format!("{} {:.4} ({})  ", p.joint, p.dry_mu, p.source);
    }
    s += "\n";
    let sp = &v.spring;
    s += &match sp.rate_factor_ci95 {
        Some([lo, hi]) => format!(
            "drive spring: rate × {:.4} [{lo:.4}, {hi:.4}] ({}{})\n",
            sp.rate_factor,
            sp.source,
            sp.trace_id
                .as_deref()
                .map_or(String::new(), |t| format!(" {t}"))
        ),
        None => format!("drive spring: the type's ({})\n", sp.source),
    };
    s += &format!(
        "{:>6} {:>8} {:>24} {:>24} {:>8} {:>8}\n",
        "H m", "F0", "F_raise [lo, hi]", "F_lower [lo, hi]", "min", "max"
    );
    for i in 0..v.heights_m.len() {
        s += &format!(
            "{:>6.3} {:>8.2} {:>24} {:>24} {:>8.2} {:>8.2}\n",
            v.heights_m[i],
            v.frictionless_n[i],
            format!(
                "{:.2} [{:.2}, {:.2}]",
                v.raise_n[i], v.raise_lo_n[i], v.raise_hi_n[i]
            ),
            format!(
                "{:.2} [{:.2}, {:.2}]",
                v.lower_n[i], v.lower_lo_n[i], v.lower_hi_n[i]
            ),
            v.limits.min_n[i],
            v.limits.max_n[i],
        );
    }
    s += &format!(
        "largest raise/lower difference allowed {:.1} N; limits: {}\n",
        v.limits.max_raise_lower_difference_n, v.limits.source
    );
    if v.findings.is_empty() {
        s += "findings: none (every band within the limits)\n";
    } else {
        for f in &v.findings {
            s += &format!(
                "finding: H {:.3} m {} ({:.2} N against {:.2} N)\n",
                f.height_m, f.what, f.value_n, f.limit_n
            );
        }
    }
    s
}

pub fn run(a: StaticForceArgs, thresholds: &DriftThresholds) -> anyhow::Result<()> {
    let (result, model, name) = match (&a.trace, &a.fit) {
        (Some(path), _) => {
            let doc = super::read_trace(path)?;
            // Any kind: a lift, a pendulum or a swing informs the joints it informs.
            let r = crate::fitting::fit_document(&doc, thresholds)
                .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
            let name = doc
                .pantograph_serial
                .clone()
                .or(doc.trace_id.clone())
                .unwrap_or_else(|| path.display().to_string());
            (r, doc.pantograph_model.clone(), name)
        }
        (None, Some(path)) => {
            let text =
                std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
            let r: pantowatch_models::report::FitResult = serde_json::from_slice(&text)
                .map_err(|e| anyhow::anyhow!("{}: not a fit result: {e}", path.display()))?;
            (r, a.model.clone(), path.display().to_string())
        }
        (None, None) => anyhow::bail!("give --trace or --fit"),
    };
    let (_, g) = type_models(&model)
        .ok_or_else(|| anyhow::anyhow!("pantograph type `{model}` has no static-force model"))?;
    let now = Utc::now();
    let spring = if pantowatch_models::lift::gauge::spring_rate_of(&result).is_some() {
        SpringSource::of_gauge_fit(&result, &name, now)
    } else {
        SpringSource::type_spring()
    };
    let fit = NewFit::from_result(result);
    let points: Vec<JointPoint> = fit
        .joints
        .into_iter()
        .map(|j| JointPoint {
            trace_id: name.clone(),
            vehicle_id: String::new(),
            recorded_at: now,
            model_version: String::new(),
            fit_id: 0,
            fitted_at: now,
            fit: j,
        })
        .collect();
    let (mu, sources) = current_mu(g, &points);
    let v = predict_blocking(&name, &model, &mu, sources, spring)
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        print!("{}", table(&v));
    }
    Ok(())
}

//! `pantowatch fit TRACE.json [--json] [--plot fit.svg]`: identify a trace's joint friction and
//! print a short table, or the contract's fit result as JSON.

use std::path::PathBuf;

use anyhow::Context;
use pantowatch_models::drift::DriftThresholds;
use pantowatch_models::identify::FitOutcome;
use pantowatch_models::report::FitResult;
use plotters::style::RGBColor;

use crate::plot::{Series, fit_svg};
use crate::trace::{Kind, TraceDoc};

#[derive(Debug, clap::Args)]
pub struct FitArgs {
    /// Trace document (pantograph-trace/1 JSON).
    pub trace: PathBuf,
    /// More recordings of the same rig, with `--pooled`.
    pub more: Vec<PathBuf>,
    /// Fit every recording given with one set of physical parameters (issue 36, point 5): the
    /// same pantograph serial, joint and rig; the residual loop names an effect only if it
    /// explains every recording.
    #[arg(long)]
    pub pooled: bool,
    /// Print the fit result of the trace format as JSON.
    #[arg(long)]
    pub json: bool,
    /// Draw measured vs fitted motion and the residual to this SVG file.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Write the residual loop's report (base vs augmented fit, candidates tried; for a lift:
    /// plain vs with the named effect, held-out error, autocorrelation) as HTML.
    #[arg(long)]
    pub report: Option<PathBuf>,
}

/// Fit a validated document: the identification and the contract result.
pub fn fit_doc(
    doc: &TraceDoc,
    thresholds: &DriftThresholds,
) -> anyhow::Result<(FitResult, FitOutcome)> {
    crate::fitting::fit_with_outcome(doc, thresholds).map_err(|e| anyhow::anyhow!("{e}"))
}

fn fmt_opt(x: Option<f64>) -> String {
    x.map_or("—".into(), |v| format!("{v:.4}"))
}

/// The human table.
pub fn table(doc: &TraceDoc, r: &FitResult) -> String {
    let mut s = String::new();
    let id = doc.trace_id.as_deref().unwrap_or("(no trace_id)");
    let lift = doc.kind == Kind::Lift;
    let quad = doc.kind == Kind::QuadrangleSwing;
    let gauge = doc.kind == Kind::StaticForce;
    if gauge {
        s += &format!(
            "trace {id}  vehicle {}  static_force test (force gauge on the whole pantograph, MAP \
             with Table 4 prior), {} readings fitted\n",
            doc.vehicle_id, r.fit.samples_fitted
        );
    } else if quad {
        s += &format!(
            "trace {id}  vehicle {}  lower-quadrangle swing (J1, J2, J2', J3; MAP with Table 4 \
             prior sd 0.5 × baseline), {} samples fitted\n",
            doc.vehicle_id, r.fit.samples_fitted
        );
    } else if lift {
        s += &format!(
            "trace {id}  vehicle {}  lift test (complete pantograph, MAP with Table 4 prior sd \
             0.5 × baseline), {} samples fitted\n",
            doc.vehicle_id, r.fit.samples_fitted
        );
    } else {
        s += &format!(
            "trace {id}  vehicle {}  {} test  released at t = {:.3} s ({}), {} samples fitted\n",
            doc.vehicle_id,
            doc.kind.as_str(),
            r.fit.release_t_s,
            r.fit.release_rule.replace('_', " "),
            r.fit.samples_fitted
        );
        if let Some(d) = &r.fit.release_disturbance {
            s += &format!(
                "left out {:.3}–{:.3} s: {}\n",
                d.from_s, d.until_s, d.reason
            );
        }
        if let Some(w) = &r.fit.release_warning {
            s += &format!("warning: {w}\n");
        }
    }
    s += &format!(
        "{:<6} {:<9} {:>11} {:>25} {:>10} {:>13} {:>8}\n",
        "joint", "parameter", "value", "95 % interval", "baseline", "identifiable", "status"
    );
    for j in &r.joints {
        for (name, p) in [("viscous", &j.viscous), ("dry", &j.dry)] {
            s += &format!(
                "{:<6} {:<9} {:>11.5} {:>25} {:>10} {:>13} {:>8}   {}\n",
                j.joint,
                name,
                p.value,
                format!("[{:.5}, {:.5}]", p.ci95[0], p.ci95[1]),
                fmt_opt(p.baseline),
                if p.identifiable { "yes" } else { "no" },
                p.status.as_str(),
                p.unit
            );
        }
        s += &format!("{:<6} joint status: {}\n", j.joint, j.status.as_str());
    }
    if quad {
        let informed: Vec<&str> = r
            .joints
            .iter()
            .filter(|j| j.identifiable)
            .map(|j| j.joint.as_str())
            .collect();
        let ci = r.fit.sensor_offset_ci95.unwrap_or([f64::NAN; 2]);
        s += &format!(
            "informed by this trace: {}; the others are reported at baseline, not identified\n\
             RMSE {:.4} deg (alpha and beta); release {:.3} deg at {:.3} deg/s; alpha sensor zero \
             {:.3} deg [{:.3}, {:.3}]; {} after {} iterations (no residual loop on swings)\n",
            informed.join(", "),
            r.rmse.value,
            r.fit.release_position.value,
            r.fit.release_rate.value,
            r.fit.sensor_offset.value,
            ci[0],
            ci[1],
            r.fit.termination,
            r.fit.iterations
        );
        return s;
    }
    if gauge {
        let informed: Vec<&str> = r
            .joints
            .iter()
            .filter(|j| j.identifiable)
            .map(|j| j.joint.as_str())
            .collect();
        let effects: Vec<&str> = r.residual.effects.iter().map(|e| e.name.as_str()).collect();
        let or_none = |v: &[&str]| {
            if v.is_empty() {
                "none".to_owned()
            } else {
                v.join(", ")
            }
        };
        s += &format!(
            "informed by this trace: {}; the others are reported at baseline, not identified\n\
             RMSE {:.3} N of the gauge's force; residual effects: {}\n",
            or_none(&informed),
            r.rmse.value,
            or_none(&effects)
        );
        return s;
    }
    if lift {
        let informed: Vec<&str> = r
            .joints
            .iter()
            .filter(|j| j.identifiable)
            .map(|j| j.joint.as_str())
            .collect();
        let ci = r.fit.sensor_offset_ci95.unwrap_or([f64::NAN; 2]);
        s += &format!(
            "informed by this trace: {}; the others are reported at baseline, not identified\n\
             RMSE {:.3} mm of H; torque-sensor offset {:.3} N·m [{:.3}, {:.3}]; {} after {} \
             iterations\n",
            informed.join(", "),
            r.rmse.value * 1e3,
            r.fit.sensor_offset.value,
            ci[0],
            ci[1],
            r.fit.termination,
            r.fit.iterations
        );
        // The residual loop's finding, from the result itself (one verdict, issue 16 point 5):
        // each named effect with its parameters, or the verdict, the error before and after.
        let effects: Vec<String> = r
            .residual
            .effects
            .iter()
            .map(|e| format!("{} {}", e.name, serde_json::Value::Object(e.params.clone())))
            .collect();
        s += &format!(
            "residual: {}; {:.2}× the noise; RMSE {:.3} -> {:.3} mm, held-out {:.3} -> {:.3} mm\n",
            if !effects.is_empty() {
                format!("named {}", effects.join("; "))
            } else if let Some(v) = &r.residual.verdict {
                v.clone()
            } else {
                "no effect to name".to_owned()
            },
            r.residual.excess_ratio.unwrap_or(f64::NAN),
            r.residual.rmse_before * 1e3,
            r.residual.rmse_after * 1e3,
            r.residual.holdout_rmse_before * 1e3,
            r.residual.holdout_rmse_after * 1e3,
        );
        if let Some(w) = &r.residual.joints_withheld {
            s += &format!("joint statuses withheld: {w}\n");
        }
        if let Some(w) = &r.residual.holdout_note {
            s += &format!("{w}\n");
        }
        return s;
    }
    s += &format!(
        "RMSE {:.4} {}; sensor zero {:.4} {}; release rate {:.4} {}; {} after {} iterations\n",
        r.rmse.value,
        r.rmse.unit,
        r.fit.sensor_offset.value,
        r.fit.sensor_offset.unit,
        r.fit.release_rate.value,
        r.fit.release_rate.unit,
        r.fit.termination,
        r.fit.iterations
    );
    let effects: Vec<&str> = r.residual.effects.iter().map(|e| e.name.as_str()).collect();
    s += &format!(
        "residual: effects [{}]{}; RMSE fitted part {:.4} -> {:.4}, held-out part {:.4} -> {:.4} {}\n",
        effects.join(", "),
        r.residual
            .verdict
            .as_deref()
            .map(|v| format!(" ({v})"))
            .unwrap_or_default(),
        r.residual.rmse_before,
        r.residual.rmse_after,
        r.residual.holdout_rmse_before,
        r.residual.holdout_rmse_after,
        r.rmse.unit
    );
    // Issue 36, point 3: explanations the record cannot tell apart, and the halves check.
    if let Some(a) = &r.residual.ambiguity {
        let each: Vec<String> = a
            .explanations
            .iter()
            .map(|e| {
                format!(
                    "{}{} (ΔBIC {:.1}, held-out {:.4})",
                    e.name,
                    if e.in_vocabulary {
                        ""
                    } else {
                        ", outside the vocabulary"
                    },
                    e.delta_bic,
                    e.holdout_rmse
                )
            })
            .collect();
        s += &format!(
            "ambiguous: the record cannot tell apart {} ({})\n  the test that would: {}\n",
            each.join(" and "),
            a.margin,
            a.separating_test
        );
    }
    if let Some(h) = &r.residual.halves {
        s += &format!(
            "{} on the early / late half of the swing: explains {:.0} % / {:.0} % of the base \
             excess over the noise, leaves {:.1}× / {:.1}× the noise{}\n",
            h.model,
            100.0 * h.early_explained_share,
            100.0 * h.late_explained_share,
            h.early_remainder_over_noise,
            h.late_remainder_over_noise,
            if h.holds {
                ""
            } else {
                ": not the explanation across the range"
            }
        );
    }
    if let Some(w) = &r.residual.joints_withheld {
        s += &format!("joint statuses withheld: {w}\n");
    }
    if let Some(w) = &r.residual.holdout_note {
        s += &format!("{w}\n");
    }
    s
}

/// One trace channel measured against the fitted model, with the residual, as an SVG file.
fn write_plot(
    path: &std::path::Path,
    title: &str,
    t: &[f64],
    unit: &str,
    measured: &[f64],
    fitted: &[f64],
    residual: &[f64],
) -> anyhow::Result<()> {
    let svg = fit_svg(
        title,
        t,
        unit,
        &[
            Series {
                name: "measured",
                y: measured,
                color: RGBColor(120, 120, 120),
            },
            Series {
                name: "fitted model",
                y: fitted,
                color: RGBColor(200, 30, 30),
            },
        ],
        &[Series {
            name: "residual",
            y: residual,
            color: RGBColor(30, 60, 200),
        }],
    )
    .map_err(|e| anyhow::anyhow!("plot: {e}"))?;
    std::fs::write(path, svg).with_context(|| format!("writing {}", path.display()))?;
    eprintln!("plot written to {}", path.display());
    Ok(())
}

/// `fit` of a quadrangle swing: the table or JSON, and α measured vs fitted as SVG.
fn run_quadrangle(
    args: &FitArgs,
    doc: &TraceDoc,
    thresholds: &DriftThresholds,
) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.report.is_none(),
        "--report: the residual loop does not run on quadrangle swings"
    );
    let rep =
        crate::fitting::fit_quadrangle(doc, thresholds).map_err(|e| anyhow::anyhow!("{e}"))?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&rep.result)?);
    } else {
        print!("{}", table(doc, &rep.result));
    }
    if let Some(path) = &args.plot {
        let t = doc.channel("t_s").unwrap_or_default();
        let a = doc.channel("alpha_deg").unwrap_or_default();
        let fitted: Vec<f64> = rep
            .fit
            .fitted_alpha_rad
            .iter()
            .map(|v| v.to_degrees())
            .collect();
        let residual: Vec<f64> = rep
            .fit
            .residual_alpha_rad
            .iter()
            .map(|v| v.to_degrees())
            .collect();
        let title = format!(
            "{} — alpha measured vs fitted (RMSE {:.4} deg)",
            doc.trace_id.as_deref().unwrap_or(""),
            rep.result.rmse.value
        );
        write_plot(path, &title, t, "deg", a, &fitted, &residual)?;
    }
    Ok(())
}

/// `fit` of a static_force (force-gauge) trace: the table or JSON (no plot or report yet).
fn run_static_force(
    args: &FitArgs,
    doc: &TraceDoc,
    thresholds: &DriftThresholds,
) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.plot.is_none() && args.report.is_none(),
        "--plot and --report are not drawn for a static_force trace yet"
    );
    let result = crate::fitting::fit_static_force(doc, thresholds)
        .map_err(|e| anyhow::anyhow!("{e}"))?
        .result;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&result)?);
    } else {
        print!("{}", table(doc, &result));
    }
    Ok(())
}

/// `fit` of a lift trace: the table or JSON, and H measured vs fitted as SVG.
fn run_lift(args: &FitArgs, doc: &TraceDoc, thresholds: &DriftThresholds) -> anyhow::Result<()> {
    let rep = crate::fitting::fit_lift(doc, thresholds).map_err(|e| anyhow::anyhow!("{e}"))?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&rep.result)?);
    } else {
        print!("{}", table(doc, &rep.result));
    }
    if let Some(path) = &args.report {
        std::fs::write(path, super::report::html_lift(doc, &rep)?)
            .with_context(|| format!("writing {}", path.display()))?;
        eprintln!("report written to {}", path.display());
    }
    if let Some(path) = &args.plot {
        let t = doc.channel("t_s").unwrap_or_default();
        let h = doc.channel("H_m").unwrap_or_default();
        anyhow::ensure!(
            rep.fitted_height_m.len() == h.len(),
            "--plot: the fitted lift could not be simulated"
        );
        let residual: Vec<f64> = h
            .iter()
            .zip(&rep.fitted_height_m)
            .map(|(a, b)| a - b)
            .collect();
        let title = format!(
            "{} — H measured vs fitted (RMSE {:.3} mm)",
            doc.trace_id.as_deref().unwrap_or(""),
            rep.result.rmse.value * 1e3
        );
        write_plot(path, &title, t, "m", h, &rep.fitted_height_m, &residual)?;
    }
    Ok(())
}

pub fn run(args: FitArgs, thresholds: &DriftThresholds) -> anyhow::Result<()> {
    if args.pooled {
        let mut paths = vec![args.trace.clone()];
        paths.extend(args.more.iter().cloned());
        return super::pooled::run(&paths, args.json);
    }
    if !args.more.is_empty() {
        anyhow::bail!("several trace files are fitted together only with --pooled");
    }
    let doc = super::read_trace(&args.trace)?;
    if doc.kind == Kind::Lift {
        return run_lift(&args, &doc, thresholds);
    }
    if doc.kind == Kind::QuadrangleSwing {
        return run_quadrangle(&args, &doc, thresholds);
    }
    if doc.kind == Kind::StaticForce {
        return run_static_force(&args, &doc, thresholds);
    }
    let (result, fit, finding) =
        crate::fitting::fit_with_finding(&doc, thresholds).map_err(|e| anyhow::anyhow!("{e}"))?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&result)?);
    } else {
        print!("{}", table(&doc, &result));
    }
    if let Some(path) = &args.report {
        std::fs::write(path, super::report::html(&doc, &result, &finding)?)
            .with_context(|| format!("writing {}", path.display()))?;
        eprintln!("report written to {}", path.display());
    }
    if let Some(path) = args.plot {
        let t = &doc.channel("t_s").unwrap_or_default()[fit.start..fit.start + fit.n_fit];
        let y = &doc.channels[1].1[fit.start..fit.start + fit.n_fit];
        let key = if doc.channel("alpha_deg").is_some() {
            "alpha_deg"
        } else {
            "h_mm"
        };
        let y = doc
            .channel(key)
            .map_or(y, |c| &c[fit.start..fit.start + fit.n_fit]);
        let title = format!(
            "{} — measured vs fitted (RMSE {:.4} {})",
            doc.trace_id.as_deref().unwrap_or(""),
            result.rmse.value,
            result.rmse.unit
        );
        let svg = fit_svg(
            &title,
            t,
            &result.rmse.unit,
            &[
                Series {
                    name: "measured",
                    y,
                    color: RGBColor(120, 120, 120),
                },
                Series {
                    name: "fitted model",
                    y: &fit.model_y,
                    color: RGBColor(200, 30, 30),
                },
            ],
            &[Series {
                name: "residual",
                y: &fit.residual,
                color: RGBColor(30, 60, 200),
            }],
        )
        .map_err(|e| anyhow::anyhow!("plot: {e}"))?;
        std::fs::write(&path, svg).with_context(|| format!("writing {}", path.display()))?;
        eprintln!("plot written to {}", path.display());
    }
    Ok(())
}

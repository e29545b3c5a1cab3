//! `pantowatch fit TRACE --report report.html`: the residual loop for people — measured, base
//! fit and augmented fit overlaid; the residual before and after; every candidate effect tried
//! with its held-out error and criterion. One self-contained HTML file with inline SVG.

use pantowatch_models::report::FitResult;
use pantowatch_models::residual::Finding;
use plotters::style::RGBColor;

use crate::plot::{Series, fit_svg};
use crate::trace::TraceDoc;

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Build the report for a document from its fit and the residual loop's finding (no refit).
pub fn html(doc: &TraceDoc, result: &FitResult, f: &Finding) -> anyhow::Result<String> {
    let (test, baseline) = doc.joint_test().map_err(|e| anyhow::anyhow!("{e}"))?;
    let id = doc.trace_id.clone().unwrap_or_default();
    let start = f.base_split.fit.start;
    let t = &test.t_s[start..];
    let y = &test.y[start..];
    let base = &f.base_split.prediction;
    let base_res: Vec<f64> = base.iter().zip(y).map(|(m, y)| m - y).collect();
    let mut top = vec![
        Series {
            name: "measured",
            y,
            color: RGBColor(120, 120, 120),
        },
        Series {
            name: "base model (Table 4 form)",
            y: base,
            color: RGBColor(30, 60, 200),
        },
    ];
    let mut bottom = vec![Series {
        name: "residual, base model",
        y: &base_res,
        color: RGBColor(30, 60, 200),
    }];
    let aug_res: Vec<f64>;
    if let Some(best) = &f.best_split {
        aug_res = best.prediction.iter().zip(y).map(|(m, y)| m - y).collect();
        top.push(Series {
            name: "base + found effects",
            y: &best.prediction,
            color: RGBColor(200, 30, 30),
        });
        bottom.push(Series {
            name: "residual, with effects",
            y: &aug_res,
            color: RGBColor(200, 30, 30),
        });
    }
    let unit = test.unit;
    let t_hold = t[f.base_split.n_fit.min(t.len() - 1)];
    let svg = fit_svg(
        &format!("{id} — fitted up to t = {t_hold:.2} s, held out after"),
        t,
        unit,
        &top,
        &bottom,
    )
    .map_err(|e| anyhow::anyhow!("plot: {e}"))?;
    let r = &result.residual;
    let found = if r.effects.is_empty() {
        "none".to_string()
    } else {
        r.effects
            .iter()
            .map(|e| e.name.clone())
            .collect::<Vec<_>>()
            .join(", ")
    };
    let mut h = String::new();
    h += "<!doctype html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>pantowatch residual report</title><style>body{font-family:sans-serif;max-width:1150px;margin:2em auto;color:#222}table{border-collapse:collapse}td,th{border:1px solid #bbb;padding:4px 8px;text-align:right}th{background:#eee}td.l{text-align:left}.ok{color:#070}.no{color:#a00}</style></head><body>";
    h += &format!("<h1>Residual report: {}</h1>", esc(&id));
    h += &format!(
        "<p>Vehicle {}, pantograph {} {}, {} test of {}, recorded {}.</p>",
        esc(&doc.vehicle_id),
        esc(&doc.pantograph_model),
        esc(doc.pantograph_serial.as_deref().unwrap_or("")),
        doc.kind.as_str(),
        esc(&baseline.joint),
        esc(&doc.recorded_at)
    );
    h += &format!("<h2>Finding: {}</h2>", esc(&found));
    if let Some(v) = &r.verdict {
        let corr: Vec<String> = r
            .correlates_with
            .iter()
            .map(|(n, c)| format!("{} ({c:+.2})", esc(n)))
            .collect();
        h += &format!(
            "<p class=\"no\"><b>{}</b>: structure remains that no candidate explains. The residual correlates most with {}.</p>",
            esc(v),
            corr.join(", ")
        );
    }
    h += &format!(
        "<table><tr><th></th><th>fitted part ({unit})</th><th>held-out part ({unit})</th></tr><tr><td class=\"l\">base model</td><td>{:.4}</td><td>{:.4}</td></tr><tr><td class=\"l\">with effects</td><td>{:.4}</td><td>{:.4}</td></tr></table>",
        r.rmse_before, r.holdout_rmse_before, r.rmse_after, r.holdout_rmse_after
    );
    for e in &r.effects {
        h += &format!(
            "<p><b>{}</b>: <code>{}</code></p>",
            esc(&e.name),
            esc(&serde_json::Value::Object(e.params.clone()).to_string())
        );
    }
    h += &format!(
        "<figure>{svg}<figcaption>Measured motion, the base model and the model with the accepted effects, fitted on the first {:.0} % and predicted after; below, the residual of each.</figcaption></figure>",
        100.0 * (1.0 - pantowatch_models::residual::HOLDOUT_FRACTION)
    );
    let d = &f.diagnosis;
    h += &format!(
        "<h2>Diagnosis of the base residual</h2><p>Ljung–Box Q = {:.1} over {} lags (white below {:.1}): <b>{}</b>. Sensor noise from first differences: {:.4} {unit}.</p>",
        d.ljung_box_q,
        d.ljung_box_lags,
        d.ljung_box_critical,
        if d.white {
            "white"
        } else {
            "structure present"
        },
        d.noise_sigma
    );
    h += "<table><tr><th>signal</th><th>correlation with the residual</th></tr>";
    for (n, c) in &d.correlations {
        h += &format!("<tr><td class=\"l\">{}</td><td>{c:+.3}</td></tr>", esc(n));
    }
    h += "</table><h2>Candidates tried</h2><table><tr><th>effects</th><th>score / dof</th><th>RMSE fitted</th><th>RMSE held out</th><th>BIC</th><th>accepted</th><th class=\"l\">why</th></tr>";
    h += &format!(
        "<tr><td class=\"l\">base</td><td>—</td><td>{:.4}</td><td>{:.4}</td><td>—</td><td>—</td><td class=\"l\">reference</td></tr>",
        r.rmse_before, r.holdout_rmse_before
    );
    for c in &f.candidates {
        let names: Vec<&str> = c.effects.iter().map(|e| e.name()).collect();
        let fmt = |x: f64| {
            if x.is_finite() {
                format!("{x:.4}")
            } else {
                "—".into()
            }
        };
        h += &format!(
            "<tr><td class=\"l\">{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td class=\"{}\">{}</td><td class=\"l\">{}</td></tr>",
            names.join(" + "),
            c.score.map_or("—".into(), |s| format!("{s:.1}")),
            fmt(c.rmse_fit),
            fmt(c.rmse_holdout),
            if c.bic.is_finite() {
                format!("{:.0}", c.bic)
            } else {
                "—".into()
            },
            if c.accepted { "ok" } else { "no" },
            if c.accepted { "yes" } else { "no" },
            esc(&c.reason)
        );
    }
    h += "</table><p>Acceptance: BIC lower by ≥ 10, held-out RMSE lower by ≥ 2 %, the effect's 95 % interval excluding its null, and the accepted effects explaining ≥ 75 % of the held-out excess over the sensor noise; otherwise <i>unexplained</i>.</p></body></html>";
    Ok(h)
}

/// The lift's residual report (issue 16, point 5): measured H, the plain model and, when an
/// effect is named, the model with it; the residual of each; its autocorrelation and what it
/// follows; the error before and after on the whole trace and on the held-out blocks; the
/// acceptance rule. From the fit already made (no refit).
pub fn html_lift(
    doc: &TraceDoc,
    rep: &pantowatch_models::lift::report::LiftReport,
) -> anyhow::Result<String> {
    use pantowatch_models::lift::{effects, holdout, residual};
    let id = doc.trace_id.clone().unwrap_or_default();
    let t = doc.channel("t_s").unwrap_or_default();
    let h = doc.channel("H_m").unwrap_or_default();
    let torque = doc.channel("T_Nm").unwrap_or_default();
    anyhow::ensure!(
        rep.fitted_height_m.len() == h.len() && t.len() == h.len(),
        "the fitted lift could not be simulated over the record"
    );
    let plain = rep
        .plain_fitted_height_m
        .as_deref()
        .unwrap_or(&rep.fitted_height_m);
    let mm = |v: &[f64]| -> Vec<f64> { v.iter().map(|x| x * 1e3).collect() };
    let h_mm = mm(h);
    let plain_mm = mm(plain);
    let plain_res: Vec<f64> = plain_mm.iter().zip(&h_mm).map(|(m, y)| m - y).collect();
    let named = rep.plain_fitted_height_m.is_some();
    let aug_mm = mm(&rep.fitted_height_m);
    let aug_res: Vec<f64> = aug_mm.iter().zip(&h_mm).map(|(m, y)| m - y).collect();
    let mut top = vec![
        Series {
            name: "measured H",
            y: &h_mm,
            color: RGBColor(120, 120, 120),
        },
        Series {
            name: "plain model (Table 4 form, friction refitted)",
            y: &plain_mm,
            color: RGBColor(30, 60, 200),
        },
    ];
    let mut bottom = vec![Series {
        name: "residual, plain model",
        y: &plain_res,
        color: RGBColor(30, 60, 200),
    }];
    if named {
        top.push(Series {
            name: "model with the named effect",
            y: &aug_mm,
            color: RGBColor(200, 30, 30),
        });
        bottom.push(Series {
            name: "residual, with the effect",
            y: &aug_res,
            color: RGBColor(200, 30, 30),
        });
    }
    let svg = fit_svg(&format!("{id} — lift, H (mm)"), t, "mm", &top, &bottom)
        .map_err(|e| anyhow::anyhow!("plot: {e}"))?;
    let r = &rep.result.residual;
    let floor = pantowatch_models::lift::identify::LiftFitOptions::default().h_noise_m;
    // `diagnose` takes measured − fitted, m.
    let plain_m: Vec<f64> = plain_res.iter().map(|v| -v * 1e-3).collect();
    let d = residual::diagnose(t, &plain_m, plain, torque, floor);
    let found = if !r.effects.is_empty() {
        r.effects
            .iter()
            .map(|e| e.name.clone())
            .collect::<Vec<_>>()
            .join(", ")
    } else if let Some(v) = &r.verdict {
        v.clone()
    } else {
        "none: the plain model explains the trace to within the noise".into()
    };
    let mut s = String::new();
    s += "<!doctype html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>pantowatch lift residual report</title><style>body{font-family:sans-serif;max-width:1150px;margin:2em auto;color:#222}table{border-collapse:collapse}td,th{border:1px solid #bbb;padding:4px 8px;text-align:right}th{background:#eee}td.l{text-align:left}.ok{color:#070}.no{color:#a00}</style></head><body>";
    s += &format!("<h1>Lift residual report: {}</h1>", esc(&id));
    s += &format!(
        "<p>Vehicle {}, pantograph {} {}, lift test recorded {}.</p>",
        esc(&doc.vehicle_id),
        esc(&doc.pantograph_model),
        esc(doc.pantograph_serial.as_deref().unwrap_or("")),
        esc(&doc.recorded_at)
    );
    s += &format!("<h2 id=\"verdict\">Finding: {}</h2>", esc(&found));
    for e in &r.effects {
        s += &format!(
            "<p id=\"accepted\"><b>Accepted: {}</b> <code>{}</code>. The fit result's joints come from the fit with it.</p>",
            esc(&e.name),
            esc(&serde_json::Value::Object(e.params.clone()).to_string())
        );
    }
    if r.verdict.is_some() {
        let corr: Vec<String> = r
            .correlates_with
            .iter()
            .map(|(n, c)| format!("{} ({c:+.2})", esc(n)))
            .collect();
        s += &format!(
            "<p class=\"no\"><b>unexplained</b>: no effect of the lift vocabulary explains the residual by the margins below. It follows {}.</p>",
            corr.join(", ")
        );
    }
    if let Some(w) = &r.joints_withheld {
        s += &format!(
            "<p class=\"no\" id=\"withheld\"><b>Joint statuses withheld:</b> {}.</p>",
            esc(w)
        );
    }
    if let Some(w) = &r.holdout_note {
        s += &format!("<p>{}.</p>", esc(w));
    }
    s += &format!(
        "<table><tr><th>H RMSE (mm)</th><th>whole trace</th><th>held-out blocks</th></tr><tr><td class=\"l\">plain model</td><td>{:.3}</td><td>{:.3}</td></tr><tr><td class=\"l\">{}</td><td>{:.3}</td><td>{:.3}</td></tr></table>",
        r.rmse_before * 1e3,
        r.holdout_rmse_before * 1e3,
        if named {
            "with the named effect"
        } else {
            "nothing named (same)"
        },
        r.rmse_after * 1e3,
        r.holdout_rmse_after * 1e3
    );
    s += &format!(
        "<figure>{svg}<figcaption>Measured H, the plain model and (when named) the model with the effect; below, the residual of each (model − measured), mm.</figcaption></figure>"
    );
    s += &format!(
        "<h2>Diagnosis of the plain model's residual</h2><p>RMS {:.3} mm against a sensor noise of {:.3} mm (from first differences, floored at the fit's σ_H {:.2} mm): <b>{:.2}×</b>. Effects are tried above {:.1}×; above {:.0}× the joints are withheld unless an effect is named. Ljung–Box Q over 20 lags at 50 Hz: {:.1} (reported, not a gate: the inputs' smoothed noise makes it fail on correct lifts).</p>",
        d.rms_m * 1e3,
        d.noise_m * 1e3,
        floor * 1e3,
        d.excess_ratio,
        residual::EFFECT_TRY_RATIO,
        residual::MODEL_ERROR_RATIO,
        d.ljung_box_q
    );
    let dt = if t.len() > 1 {
        (t[t.len() - 1] - t[0]) / (t.len() - 1) as f64
    } else {
        1.0
    };
    s += "<table><tr><th>lag (s)</th><th>autocorrelation, plain</th><th>autocorrelation, with effect</th></tr>";
    for lag_s in residual::ACF_LAGS_S {
        let k = ((lag_s / dt).round() as usize).max(1);
        s += &format!(
            "<tr><td>{lag_s}</td><td>{:+.3}</td><td>{}</td></tr>",
            residual::acf(&plain_res, k),
            if named {
                format!("{:+.3}", residual::acf(&aug_res, k))
            } else {
                "—".into()
            }
        );
    }
    s += "</table><table><tr><th>signal</th><th>correlation with the plain residual</th></tr>";
    for (n, c) in &d.correlates_with {
        s += &format!("<tr><td class=\"l\">{}</td><td>{c:+.3}</td></tr>", esc(n));
    }
    s += &format!(
        "</table><h2>Acceptance</h2><p>The vocabulary (<code>quadratic_drag</code>, <code>sensor_delay</code>, <code>sensor_offset</code>, <code>stribeck</code> at J1+J3; one fit each, <code>sensor_delay</code> first where the plain residual follows the strip speed most) is tried; a candidate passes when its refit is back under {:.0}× the noise, its RMSE at most {:.0} % of the plain fit's, its held-out RMSE (every {}th {} s block left out of a refit) at most {:.0} % of the plain model's or within {:.2}× the noise and below it, and its 95 % interval excludes 0. Of those that pass the lowest BIC is named; the search stops at one whose refit is at the noise. Otherwise the finding stays as the plain fit left it.</p></body></html>",
        residual::MODEL_ERROR_RATIO,
        effects::MIN_IMPROVEMENT * 100.0,
        holdout::HOLD_EVERY,
        holdout::BLOCK_S,
        holdout::MAX_HOLDOUT_RATIO * 100.0,
        holdout::HOLDOUT_NOISE_RATIO
    );
    Ok(s)
}

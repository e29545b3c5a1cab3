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

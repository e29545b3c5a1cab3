//! `pantowatch fit TRACE --report report.html`: the residual loop for people — measured, base
//! fit and augmented fit overlaid; the residual before and after; every candidate effect tried
//! with its held-out error and criterion. One self-contained HTML file with inline SVG, written
//! with `maud` (every text and attribute escaped; the SVG from `plot` is the one raw part).

use maud::{DOCTYPE, Markup, PreEscaped, html};
use pantowatch_models::report::FitResult;
use pantowatch_models::residual::Finding;
use plotters::style::RGBColor;

use crate::plot::{Series, fit_svg};
use crate::trace::TraceDoc;

const STYLE: &str = "body{font-family:sans-serif;max-width:1150px;margin:2em auto;color:#222}table{border-collapse:collapse}td,th{border:1px solid #bbb;padding:4px 8px;text-align:right}th{background:#eee}td.l{text-align:left}.ok{color:#070}.no{color:#a00}";

/// The report's page around `body`.
fn page(title: &str, body: Markup) -> String {
    html! {
        (DOCTYPE)
        html lang="en" {
            head {
                meta charset="utf-8";
                title { (title) }
                style { (PreEscaped(STYLE)) }
            }
            body { (body) }
        }
    }
    .into_string()
}

/// `name (+0.42), …`
fn correlations(c: &[(String, f64)]) -> String {
    c.iter()
        .map(|(n, c)| format!("{n} ({c:+.2})"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// A finite number with `digits` decimals, else "—".
fn num(x: f64, digits: usize) -> String {
    if x.is_finite() {
        format!("{x:.digits$}")
    } else {
        "—".into()
    }
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
    let d = &f.diagnosis;
    let body = html! {
        h1 { "Residual report: " (id) }
        p {
            "Vehicle " (doc.vehicle_id) ", pantograph " (doc.pantograph_model) " "
            (doc.pantograph_serial.as_deref().unwrap_or("")) ", " (doc.kind.as_str())
            " test of " (baseline.joint) ", recorded " (doc.recorded_at) "."
        }
        h2 { "Finding: " (found) }
        @if let Some(v) = &r.verdict {
            p.no {
                b { (v) } ": structure remains that no candidate explains. The residual correlates most with "
                (correlations(&r.correlates_with)) "."
            }
        }
        table {
            tr { th {} th { "fitted part (" (unit) ")" } th { "held-out part (" (unit) ")" } }
            tr { td.l { "base model" } td { (num(r.rmse_before, 4)) } td { (num(r.holdout_rmse_before, 4)) } }
            tr { td.l { "with effects" } td { (num(r.rmse_after, 4)) } td { (num(r.holdout_rmse_after, 4)) } }
        }
        @for e in &r.effects {
            p { b { (e.name) } ": " code { (serde_json::Value::Object(e.params.clone()).to_string()) } }
        }
        figure {
            (PreEscaped(svg))
            figcaption {
                "Measured motion, the base model and the model with the accepted effects, fitted on the first "
                (format!("{:.0}", 100.0 * (1.0 - pantowatch_models::residual::HOLDOUT_FRACTION)))
                " % and predicted after; below, the residual of each."
            }
        }
        h2 { "Diagnosis of the base residual" }
        p {
            "Ljung–Box Q = " (format!("{:.1}", d.ljung_box_q)) " over " (d.ljung_box_lags)
            " lags (white below " (format!("{:.1}", d.ljung_box_critical)) "): "
            b { @if d.white { "white" } @else { "structure present" } }
            ". Sensor noise from first differences: " (format!("{:.4}", d.noise_sigma)) " " (unit) "."
        }
        table {
            tr { th { "signal" } th { "correlation with the residual" } }
            @for (n, c) in &d.correlations {
                tr { td.l { (n) } td { (format!("{c:+.3}")) } }
            }
        }
        h2 { "Candidates tried" }
        table {
            tr {
                th { "effects" } th { "score / dof" } th { "RMSE fitted" } th { "RMSE held out" }
                th { "BIC" } th { "accepted" } th.l { "why" }
            }
            tr {
                td.l { "base" } td { "—" } td { (num(r.rmse_before, 4)) }
                td { (num(r.holdout_rmse_before, 4)) } td { "—" } td { "—" } td.l { "reference" }
            }
            @for c in &f.candidates {
                tr {
                    td.l { (c.effects.iter().map(|e| e.name()).collect::<Vec<_>>().join(" + ")) }
                    td { (c.score.map_or("—".into(), |s| format!("{s:.1}"))) }
                    td { (num(c.rmse_fit, 4)) }
                    td { (num(c.rmse_holdout, 4)) }
                    td { (num(c.bic, 0)) }
                    td class=(if c.accepted { "ok" } else { "no" }) { (if c.accepted { "yes" } else { "no" }) }
                    td.l { (c.reason) }
                }
            }
        }
        p {
            "Acceptance: BIC lower by ≥ 10, held-out RMSE lower by ≥ 2 %, the effect's 95 % interval excluding its null, and the accepted effects explaining ≥ 75 % of the held-out excess over the sensor noise; otherwise "
            i { "unexplained" } "."
        }
    };
    Ok(page("pantowatch residual report", body))
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
    let floor = pantowatch_models::lift::identify::LiftFitOptions::default()
        .h_noise_m
        .max(residual::GATE_FLOOR_M);
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
    let dt = if t.len() > 1 {
        (t[t.len() - 1] - t[0]) / (t.len() - 1) as f64
    } else {
        1.0
    };
    let body = html! {
        h1 { "Lift residual report: " (id) }
        p {
            "Vehicle " (doc.vehicle_id) ", pantograph " (doc.pantograph_model) " "
            (doc.pantograph_serial.as_deref().unwrap_or("")) ", lift test recorded " (doc.recorded_at) "."
        }
        h2 #verdict { "Finding: " (found) }
        @for e in &r.effects {
            p #accepted {
                b { "Accepted: " (e.name) } " " code { (serde_json::Value::Object(e.params.clone()).to_string()) }
                ". The fit result's joints come from the fit with it."
            }
        }
        @if r.verdict.is_some() {
            p.no {
                b { "unexplained" } ": no effect of the lift vocabulary explains the residual by the margins below. It follows "
                (correlations(&r.correlates_with)) "."
            }
        }
        @if let Some(w) = &r.joints_withheld {
            p.no #withheld { b { "Joint statuses withheld:" } " " (w) "." }
        }
        @if let Some(w) = &r.holdout_note {
            p { (w) "." }
        }
        table {
            tr { th { "H RMSE (mm)" } th { "whole trace" } th { "held-out blocks" } }
            tr { td.l { "plain model" } td { (num(r.rmse_before * 1e3, 3)) } td { (num(r.holdout_rmse_before * 1e3, 3)) } }
            tr {
                td.l { (if named { "with the named effect" } else { "nothing named (same)" }) }
                td { (num(r.rmse_after * 1e3, 3)) } td { (num(r.holdout_rmse_after * 1e3, 3)) }
            }
        }
        figure {
            (PreEscaped(svg))
            figcaption { "Measured H, the plain model and (when named) the model with the effect; below, the residual of each (model − measured), mm." }
        }
        h2 { "Diagnosis of the plain model's residual" }
        p {
            "RMS " (format!("{:.3}", d.rms_m * 1e3)) " mm against a sensor noise of " (format!("{:.3}", d.noise_m * 1e3))
            " mm (from first differences, floored at the fit's σ_H " (format!("{:.2}", floor * 1e3)) " mm): "
            b { (format!("{:.2}×", d.excess_ratio)) }
            ". Effects are tried above " (format!("{:.1}", residual::EFFECT_TRY_RATIO)) "×; above "
            (format!("{:.0}", residual::MODEL_ERROR_RATIO))
            "× the joints are withheld unless an effect is named. Ljung–Box Q over 20 lags at 50 Hz: "
            (format!("{:.1}", d.ljung_box_q))
            " (reported, not a gate: the inputs' smoothed noise makes it fail on correct lifts)."
        }
        table {
            tr { th { "lag (s)" } th { "autocorrelation, plain" } th { "autocorrelation, with effect" } }
            @for lag_s in residual::ACF_LAGS_S {
                @let k = ((lag_s / dt).round() as usize).max(1);
                tr {
                    td { (lag_s) }
                    td { (format!("{:+.3}", residual::acf(&plain_res, k))) }
                    td { (if named { format!("{:+.3}", residual::acf(&aug_res, k)) } else { "—".into() }) }
                }
            }
        }
        table {
            tr { th { "signal" } th { "correlation with the plain residual" } }
            @for (n, c) in &d.correlates_with {
                tr { td.l { (n) } td { (format!("{c:+.3}")) } }
            }
        }
        h2 { "Acceptance" }
        p {
            "The vocabulary (" code { "quadratic_drag" } ", " code { "sensor_delay" } ", " code { "sensor_offset" } ", "
            code { "stribeck" } " at J1+J3, " code { "drive_compliance" } "; one fit each, " code { "sensor_delay" }
            " first where the plain residual follows the strip speed most) is tried; a candidate passes when its refit is back under "
            (format!("{:.0}", residual::MODEL_ERROR_RATIO)) "× the noise, its RMSE at most "
            (format!("{:.0}", effects::MIN_IMPROVEMENT * 100.0)) " % of the plain fit's, its held-out RMSE (every "
            (holdout::HOLD_EVERY) "th " (holdout::BLOCK_S) " s block left out of a refit) at most "
            (format!("{:.0}", holdout::MAX_HOLDOUT_RATIO * 100.0)) " % of the plain model's or within "
            (format!("{:.2}", holdout::HOLDOUT_NOISE_RATIO))
            "× the noise and below it, and its 95 % interval excludes 0. Of those that pass the lowest BIC is named; the search stops at one whose refit is at the noise. Otherwise the finding stays as the plain fit left it."
        }
    };
    Ok(page("pantowatch lift residual report", body))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_in_a_report_is_escaped_and_the_svg_kept() {
        let hostile = "EN57 </title><script>alert('x')</script> & \"q\"";
        let out = page(
            hostile,
            html! { h1 { (hostile) } figure { (PreEscaped("<svg id=\"plot\"></svg>")) } },
        );
        assert!(!out.contains("<script>"), "{out}");
        assert!(out.contains("&lt;/title&gt;&lt;script&gt;"), "{out}");
        assert!(out.contains("&amp; &quot;q&quot;"), "{out}");
        assert!(out.contains("<svg id=\"plot\"></svg>"), "{out}");
        assert!(out.starts_with("<!DOCTYPE html>"), "{out}");
    }
}

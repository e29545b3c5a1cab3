//! One trace: what was tested (the kind, the joint or assembly, the pantograph and vehicle), its
//! current fit's parameters, the residual finding and measured vs model (the curve stored with
//! the fit, never a refit). A fault while drawing is logged and told in a plain sentence, never as error text.

use axum::extract::State;
use maud::{Markup, html};
use pantowatch_models::report::{EffectResult, FitResult, ParamResult, ResidualResult};

use crate::api::auth::WebUser;
use crate::api::error::AppError;
use crate::api::state::AppState;
use crate::store::TraceMeta;
use crate::web::error::WebPath;
use crate::web::layout::badge;
use crate::web::svg::{Frame, fmt_num, thin};
use crate::web::{PageResult, seg, signed_in_page};

pub async fn trace_page(
    State(st): State<AppState>,
    user: WebUser,
    WebPath(id): WebPath<String>,
) -> PageResult {
    signed_in_page(&user, &id, trace(&st, &id).await)
}

/// What a test of this kind tested: a lift or a quadrangle swing tests an assembly, not one joint.
fn subject(meta: &TraceMeta) -> String {
    match (meta.joint.as_deref(), meta.kind.as_str()) {
        (Some(j), _) => format!("joint {j}"),
        (None, "lift") => "the whole pantograph".to_owned(),
        (None, "quadrangle_swing") => "the lower quadrangle (J1, J2, J2′, J3)".to_owned(),
        (None, crate::trace::STATIC_FORCE) => {
            "the whole pantograph's static contact force (force gauge)".to_owned()
        }
        (None, _) => "the pantograph".to_owned(),
    }
}

async fn trace(st: &AppState, id: &str) -> Result<Markup, AppError> {
    let meta = st
        .store
        .get_trace(id)
        .await?
        .ok_or_else(|| AppError::NotFound(format!("no trace `{id}`")))?;
    let fit = st.store.get_fit(id).await?;
    let recorded = meta.recorded_at.format("%Y-%m-%d %H:%M UTC").to_string();
    let tested = html! {
        p #tested {
            (meta.kind) " test of " (subject(&meta))
            @if let Some(s) = &meta.serial {
                " on pantograph " a href={ "/pantographs/" (seg(s)) } { (s) }
                " (vehicle " (meta.vehicle_id) "), recorded " (recorded) "."
            } @else {
                " on vehicle " (meta.vehicle_id) " (no pantograph serial recorded), recorded "
                (recorded) "."
            }
        }
    };
    let Some(fit) = fit else {
        return Ok(html! {
            h1 { "Trace " (meta.trace_id) }
            (tested)
            p { "Not fitted yet." }
        });
    };
    let result = fit.result()?;
    let charts = trace_charts(st, &meta, fit.id).await;
    Ok(html! {
        h1 { "Trace " (meta.trace_id) }
        (tested)
        p { "Fit " (fit.id) " by " code { (fit.model_version) } ", status " (badge(fit.status)) "." }
        table {
            thead {
                tr {
                    th { "joint" } th { "parameter" } th { "value" } th { "95 % interval" }
                    th { "baseline" } th { "status" }
                }
            }
            tbody {
                @for j in &result.joints {
                    @for (p, r) in [("viscous", &j.viscous), ("dry", &j.dry)] {
                        (param_row(&j.joint, p, r))
                    }
                }
            }
        }
        (release_note(&result))
        (pooled_rig(&result))
        (residual_finding(&result))
        (charts)
    })
}

/// The release the fit started from, and what it left out when the first motion was not a
/// free swing (issue 36, point 4).
fn release_note(result: &FitResult) -> Markup {
    let f = &result.fit;
    html! {
        @if let Some(d) = &f.release_disturbance {
            p #release.watch {
                b { "Release not free: " }
                (fmt_num(d.from_s)) "–" (fmt_num(d.until_s)) " s left out of the fit. "
                (d.reason) "."
                @if let Some(w) = &d.warning { " " (w) "." }
            }
        } @else if let Some(w) = &f.release_warning {
            p #release { "Release at " (fmt_num(f.release_t_s)) " s (" (f.release_rule) "): " (w) "." }
        }
    }
}

/// A pooled fit across recordings of one rig (issue 36, point 5): each recording linked, with
/// its errors alone and pooled, and the pooled verdict.
fn pooled_rig(result: &FitResult) -> Markup {
    let Some(p) = &result.pooled_rig else {
        return html! {};
    };
    let verdict = if !p.effects.is_empty() {
        format!("named across every recording: {}", p.effects.join(" + "))
    } else if let Some(v) = &p.verdict {
        format!(
            "{v}: {} (best tried: {})",
            if v == "ambiguous" {
                "models that explain every recording tie; none is named"
            } else {
                "no effect explains every recording"
            },
            if p.best_tried.is_empty() {
                "none".to_owned()
            } else {
                p.best_tried.join(" + ")
            }
        )
    } else {
        "the base model fits every recording".to_owned()
    };
    html! {
        h2 { "Pooled over rig " (p.rig_id) }
        p #pooled-verdict { (verdict) "." }
        table #pooled-rig {
            thead {
                tr {
                    th { "recording" } th { "RMSE alone" } th { "named alone" }
                    th { "pooled before" } th { "pooled after" } th { "explained" }
                }
            }
            tbody {
                @for r in &p.recordings {
                    tr {
                        td { a href={ "/traces/" (seg(&r.trace_id)) } { (r.trace_id) } }
                        td { (num(Some(r.rmse_alone))) }
                        td {
                            @if r.named_alone.is_empty() {
                                (r.verdict_alone.clone().unwrap_or_else(|| "—".into()))
                            } @else { (r.named_alone.join(" + ")) }
                        }
                        td { (num(Some(r.rmse_pooled_before))) }
                        td { (num(Some(r.rmse_pooled_after))) }
                        td { (format!("{:.0} %", 100.0 * r.explained_share)) }
                    }
                }
            }
        }
    }
}

/// A number for people: `—` where the fit has none (not finite; `null` in the result).
fn num(v: Option<f64>) -> String {
    v.filter(|v| v.is_finite()).map_or("—".to_owned(), fmt_num)
}

/// One parameter of one joint: value, interval, baseline, status.
fn param_row(joint: &str, param: &str, r: &ParamResult) -> Markup {
    html! {
        tr {
            td { (joint) }
            td { (param) }
            td { (num(Some(r.value))) }
            td { "[" (num(Some(r.ci95[0]))) ", " (num(Some(r.ci95[1]))) "]" }
            td { (num(r.baseline)) }
            td { (r.status.as_str()) }
        }
    }
}

/// A residual effect in words: its name and each parameter as "v [lo, hi]".
fn effect_text(e: &EffectResult) -> String {
    let name = &e.name;
    let shown: Vec<String> = e
        .params
        .iter()
        .filter(|(k, _)| !k.ends_with("_ci95"))
        .map(|(k, v)| {
            let ci = e.params.get(&format!("{k}_ci95"));
            let ci = ci
                .and_then(|c| Some((c.get(0)?.as_f64()?, c.get(1)?.as_f64()?)))
                .map_or(String::new(), |(lo, hi)| {
                    format!(" [{}, {}]", fmt_num(lo), fmt_num(hi))
                });
            let v = v
                .as_f64()
                .map_or_else(|| v.as_str().unwrap_or("").to_owned(), fmt_num);
            format!("{k} {v}{ci}")
        })
        .collect();
    if shown.is_empty() {
        name.to_owned()
    } else {
        format!("{name} ({})", shown.join(", "))
    }
}

/// The residual block in words.
fn residual_finding(result: &FitResult) -> Markup {
    let r: &ResidualResult = &result.residual;
    let effects: Vec<String> = r.effects.iter().map(effect_text).collect();
    let finding = if !effects.is_empty() {
        format!("effects found: {}", effects.join(", "))
    } else if let Some(v) = &r.verdict {
        format!("verdict: {v}")
    } else {
        "no structure left that an effect would explain".to_owned()
    };
    let correlates: Vec<String> = r
        .correlates_with
        .iter()
        .filter(|(_, c)| c.is_finite())
        .map(|(name, c)| format!("{name} ({c:+.2})"))
        .collect();
    let excess = r.excess_ratio.filter(|x| x.is_finite());
    // A lift whose residual shows a model error (issue 16): the joints above are withheld.
    let withheld = r.joints_withheld.as_deref();
    let holdout_note = r.holdout_note.as_deref();
    // The residual's autocorrelation (lift fits): after, and before where an effect was named.
    let acf = |v: &[(f64, f64)]| -> Vec<(f64, f64)> {
        v.iter()
            .copied()
            .filter(|(lag, a)| lag.is_finite() && a.is_finite())
            .collect()
    };
    let (after, before) = (acf(&r.autocorrelation), acf(&r.autocorrelation_before));
    html! {
        h2 { "Residual finding" }
        p #finding {
            (finding) ". RMSE before " (num(Some(r.rmse_before))) " / after " (num(Some(r.rmse_after)))
            "; held-out " (num(Some(r.holdout_rmse_before))) " / " (num(Some(r.holdout_rmse_after))) "."
            @if let Some(x) = excess { " Residual RMS " (fmt_num(x)) " × the sensor noise." }
            @if !correlates.is_empty() { " The residual follows " (correlates.join(", ")) "." }
        }
        @if let Some(w) = withheld {
            p #withheld.alarm { b { "Joint statuses withheld:" } " " (w) "." }
        }
        @if let Some(w) = holdout_note { p #holdout-note { (w) "." } }
        @if let Some(a) = &r.ambiguity {
            p #ambiguity.watch {
                b { "Ambiguous: " }
                "the record cannot tell apart "
                (a.explanations.iter().map(|e| if e.in_vocabulary { e.name.clone() } else { format!("{} (outside the vocabulary)", e.name) }).collect::<Vec<_>>().join(" and "))
                " (" (a.margin) "). The test that would: " (a.separating_test)
            }
        }
        @if let Some(h) = &r.halves {
            p #halves {
                (h.model) " explains " (format!("{:.0} %", 100.0 * h.early_explained_share))
                " of the early half's excess over the noise and "
                (format!("{:.0} %", 100.0 * h.late_explained_share)) " of the late half's"
                @if !h.holds { ": not the explanation across the record's range" } "."
            }
        }
        @if !after.is_empty() {
            table #acf {
                thead {
                    tr {
                        th { "lag (s)" } th { "autocorrelation" }
                        @if !before.is_empty() { th { "before the effect" } }
                    }
                }
                tbody {
                    @for (i, (lag, a)) in after.iter().enumerate() {
                        tr {
                            td { (fmt_num(*lag)) }
                            td { (format!("{a:+.3}")) }
                            @if let Some((_, b)) = before.get(i) { td { (format!("{b:+.3}")) } }
                        }
                    }
                }
            }
        }
    }
}

/// Why there is no model curve, for people; the error itself goes to the log.
fn no_curve(trace_id: &str, error: &str) -> Markup {
    tracing::error!(trace_id, error, "trace page: model curve not drawn");
    html! {
        p #no-curve {
            "The measured and model curves of this trace could not be drawn; the service's log \
             says why. The fitted parameters above are unaffected."
        }
    }
}

/// Measured vs model and the residual, drawn from the curve stored with the fit (issue 19,
/// point 4: a page never refits; `fitting::fit_document_with_curve` made it when the worker
/// fitted the trace).
async fn trace_charts(st: &AppState, meta: &TraceMeta, fit_id: i64) -> Markup {
    if let (crate::trace::STATIC_FORCE, Some(serial)) = (meta.kind.as_str(), &meta.serial) {
        return html! {
            p {
                "A force gauge's readings: the pantograph's latest gauge test is drawn over its \
                 predicted static contact force on the "
                a href={ "/pantographs/" (seg(serial)) "#static-force" } { "pantograph's page" } "."
            }
        };
    }
    let curve = match st.store.fit_curve(fit_id).await {
        Ok(Some(c)) => c,
        Ok(None) => {
            return html! {
                p #no-curve {
                    "This fit was stored without its measured and model curves (fits written \
                     before curves were kept, and pooled fits, have none); "
                    code { "pantowatch fit TRACE --plot" } " draws them."
                }
            };
        }
        Err(e) => return no_curve(&meta.trace_id, &format!("curve unreadable: {e}")),
    };
    let (t, y, m) = (&curve.t_s, &curve.measured, &curve.model);
    let n = t.len().min(y.len()).min(m.len());
    if n < 2 {
        return no_curve(&meta.trace_id, "the stored curve is empty");
    }
    let (t, y, m) = (&t[..n], &y[..n], &m[..n]);
    let unit = curve.unit.as_str();
    let idx = thin(n, 1200);
    let (lo, hi) = y
        .iter()
        .chain(m)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(*v), b.max(*v))
        });
    let (t0, t1) = (t[0], t[n - 1]);
    let mut f = Frame::new((t0, t1), (lo, hi));
    f.polyline(
        &idx.iter().map(|&i| (t[i], y[i])).collect::<Vec<_>>(),
        "#757575",
        1.0,
        false,
    );
    f.polyline(
        &idx.iter().map(|&i| (t[i], m[i])).collect::<Vec<_>>(),
        "#1565c0",
        1.0,
        false,
    );
    let xl = vec![(t0, format!("{t0:.2} s")), (t1, format!("{t1:.2} s"))];
    let desc = format!(
        "Measured {} (wide grey) and the fitted model (thin blue) over {} samples from {:.2} s to {:.2} s; RMSE {} {}.",
        curve.channel,
        n,
        t0,
        t1,
        fmt_num(curve.rmse()),
        unit
    );
    let top = f.finish("Measured vs model", &desc, &xl, unit);
    let res = curve.residual();
    let res = &res[..n.min(res.len())];
    let (rlo, rhi) = res
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(*v), b.max(*v))
        });
    let mut g = Frame::new((t0, t1), (rlo, rhi));
    g.hline(0.0, "#999", true);
    g.polyline(
        &idx.iter().map(|&i| (t[i], res[i])).collect::<Vec<_>>(),
        "#c62828",
        1.0,
        false,
    );
    let rdesc = format!(
        "Residual (model − measured) from {} to {} {}.",
        fmt_num(rlo),
        fmt_num(rhi),
        unit
    );
    let bottom = g.finish("Residual", &rdesc, &xl, unit);
    html! {
        h2 { "Measured vs model" }
        figure { (top) figcaption { (desc) } }
        figure { (bottom) figcaption { (rdesc) } }
    }
}

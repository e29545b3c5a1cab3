//! `pantowatch fit A.json B.json … --pooled`: recordings of one rig (the same pantograph serial,
//! joint and rig) fitted with one set of physical parameters, and the residual loop across them.

use anyhow::{Context, bail};
use pantowatch_models::identify::FitOptions;
use pantowatch_models::residual::pooled::{PooledFinding, analyse_pooled};
use serde::Serialize;

use crate::trace::TraceDoc;

/// The pooled fit's answer, as `--json` prints it.
#[derive(Debug, Serialize)]
pub struct PooledReport {
    pub trace_ids: Vec<String>,
    /// The rig's parameters: name, value, 95 % interval.
    pub shared: Vec<(String, f64, [f64; 2])>,
    pub effects: Vec<String>,
    pub verdict: Option<String>,
    /// The model the recordings' `rmse_pooled_after` is of: the named one, else the best tried.
    pub best_tried: Vec<String>,
    pub recordings: Vec<pantowatch_models::residual::pooled::PooledRecording>,
    pub candidates: Vec<pantowatch_models::residual::pooled::PooledCandidate>,
}

fn param_name(p: pantowatch_models::identify::Param) -> String {
    use pantowatch_models::identify::Param;
    match p {
        Param::Dyn(d) => format!("{d:?}").to_lowercase(),
        Param::Inertia => "inertia_log_ratio".into(),
        Param::Delay => "delay_s".into(),
        Param::Backlash => "backlash".into(),
        other => format!("{other:?}").to_lowercase(),
    }
}

/// Check the documents describe one rig, and run the pooled loop.
pub fn pooled(docs: &[(String, TraceDoc)]) -> anyhow::Result<(PooledReport, PooledFinding)> {
    let mut tests = Vec::new();
    for (name, d) in docs {
        let (t, _) = d
            .joint_test()
            .map_err(|e| anyhow::anyhow!("{name}: {e}"))
            .with_context(|| format!("{name}: a pooled fit takes single-joint tests"))?;
        tests.push(t);
    }
    let (first_name, first) = &docs[0];
    for ((name, d), t) in docs.iter().zip(&tests).skip(1) {
        if d.pantograph_serial != first.pantograph_serial || d.joint != first.joint {
            bail!(
                "{name}: pantograph.serial / test.joint differ from {first_name}'s: a pooled fit \
                 takes recordings of one rig"
            );
        }
        if t.dof.mech != tests[0].dof.mech || t.scale != tests[0].scale {
            bail!(
                "{name}: test.rig differs from {first_name}'s: a pooled fit takes recordings of \
                 one rig (one body, one pin)"
            );
        }
    }
    let refs: Vec<_> = tests.iter().collect();
    let finding =
        analyse_pooled(&refs, &FitOptions::default()).map_err(|e| anyhow::anyhow!("{e}"))?;
    let rep = &finding.reported;
    let shared = rep
        .params
        .iter()
        .zip(&rep.values)
        .zip(&rep.ci95)
        .filter(|(((rec, _), _), _)| rec.is_none())
        .map(|(((_, p), v), ci)| (param_name(*p), *v, *ci))
        .collect();
    let report = PooledReport {
        trace_ids: docs
            .iter()
            .map(|(n, d)| d.trace_id.clone().unwrap_or_else(|| n.clone()))
            .collect(),
        shared,
        effects: finding
            .effects
            .iter()
            .map(|e| e.name().to_owned())
            .collect(),
        verdict: finding.verdict.clone(),
        best_tried: finding
            .best_tried
            .iter()
            .map(|e| e.name().to_owned())
            .collect(),
        recordings: finding.recordings.clone(),
        candidates: finding.candidates.clone(),
    };
    Ok((report, finding))
}

/// The human table.
pub fn table(r: &PooledReport) -> String {
    let mut s = format!(
        "pooled fit of {} recordings of one rig: {}\n",
        r.trace_ids.len(),
        r.trace_ids.join(", ")
    );
    s += &format!(
        "{:<34} {:>9} {:<14} {:>10} {:<24} {:>13} {:>12} {:>9}\n",
        "recording",
        "release",
        "rule",
        "RMSE alone",
        "named alone",
        "pooled before",
        "pooled after",
        "explained"
    );
    for (id, rec) in r.trace_ids.iter().zip(&r.recordings) {
        s += &format!(
            "{:<34} {:>9.3} {:<14} {:>10.4} {:<24} {:>13.4} {:>12.4} {:>8.0}%\n",
            id,
            rec.release_t_s,
            rec.release_rule,
            rec.rmse_alone,
            if rec.named_alone.is_empty() {
                rec.verdict_alone.clone().unwrap_or_else(|| "—".into())
            } else {
                rec.named_alone.join("+")
            },
            rec.rmse_pooled_before,
            rec.rmse_pooled_after,
            100.0 * rec.explained_share
        );
    }
    s += "the rig's parameters (one set for every recording):\n";
    for (name, v, ci) in &r.shared {
        s += &format!("  {name:<18} {v:>12.6}  [{:.6}, {:.6}]\n", ci[0], ci[1]);
    }
    s += &match (&r.verdict, r.effects.is_empty()) {
        (_, false) => format!(
            "effect named across every recording: {}\n",
            r.effects.join(" + ")
        ),
        (Some(v), true) => format!(
            "verdict: {v} ({}; 'pooled after' is the best tried: {})\n",
            if v == "ambiguous" {
                "models that explain every recording tie: see their reasons below"
            } else {
                "no effect explains every recording"
            },
            if r.best_tried.is_empty() {
                "none".to_owned()
            } else {
                r.best_tried.join(" + ")
            }
        ),
        (None, true) => "the base model fits every recording\n".into(),
    };
    s += "models tried:\n";
    for c in &r.candidates {
        let names: Vec<&str> = c.effects.iter().map(|e| e.name()).collect();
        s += &format!(
            "  {:<34} {}{}\n",
            names.join(" + "),
            c.reason,
            if c.accepted { "  [named]" } else { "" }
        );
    }
    s
}

/// `fit … --pooled`.
pub fn run(paths: &[std::path::PathBuf], json: bool) -> anyhow::Result<()> {
    if paths.len() < 2 {
        bail!("--pooled needs at least two trace files");
    }
    let mut docs = Vec::new();
    for p in paths {
        docs.push((p.display().to_string(), super::read_trace(p)?));
    }
    let (report, _) = pooled(&docs)?;
    if json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", table(&report));
    }
    Ok(())
}

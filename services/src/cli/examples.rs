//! `pantowatch examples`: fit every example trace in `../shared/data/examples` with a progress
//! bar and print the results against their truth (`truth.json`) — the README's results table.

use indicatif::{ProgressBar, ProgressStyle};
use pantowatch_models::drift::DriftThresholds;

pub fn run(thresholds: &DriftThresholds) -> anyhow::Result<()> {
    let dir = super::examples_dir().ok_or_else(|| anyhow::anyhow!("example traces not found: set PANTOWATCH_EXAMPLES or run from the repository root beside ../shared"))?;
    let mut files: Vec<_> = std::fs::read_dir(&dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension().is_some_and(|x| x == "json")
                && p.file_name().is_some_and(|n| n != "truth.json")
        })
        .collect();
    files.sort();
    let truth: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("truth.json"))?)?;
    let pb = ProgressBar::new(files.len() as u64);
    pb.set_style(
        ProgressStyle::with_template("{spinner} fitting [{bar:30}] {pos}/{len} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut rows = Vec::new();
    for f in &files {
        let name = f
            .file_stem()
            .map_or(String::new(), |s| s.to_string_lossy().into_owned());
        pb.set_message(name.clone());
        let doc = super::read_trace(f)?;
        let (r, _) = super::fit::fit_doc(&doc, thresholds)?;
        rows.push((name, r));
        pb.inc(1);
    }
    pb.finish_and_clear();
    println!(
        "{:<22} {:<5} {:>10} {:>10} {:>8} {:>8} {:>8} {:>9} {:>9}",
        "trace", "joint", "viscous", "true", "err %", "dry", "true", "err %", "status"
    );
    for (name, r) in &rows {
        let j = &r.joints[0];
        let t = &truth[name];
        let (tv, td) = (
            t["viscous"].as_f64().unwrap_or(f64::NAN),
            t["dry"].as_f64().unwrap_or(f64::NAN),
        );
        println!(
            "{:<22} {:<5} {:>10.5} {:>10.5} {:>+8.2} {:>8.4} {:>8.4} {:>+9.2} {:>9}",
            name,
            j.joint,
            j.viscous.value,
            tv,
            100.0 * (j.viscous.value / tv - 1.0),
            j.dry.value,
            td,
            100.0 * (j.dry.value / td - 1.0),
            j.status.as_str()
        );
    }
    Ok(())
}

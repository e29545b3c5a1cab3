//! How wide a pooled lift fit's intervals should be (issue 15, point 4): K pools of N
//! raise-and-lower lifts of a Table 4 pantograph (the stand's realistic noise on every channel,
//! each lift its own seed), fitted together as the service fits them; per friction parameter the
//! realised spread of the estimate about the truth against the mean posterior sd the fit reports.
//!
//! `cargo run --release -p pantowatch-models --example lift_pooled_calibration -- [K] [N] [SEED0] [J5_FACTOR]`
//! (`PW_PROTOCOL=FILE`: lifts of that protocol; `PW_SHARED=1`: every coefficient shared;
//! `PW_WARM=1`: started from the mean of the lifts' own fits)
use pantowatch_models::lift::dynamics::LiftModel;
use pantowatch_models::lift::geometry::builtin_160ec;
use pantowatch_models::lift::identify::{LiftFitOptions, LiftTrace, POOLED_PER_TRACE, fit_map};
use pantowatch_models::lift::protocol::{LiftProtocol, record};
use pantowatch_models::lift::sensitivity::LiftParam;
use pantowatch_models::lift::sensors::LiftSensorNoise;
use pantowatch_models::lift::simulate::SimOptions;

fn main() {
    let mut args = std::env::args().skip(1);
    let k: u64 = args.next().and_then(|s| s.parse().ok()).unwrap_or(8);
    let n: u64 = args.next().and_then(|s| s.parse().ok()).unwrap_or(3);
    let seed0: u64 = args.next().and_then(|s| s.parse().ok()).unwrap_or(20_000);
    let j5f: f64 = args.next().and_then(|s| s.parse().ok()).unwrap_or(1.0);
    let g = builtin_160ec();
    let base = LiftModel::new(g);
    let mut m = base.clone();
    let j5 = LiftParam::named("J5", "dry").unwrap();
    let mut off = 0.0;
    j5.set(&mut m, &mut off, j5.get(&base, 0.0) * j5f);
    // `PW_PROTOCOL=FILE`: a stated protocol (the JSON `pantowatch design-test --out` writes).
    let protocol = match std::env::var("PW_PROTOCOL") {
        Ok(path) => serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap(),
        Err(_) => LiftProtocol::raise_and_lower(&base, g).unwrap(),
    };
    let clean = record(&m, &protocol, &SimOptions::default()).unwrap();
    let opts = LiftFitOptions {
        per_trace: if n > 1 {
            POOLED_PER_TRACE.to_vec()
        } else {
            Vec::new()
        },
        ..LiftFitOptions::default()
    };
    let pf = opts.friction_params.len();
    let (mut err2, mut sd_sum) = (vec![0.0; pf], vec![0.0; pf]);
    let mut done = 0;
    for set in 0..k {
        let recs: Vec<_> = (0..n)
            .map(|i| LiftSensorNoise::realistic().apply(&clean, seed0 + n * set + i))
            .collect();
        let traces: Vec<LiftTrace> = recs.iter().map(|r| r.trace()).collect();
        let mut o = opts.clone();
        if let Some(s) = std::env::var("PW_J5_SCALE")
            .ok()
            .and_then(|s| s.parse::<f64>().ok())
        {
            o.param_interval_scale = vec![(j5, s)];
        }
        if std::env::var("PW_SHARED").is_ok_and(|s| s == "1") {
            o.per_trace.clear();
        }
        if std::env::var("PW_WARM").is_ok_and(|s| s == "1") && n > 1 {
            // Start from the mean of the lifts' own fits.
            let singles: Vec<_> = traces
                .iter()
                .filter_map(|t| {
                    fit_map(&base, std::slice::from_ref(t), &LiftFitOptions::default()).ok()
                })
                .collect();
            let mut x = vec![0.0; pf];
            for f in &singles {
                for (i, e) in f.params.iter().enumerate() {
                    x[i] += e.map_value / e.baseline / singles.len() as f64;
                }
            }
            x.extend(singles.iter().map(|f| f.offsets[0].map_value));
            x.extend(std::iter::repeat_n(0.0, traces.len() * o.per_trace.len()));
            o.start = Some(x);
        }
        let Ok(fit) = fit_map(&base, &traces, &o) else {
            continue;
        };
        done += 1;
        for (i, e) in fit.params.iter().enumerate() {
            let truth = e.param.get(&m, 0.0) / e.baseline;
            err2[i] += (e.map_value / e.baseline - truth).powi(2);
            sd_sum[i] += e.posterior_sd / e.baseline;
        }
        let e5 = fit.params.iter().find(|e| e.param == j5).unwrap();
        let shown: Vec<String> = fit
            .params
            .iter()
            .filter(|e| e.informed)
            .map(|e| {
                format!(
                    "{}.{} {:.3} [{:.3}, {:.3}] {:?}",
                    e.param.joint(),
                    e.param.kind(),
                    e.value / e.baseline,
                    e.ci95[0] / e.baseline,
                    e.ci95[1] / e.baseline,
                    e.status
                )
            })
            .chain(
                fit.combinations
                    .iter()
                    .filter(|c| c.informed)
                    .map(|c| format!("{} {:.3} {:?}", c.label(), c.value, c.status)),
            )
            .collect();
        eprintln!(
            "pool {set}: J5 dry {:.3} sd {:.3}; RMSE {:?} mm; shown {shown:?}",
            e5.map_value / e5.baseline,
            e5.posterior_sd / e5.baseline,
            fit.rmse_m
                .iter()
                .map(|v| (v * 1e4).round() / 10.0)
                .collect::<Vec<_>>()
        );
    }
    println!(
        "{done} pools of {n} lifts, J5 dry × {j5f}: parameter, realised RMS error, mean reported sd, ratio (× Table 4)"
    );
    for (i, p) in opts.friction_params.iter().enumerate() {
        let rms = (err2[i] / done as f64).sqrt();
        let sd = sd_sum[i] / done as f64;
        println!(
            "{:>4}.{:<8} {rms:.3} {sd:.3} {:.2}",
            p.joint(),
            p.kind(),
            rms / sd
        );
    }
}

//! Explore: what the raise and lower and a designed protocol tell (issue 15, point 3).
//! `-- N [SEED0]`: also fit N realistic-noise lifts of each (seeds SEED0.., default 7000) and
//! compare their realised sd with the linearised and the simulated-fit predictions
//! (`design::simulated_spread`, `SIMULATED_FITS` lifts from `SIMULATED_SEED0`). `PW_DRAWS=D`:
//! D input-noise draws in the linearised prediction (default `INPUT_DRAWS`).
use pantowatch_models::lift::design::*;
use pantowatch_models::lift::dynamics::LiftModel;
use pantowatch_models::lift::geometry::builtin_160ec;
use pantowatch_models::lift::identify::LiftFitOptions;
use pantowatch_models::lift::protocol::LiftProtocol;
use pantowatch_models::lift::sensors::LiftSensorNoise;

fn main() {
    let g = builtin_160ec();
    let m = LiftModel::new(g);
    let lim = ProtocolLimits::stand(g);
    let space = DesignSpace::stand(&lim);
    let noise = LiftSensorNoise::realistic();
    let opts = LiftFitOptions::default();
    let t0 = std::time::Instant::now();
    let d = design(&m, g, &lim, &space, &noise, &opts, None, &|i, n| {
        eprintln!("step {i}/{n} {:?}", t0.elapsed())
    })
    .unwrap();
    eprintln!("designed in {:?}, {} candidates", t0.elapsed(), d.evaluated);
    for s in &d.steps {
        eprintln!("{:?} dwell {} logdet {:.2}", s.chosen, s.dwell_s, s.log_det);
    }
    let rl = LiftProtocol::raise_and_lower(&m, g).unwrap();
    let draws = std::env::var("PW_DRAWS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(INPUT_DRAWS);
    let a = predict(&m, &rl, &noise, &opts, draws).unwrap();
    let a0 = predict(&m, &rl, &noise, &opts, 0).unwrap();
    let b = predict(&m, &d.protocol, &noise, &opts, draws).unwrap();
    let b0 = predict(&m, &d.protocol, &noise, &opts, 0).unwrap();
    eprintln!("logdet {:.2} vs {:.2}", a.log_det, b.log_det);
    for pr in [&a, &b] {
        let mut post = pr.fisher.clone();
        for i in 0..post.nrows() {
            post[(i, i)] += if i + 1 < post.nrows() { 4.0 } else { 0.01 };
        }
        let c = post.try_inverse().unwrap();
        eprintln!(
            "corr J1dry-J3dry (H only) {:.3}",
            c[(1, 7)] / (c[(1, 1)] * c[(7, 7)]).sqrt()
        );
    }
    for (i, p) in a.params.iter().enumerate() {
        eprintln!(
            "{:>4} {:>8} | {:.3} {:.3} {} | {:.3} {:.3} {}",
            p.joint(),
            p.kind(),
            a.sd_h[i],
            a.sd[i],
            a.informed[i],
            b.sd_h[i],
            b.sd[i],
            b.informed[i]
        );
    }
    let seeds: u64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    let seed0: u64 = std::env::args()
        .nth(2)
        .and_then(|s| s.parse().ok())
        .unwrap_or(7000);
    for (name, proto, pred, pred0) in [
        ("designed", &d.protocol, &b, &b0),
        ("raise-and-lower", &rl, &a, &a0),
    ] {
        if seeds == 0 {
            break;
        }
        let t_sim = std::time::Instant::now();
        let sim = simulated_spread(
            &m,
            proto,
            &pred.params,
            &noise,
            &opts,
            SIMULATED_FITS,
            SIMULATED_SEED0,
            None,
            &|_| {},
        )
        .unwrap();
        eprintln!(
            "{name}: {} simulated fits in {:.1} s ({} failed)",
            sim.fits,
            t_sim.elapsed().as_secs_f64(),
            sim.failed
        );
        let clean =
            pantowatch_models::lift::protocol::record(&m, proto, &Default::default()).unwrap();
        let mut est: Vec<Vec<f64>> = Vec::new();
        let mut times = Vec::new();
        for seed in 0..seeds {
            // PW_APPLY=inputs: the stand's noise on the inputs only; =h: on H only.
            let applied = match std::env::var("PW_APPLY").as_deref() {
                Ok("inputs") => LiftSensorNoise {
                    h_sd_m: 0.0,
                    ..noise
                },
                Ok("h") => LiftSensorNoise {
                    torque_sd_nm: 0.0,
                    fs_sd_n: 0.0,
                    fm_sd_n: 0.0,
                    ..noise
                },
                _ => noise,
            };
            let rec = applied.apply(&clean, seed0 + seed);
            let t0 = std::time::Instant::now();
            let fit =
                pantowatch_models::lift::identify::fit_map(&m, &[rec.trace()], &opts).unwrap();
            times.push(t0.elapsed().as_secs_f64());
            est.push(
                pred.params
                    .iter()
                    .map(|q| {
                        fit.params
                            .iter()
                            .find(|e| e.param == *q)
                            .map(|e| e.map_value / e.baseline)
                            .or_else(|| fit.offsets.first().map(|o| o.map_value))
                            .unwrap_or(f64::NAN)
                    })
                    .collect(),
            );
        }
        times.sort_by(f64::total_cmp);
        eprintln!("{name}: fit p50 {:.3} s", times[times.len() / 2]);
        for (i, p) in pred.params.iter().enumerate() {
            let xs: Vec<f64> = est.iter().map(|e| e[i]).collect();
            let mean = xs.iter().sum::<f64>() / xs.len() as f64;
            let sd =
                (xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (xs.len() - 1) as f64).sqrt();
            eprintln!(
                "{:>4} {:>8} predicted {:.3} sampling {:.3} (H alone {:.3}) simulated {:.3} (mean {:.3}) realised {:.3} (mean {:.3}) ratio to sampling {:.2} to simulated {:.2} {}",
                p.joint(),
                p.kind(),
                pred.sd[i],
                pred.sd_sampling[i],
                pred0.sd_sampling[i],
                sim.sd[i],
                sim.mean[i],
                sd,
                mean,
                sd / pred.sd_sampling[i],
                sd / sim.sd[i],
                if pred.informed[i] { "informed" } else { "" }
            );
        }
    }
}

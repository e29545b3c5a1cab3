//! Why no lift protocol separates J1's dry friction (issue 15, point 3): the raise, then rounds
//! of drive moves to `PW_HEIGHTS` (default the designed protocol's 1.424 and 1.216 m; τ
//! `PW_TAU` s, each held `PW_DWELL` s) repeated `PW_REPS` times (default 1, 2, 4, 6: up to
//! 27.5 s of the stand's 30). Per protocol: J1 and J3 dry's posterior sd with the H noise alone
//! and with the inputs' noise (linearised, `design::predict`), J1's with J2 dry known to 5 %,
//! and the least-informed directions that hold J1; with `N` > 0, N realistic-noise lifts of a
//! J1 ×3 pantograph fitted as the service fits them (seeds 5000..).
//!
//! `cargo run --release -p pantowatch-models --example lift_long_protocols -- [N]`
use pantowatch_models::lift::design::{INPUT_DRAWS, ProtocolLimits, predict, rounds_of_moves};
use pantowatch_models::lift::dynamics::LiftModel;
use pantowatch_models::lift::geometry::builtin_160ec;
use pantowatch_models::lift::identify::{LiftFitOptions, fit_map};
use pantowatch_models::lift::protocol::record;
use pantowatch_models::lift::sensitivity::LiftParam;
use pantowatch_models::lift::sensors::LiftSensorNoise;

fn env_list(name: &str, default: &str) -> Vec<f64> {
    std::env::var(name)
        .unwrap_or_else(|_| default.into())
        .split(',')
        .map(|s| s.trim().parse().expect("a number"))
        .collect()
}

fn main() {
    let g = builtin_160ec();
    let m = LiftModel::new(g);
    let lim = ProtocolLimits::stand(g);
    let noise = LiftSensorNoise::realistic();
    let opts = LiftFitOptions::default();
    let fits: u64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    let heights = env_list("PW_HEIGHTS", "1.424,1.216");
    let tau_s = env_list("PW_TAU", "1.0")[0];
    let dwell_s = env_list("PW_DWELL", "2.0")[0];
    let name = |q: LiftParam| format!("{} {}", q.joint(), q.kind());
    let (j1, j2, j3) = (
        LiftParam::named("J1", "dry").unwrap(),
        LiftParam::named("J2", "dry").unwrap(),
        LiftParam::named("J3", "dry").unwrap(),
    );
    for reps in env_list("PW_REPS", "1,2,4,6") {
        let p = rounds_of_moves(&m, g, &heights, tau_s, dwell_s, reps as usize)
            .expect("heights in range");
        if let Err(e) = lim.check(&p) {
            println!("{reps} rounds: outside the stand's limits ({e:?})");
            continue;
        }
        let h_only = predict(&m, &p, &noise, &opts, 0).expect("a prediction");
        let with_inputs = predict(&m, &p, &noise, &opts, INPUT_DRAWS).expect("a prediction");
        let at = |q| h_only.params.iter().position(|x| *x == q).unwrap();
        let (i1, i2, i3) = (at(j1), at(j2), at(j3));
        let n = h_only.fisher.nrows();
        let mut post = h_only.fisher.clone();
        for i in 0..n {
            let prior = if i + 1 < n {
                opts.prior_relative_sd
            } else {
                opts.offset_prior_sd_nm
            };
            post[(i, i)] += prior.powi(-2);
        }
        post[(i2, i2)] += 0.05f64.powi(-2);
        let j1_given_j2 = post.try_inverse().expect("a posterior information")[(i1, i1)].sqrt();
        println!(
            "{reps} rounds ({:.1} s): J1 dry sd {:.3} H only, {:.3} with inputs, {j1_given_j2:.3} with J2 dry known to 5 %; J3 dry {:.3} / {:.3}",
            p.t_end_s, h_only.sd_h[i1], with_inputs.sd[i1], h_only.sd_h[i3], with_inputs.sd[i3]
        );
        // The data's weakest directions that hold J1 (information per unit scaled parameter,
        // against the prior's 1/0.5² = 4).
        let nf = n - 1;
        let eig = h_only
            .fisher
            .view((0, 0), (nf, nf))
            .into_owned()
            .symmetric_eigen();
        for k in 0..nf {
            let v = eig.eigenvectors.column(k);
            if v[i1] * v[i1] > 0.003 && eig.eigenvalues[k] < 4.0 {
                let comps: Vec<String> = (0..nf)
                    .filter(|&i| v[i] * v[i] > 0.01)
                    .map(|i| format!("{} {:+.2}", name(h_only.params[i]), v[i]))
                    .collect();
                println!(
                    "    direction with information {:.2e}: {}",
                    eig.eigenvalues[k],
                    comps.join(", ")
                );
            }
        }
        if fits == 0 {
            continue;
        }
        let mut worn = m.clone();
        let mut off = 0.0;
        j1.set(&mut worn, &mut off, 3.0 * j1.get(&m, 0.0));
        let clean = match record(&worn, &p, &Default::default()) {
            Ok(c) => c,
            Err(e) => {
                println!("    J1 ×3: the model cannot run it ({e})");
                continue;
            }
        };
        for seed in 5000..5000 + fits {
            let rec = noise.apply(&clean, seed);
            let fit = match fit_map(&m, &[rec.trace()], &opts) {
                Ok(f) => f,
                Err(e) => {
                    println!("    J1 ×3 seed {seed}: fit failed ({e})");
                    continue;
                }
            };
            let e = |q: LiftParam| fit.params.iter().find(|e| e.param == q).unwrap();
            let (a1, a3) = (e(j1), e(j3));
            let levels: Vec<String> = fit
                .combinations
                .iter()
                .map(|c| {
                    let who: Vec<String> = c.params.iter().map(|q| q.joint().to_string()).collect();
                    format!(
                        "{} {:.2} [{:.2}, {:.2}]{}",
                        who.join("+"),
                        c.value,
                        c.ci95[0],
                        c.ci95[1],
                        if c.informed { "" } else { " (not informed)" }
                    )
                })
                .collect();
            println!(
                "    J1 ×3 seed {seed}: J1 dry {:.2} ± {:.2}, J3 dry {:.2} ± {:.2} (alone: not reported: {}); {}; H RMSE {:.2} mm",
                a1.map_value / a1.baseline,
                a1.posterior_sd / a1.baseline,
                a3.map_value / a3.baseline,
                a3.posterior_sd / a3.baseline,
                !a1.informed && !a3.informed,
                levels.join("; "),
                fit.rmse_m[0] * 1e3
            );
        }
    }
}

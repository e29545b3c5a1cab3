//! How visible a compliant drive is in a lift (issue 16, `drive_compliance`): raise-and-lower
//! lifts of the model with the bellows as spring k, damper c and drive inertia J_d, recorded
//! without noise, against the rigid-drive model driven by the same recorded torque. Prints the
//! H difference (RMS and worst) and the two-mass mode's frequency.
//!
//! `cargo run --release -p pantowatch-models --example lift_compliance_probe -- [K C J_D]...`
use pantowatch_models::lift::dynamics::{DriveCompliance, LiftModel};
use pantowatch_models::lift::geometry::builtin_160ec;
use pantowatch_models::lift::protocol::{LiftProtocol, record};
use pantowatch_models::lift::simulate::{SimOptions, initial_state, simulate};

fn main() {
    let args: Vec<f64> = std::env::args()
        .skip(1)
        .filter_map(|s| s.parse().ok())
        .collect();
    let g = builtin_160ec();
    let base = LiftModel::new(g);
    let protocol = LiftProtocol::raise_and_lower(&base, g).unwrap();
    let pose = base
        .linkage
        .pose(
            initial_state(
                &base,
                &record(&base, &protocol, &SimOptions::default())
                    .unwrap()
                    .inputs(),
                &SimOptions::default(),
            )
            .unwrap()
            .alpha_rad,
        )
        .unwrap();
    let _ = pose;
    for c in args.chunks(3) {
        let [k, cd, jd] = [c[0], c[1], c[2]];
        let mut m = base.clone();
        m.drive_compliance = Some(DriveCompliance {
            stiffness_nm_per_rad: k,
            damping_nms_per_rad: cd,
            inertia_kgm2: jd,
        });
        let rec = match record(&m, &protocol, &SimOptions::default()) {
            Ok(r) => r,
            Err(e) => {
                println!("k {k} c {cd} J_d {jd}: {e}");
                continue;
            }
        };
        let inputs = rec.inputs();
        let o = SimOptions::default();
        let s0 = initial_state(&base, &inputs, &o).unwrap();
        let rigid = simulate(&base, &inputs, s0, &o).unwrap();
        // The compliant model itself driven by the recorded (sampled) torque: what a fit with
        // the true parameters would leave.
        let s1 = initial_state(&m, &inputs, &o).unwrap();
        let own = simulate(&m, &inputs, s1, &o).unwrap();
        let own_rms = (rec
            .strip_height_m
            .iter()
            .zip(&own.strip_height_m)
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            / rec.t_s.len() as f64)
            .sqrt();
        println!(
            "  the compliant model on the recorded torque: H RMS {:.3} mm",
            own_rms * 1e3
        );
        let mut fit_sim = pantowatch_models::lift::identify::LiftFitOptions::default().sim;
        if let Some(h) = std::env::var("FIT_HMAX").ok().and_then(|v| v.parse().ok()) {
            fit_sim.h_max_s = h;
        }
        if let Some(r) = std::env::var("FIT_RTOL").ok().and_then(|v| v.parse().ok()) {
            fit_sim.rtol = r;
        }
        let sens = pantowatch_models::lift::sensitivity::simulate_sensitivities(
            &m,
            &inputs,
            &[],
            0.0,
            &fit_sim,
        )
        .unwrap();
        let sens_rms = (rec
            .strip_height_m
            .iter()
            .zip(&sens.strip_height_m)
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            / rec.t_s.len() as f64)
            .sqrt();
        println!(
            "  at the fit's tolerance (Rosenbrock-W): H RMS {:.3} mm, {} steps",
            sens_rms * 1e3,
            sens.steps
        );
        let d: Vec<f64> = rec
            .strip_height_m
            .iter()
            .zip(&rigid.strip_height_m)
            .map(|(a, b)| a - b)
            .collect();
        let rms = (d.iter().map(|v| v * v).sum::<f64>() / d.len() as f64).sqrt();
        let worst = d.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        println!(
            "k {k:8.0} N·m/rad  c {cd:6.1} N·m·s/rad  J_d {jd:5.2} kg·m²: drive-side mode {:5.1} Hz; H vs rigid RMS {:6.3} mm, worst {:6.3} mm",
            (k / jd).sqrt() / (2.0 * std::f64::consts::PI),
            rms * 1e3,
            worst * 1e3
        );
    }
}

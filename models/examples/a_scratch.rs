use pantowatch_models::dynamics::{Dof, Mechanism};
use pantowatch_models::friction::FrictionLaw;
use pantowatch_models::identify::{
    FitOptions, FitSpec, InitialEstimate, JointTest, Readout, fit_base, fit_window, initial,
};
use pantowatch_models::rig::SliderRig;
use pantowatch_models::synth::{Sensor, Truth, grid, measure_truth};

fn main() {
    let a: Vec<f64> = std::env::args().skip(1).map(|x| x.parse().unwrap()).collect();
    let (viscous, dry, q0, fs, dur, seed) = (a[0], a[1], a[2], a[3], a[4], a[5] as u64);
    let noise = if a.len() > 6 { a[6] } else { 0.05 };
    let t = grid(dur, fs);
    let dof = Dof {
        mech: Mechanism::Slider(SliderRig {
            moving_mass_kg: 10.5,
            stiffness_n_per_m: 4000.0,
            normal_force_n: 4.05,
        }),
        input: None,
        torsion: 0.0,
    };
    let truth = Truth {
        law: FrictionLaw::base(viscous, dry),
        readout: Readout::default(),
        dry_fade: 0.0,
    };
    let sensor = Sensor {
        scale: 1000.0,
        noise_sigma: noise,
        quantum: if noise > 0.0 { 0.01 } else { 0.0 },
        offset: 0.0,
        seed,
    };
    let y = measure_truth(&dof, &truth, q0, 0.0, &t, &sensor).unwrap();
    let test = JointTest {
        dof,
        t_s: t,
        y,
        scale: 1000.0,
        unit: "mm",
        initial_rate: None,
        release_t_s: None,
        body_sd: vec![],
    };
    let opts = FitOptions::default();
    let n = test.t_s.len();
    let id = initial::inverse_dynamics(&test.dof, &test.t_s, &test.y, 1000.0, 0, None, true);
    let en = initial::energy_balance(&test.dof, &test.t_s, &test.y, 1000.0, 0, None);
    println!("inverse dynamics {:.4} {:.5}; energy {:?}", id.viscous, id.dry, en.map(|e| (e.viscous, e.dry, e.offset)));
    let tr = InitialEstimate { viscous, dry, offset: 0.0, q0, v0: 0.0 };
    for (name, init) in [("truth", tr), ("energy", en.unwrap_or(id)), ("invdyn", id)] {
        let f = fit_window(&test, 0, n, &FitSpec::base(init.viscous, init.dry, true), &init, &opts).unwrap();
        let ssr: f64 = f.residual.iter().map(|r| r * r).sum();
        println!(
            "from {name:<7} viscous {:.4} ± {:.4} dry {:.5} ± {:.5} rmse {:.5} ssr {:.5} ev {} events {} white {}",
            f.law.viscous, f.std[0], f.law.dry, f.std[1], f.rmse, ssr, f.evaluations, f.trajectory.events.len(),
            pantowatch_models::stats::is_white(&f.residual)
        );
    }
    let f = fit_base(&test, &opts).unwrap();
    println!("fit_base viscous {:.4} dry {:.5} restarts {}", f.law.viscous, f.law.dry, f.restarts);
}

//! No heap allocation inside an integrator step (issue 8): a counting global allocator (per
//! thread, so parallel tests do not disturb each other) shows that a run's allocations do not
//! depend on how many steps it takes — the same run at a tighter tolerance takes several times
//! the steps with exactly the same allocations (its output buffers, sized up front).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use pantowatch_models::dynamics::{Dof, Mechanism};
use pantowatch_models::friction::{DynParam, FrictionLaw};
use pantowatch_models::lift::dynamics::LiftModel;
use pantowatch_models::lift::geometry::builtin_160ec;
use pantowatch_models::lift::protocol::{LiftProtocol, record};
use pantowatch_models::lift::sensitivity::{LiftParam, simulate_sensitivities};
use pantowatch_models::lift::simulate::{SimOptions, initial_state, simulate};
use pantowatch_models::ode::Tolerances;
use pantowatch_models::rig::PendulumRig;
use pantowatch_models::simulate::{self as joint, SensParam};

struct Counting;

thread_local! {
    static ALLOCS: Cell<usize> = const { Cell::new(0) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let _ = ALLOCS.try_with(|c| c.set(c.get() + 1));
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let _ = ALLOCS.try_with(|c| c.set(c.get() + 1));
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Allocations made on this thread by `f`, and its result.
fn count<R>(f: impl FnOnce() -> R) -> (usize, R) {
    let before = ALLOCS.with(Cell::get);
    let r = f();
    (ALLOCS.with(Cell::get) - before, r)
}

/// The lift integrator with and without forward sensitivities: the paper's raise (1.5 s at
/// 500 Hz), at 10⁻⁵ and at 10⁻⁹ relative tolerance.
#[test]
fn lift_runs_allocate_nothing_per_step() {
    let g = builtin_160ec();
    let m = LiftModel::new(g);
    let p = LiftProtocol {
        t_end_s: 1.0,
        ..LiftProtocol::reference(g)
    };
    let rec = record(&m, &p, &SimOptions::default()).unwrap();
    let inputs = rec.inputs();
    let params = LiftParam::all();
    let opts = |rtol: f64| SimOptions {
        rtol,
        atol: rtol * 1e-2,
        ..Default::default()
    };
    let start = initial_state(&m, &inputs, &opts(1e-5)).unwrap();
    let (a_plain, loose) = count(|| simulate(&m, &inputs, start, &opts(1e-5)).unwrap());
    let (b_plain, tight) = count(|| simulate(&m, &inputs, start, &opts(1e-9)).unwrap());
    let (a_sens, sl) =
        count(|| simulate_sensitivities(&m, &inputs, &params, 0.5, &opts(1e-5)).unwrap());
    let (b_sens, st) =
        count(|| simulate_sensitivities(&m, &inputs, &params, 0.5, &opts(1e-9)).unwrap());
    eprintln!(
        "lift: {} → {} steps, {a_plain} → {b_plain} allocations; with sensitivities {} → {} steps, {a_sens} → {b_sens} allocations",
        loose.steps, tight.steps, sl.steps, st.steps
    );
    assert!(tight.steps >= 2 * loose.steps && st.steps >= 2 * sl.steps);
    assert_eq!(
        a_plain, b_plain,
        "plain lift run: allocations grew with the steps"
    );
    assert_eq!(
        a_sens, b_sens,
        "sensitivity run: allocations grew with the steps"
    );
}

/// The single-joint integrator with sensitivities: a viscous pendulum's first swing (no event,
/// so no event record), at 10⁻⁶ and 10⁻¹¹ relative tolerance.
#[test]
fn joint_runs_allocate_nothing_per_step() {
    let dof = Dof {
        mech: Mechanism::Pendulum(PendulumRig {
            mass_kg: 18.8,
            inertia_kgm2: 5.61,
            com_distance_m: 0.272,
            pin_radius_m: 0.01,
            gravity_m_s2: 9.81,
        }),
        input: None,
        torsion: 0.0,
    };
    let law = FrictionLaw::base(0.05, 0.0);
    let times: Vec<f64> = (0..450).map(|k| k as f64 * 0.002).collect();
    let opts = |rtol: f64| joint::SimOptions {
        tol: Tolerances {
            rtol,
            atol: rtol * 1e-2,
            ..Default::default()
        },
        sens: vec![SensParam::Dyn(DynParam::Viscous), SensParam::Q0],
    };
    let (lo, hi) = (opts(1e-6), opts(1e-11));
    let q0 = 1.2;
    let (a, loose) = count(|| joint::simulate(&dof, &law, q0, 0.0, &times, &lo).unwrap());
    let (b, tight) = count(|| joint::simulate(&dof, &law, q0, 0.0, &times, &hi).unwrap());
    eprintln!(
        "joint: {} → {} steps, {a} → {b} allocations",
        loose.n_steps, tight.n_steps
    );
    assert!(loose.events.is_empty() && tight.events.is_empty());
    assert!(tight.n_steps >= 3 * loose.n_steps);
    assert_eq!(a, b, "single-joint run: allocations grew with the steps");
}

//! No heap allocation inside an integrator step, and buffers reused across fits (issue 8): a
//! counting global allocator (per thread, so parallel tests do not disturb each other) shows
//! that a run's allocations do not depend on how many steps it takes — the same run at a
//! tighter tolerance takes several times the steps with exactly the same allocations (its
//! output buffers, sized up front) — and that a lift fit on a warm workspace allocates no
//! simulation buffers at all.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use pantowatch_models::dynamics::{Dof, Mechanism};
use pantowatch_models::friction::{DynParam, FrictionLaw};
use pantowatch_models::lift::dynamics::LiftModel;
use pantowatch_models::lift::geometry::builtin_160ec;
use pantowatch_models::lift::identify::{LiftFit, LiftFitOptions, fit_map_in};
use pantowatch_models::lift::protocol::{LiftProtocol, record};
use pantowatch_models::lift::sensitivity::{
    LiftParam, SensWorkspace, simulate_sensitivities, simulate_sensitivities_in,
};
use pantowatch_models::lift::simulate::{SimOptions, initial_state, simulate};
use pantowatch_models::lift::topology::RevJoint;
use pantowatch_models::ode::Tolerances;
use pantowatch_models::rig::PendulumRig;
use pantowatch_models::simulate::{self as joint, SensParam};

struct Counting;

thread_local! {
    static ALLOCS: Cell<usize> = const { Cell::new(0) };
    static BYTES: Cell<usize> = const { Cell::new(0) };
}

fn note(bytes: usize) {
    let _ = ALLOCS.try_with(|c| c.set(c.get() + 1));
    let _ = BYTES.try_with(|c| c.set(c.get() + bytes));
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note(layout.size());
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note(new_size);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Allocations made on this thread by `f`, and its result.
fn count<R>(f: impl FnOnce() -> R) -> (usize, R) {
    let ((n, _), r) = count_bytes(f);
    (n, r)
}

/// Allocations and bytes allocated on this thread by `f`, and its result.
fn count_bytes<R>(f: impl FnOnce() -> R) -> ((usize, usize), R) {
    let (n0, b0) = (ALLOCS.with(Cell::get), BYTES.with(Cell::get));
    let r = f();
    ((ALLOCS.with(Cell::get) - n0, BYTES.with(Cell::get) - b0), r)
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

/// Buffers reused across runs and fits: a sensitivity run on a workspace that has held a run
/// as long allocates nothing (and gives the new workspace's result bit for bit), and a whole
/// lift fit on a warm workspace allocates a fraction of what the same fit allocates cold —
/// what is left is the LM's Jacobian and the result, not a buffer per evaluation.
#[test]
fn lift_buffers_are_reused_across_runs_and_fits() {
    let g = builtin_160ec();
    let m = LiftModel::new(g);
    let p = LiftProtocol {
        t_end_s: 1.5,
        ..LiftProtocol::reference(g)
    };
    let rec = record(&m, &p, &SimOptions::default()).unwrap();
    let inputs = rec.inputs();
    let params = LiftParam::all();
    let opts = SimOptions::default();

    let mut ws = SensWorkspace::default();
    let ((cold, _), _) = count_bytes(|| {
        simulate_sensitivities_in(&mut ws, &m, &inputs, &params, 0.5, &opts)
            .unwrap()
            .steps
    });
    // A different linearisation point on the warm workspace, then the first one again.
    let mut worn = m.clone();
    worn.friction.dry_mu[RevJoint::J3.index()] *= 1.8;
    simulate_sensitivities_in(&mut ws, &worn, &inputs, &params, 0.0, &opts).unwrap();
    let ((warm, warm_bytes), _) = count_bytes(|| {
        simulate_sensitivities_in(&mut ws, &m, &inputs, &params, 0.5, &opts)
            .unwrap()
            .steps
    });
    let fresh = simulate_sensitivities(&m, &inputs, &params, 0.5, &opts).unwrap();
    eprintln!("sensitivity run: {cold} allocations cold, {warm} ({warm_bytes} B) warm");
    assert!(cold > 0);
    assert_eq!(
        (warm, warm_bytes),
        (0, 0),
        "a warm sensitivity run allocated"
    );
    let run = ws.run();
    assert_eq!(run.strip_height_m, fresh.strip_height_m);
    assert_eq!(run.d_height, fresh.d_height);
    assert_eq!(
        (run.steps, run.rhs_evaluations),
        (fresh.steps, fresh.rhs_evaluations)
    );

    // Whole fits: a worn trace (J3 dry ×1.5, so the LM takes several evaluations) fitted on a
    // new workspace, then again on the same one.
    let rec_w = record(&worn, &p, &SimOptions::default()).unwrap();
    let trace = [rec_w.trace()];
    let fopts = LiftFitOptions::default();
    let mut fit_ws = SensWorkspace::default();
    let ((_, cold_b), cold_fit) =
        count_bytes(|| fit_map_in(&mut fit_ws, &m, &trace, &fopts).unwrap());
    let ((_, warm_b), warm_fit) =
        count_bytes(|| fit_map_in(&mut fit_ws, &m, &trace, &fopts).unwrap());
    let run_bytes = 8 * rec_w.t_s.len() * (1 + params.len());
    eprintln!(
        "lift fit ({} evaluations): {cold_b} B allocated cold, {warm_b} B warm (one run's output: {run_bytes} B)",
        cold_fit.evaluations
    );
    assert!(cold_fit.evaluations >= 3, "{}", cold_fit.evaluations);
    let v = |f: &LiftFit| f.params.iter().map(|e| e.map_value).collect::<Vec<_>>();
    assert_eq!(v(&cold_fit), v(&warm_fit));
    assert_eq!(cold_fit.evaluations, warm_fit.evaluations);
    // Cold, every buffer is made once; warm, none — the difference is at least a run's output.
    assert!(
        cold_b >= warm_b + run_bytes,
        "warm fit allocated {warm_b} B, cold {cold_b} B"
    );
}

//! The vocabulary's candidates as `report::fit_lift_trace` tries them: one refit each
//! (`lift::effects`), its contract name and parameters.

use super::super::dynamics::LiftModel;
use std::ops::ControlFlow;
use std::panic::AssertUnwindSafe;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Condvar, Mutex};

use super::super::identify::{
    FitWork, LiftFit, LiftFitError, LiftFitOptions, LiftTrace, count_on_this_thread,
    work_on_this_thread,
};

/// A candidate that passed, with its held-out test.
pub(super) struct Named {
    pub(super) found: Found,
    pub(super) hold_after: super::super::holdout::Holdout,
}

/// An effect a candidate's refit found: its contract name and `params`, the fit and the
/// options it was fitted with (for its held-out test).
pub(super) struct Found {
    pub(super) name: &'static str,
    /// The refit's residual RMS over the noise (`lift::residual::diagnose`).
    pub(super) excess_ratio: f64,
    pub(super) params: Vec<(&'static str, serde_json::Value)>,
    pub(super) fit: LiftFit,
    pub(super) opts: LiftFitOptions,
}

/// Try one candidate of the vocabulary on a lift whose plain fit `base` left a model error.
pub(super) fn try_candidate(
    candidate: Candidate,
    model: &LiftModel,
    trace: &LiftTrace,
    base: &LiftFit,
    opts: &LiftFitOptions,
) -> Result<Option<Found>, LiftFitError> {
    use super::super::effects as fx;
    use serde_json::json;
    Ok(match candidate {
        Candidate::Drag => fx::try_quadratic_drag(model, trace, base, opts)?.map(|f| Found {
            name: "quadratic_drag",
            params: vec![
                ("c_a_ns2_per_m2", json!(f.c_a_ns2_per_m2)),
                ("c_a_ns2_per_m2_ci95", json!(f.c_a_ci95)),
            ],
            excess_ratio: f.excess_ratio,
            fit: f.fit,
            opts: fx::drag_options(opts),
        }),
        Candidate::Delay => fx::try_sensor_delay(model, trace, base, opts)?.map(|f| Found {
            name: "sensor_delay",
            params: vec![
                ("delay_s", json!(f.delay_s)),
                ("delay_s_ci95", json!(f.delay_ci95_s)),
            ],
            excess_ratio: f.excess_ratio,
            fit: f.fit,
            opts: fx::delay_options(opts),
        }),
        Candidate::Offset => fx::try_sensor_offset(model, trace, base, opts)?.map(|f| Found {
            name: "sensor_offset",
            params: vec![
                ("offset_m", json!(f.offset_m)),
                ("offset_m_ci95", json!(f.offset_ci95_m)),
            ],
            excess_ratio: f.excess_ratio,
            fit: f.fit,
            opts: fx::offset_options(opts),
        }),
        Candidate::Stribeck => fx::try_stribeck(model, trace, base, opts)?.map(|f| Found {
            name: "stribeck",
            params: vec![
                // A lift cannot tell the lower arm's pins apart (their dry friction is one
                // combination, `lift::attribution`): measured, a Stribeck at J1 is named as
                // well, fitted at J3.
                ("joint", json!(fx::STRIBECK_JOINTS)),
                ("fitted_at", json!(f.joint.name())),
                ("ratio", json!(f.ratio)),
                ("ratio_ci95", json!(f.ratio_ci95)),
                ("stribeck_speed_rad_s", json!(f.speed_rad_s)),
                ("stribeck_speed_rad_s_ci95", json!(f.speed_ci95_rad_s)),
            ],
            excess_ratio: f.excess_ratio,
            fit: f.fit,
            opts: fx::stribeck_options(opts),
        }),
        Candidate::Compliance => {
            fx::try_drive_compliance(model, trace, base, opts)?.map(|f| Found {
                name: "drive_compliance",
                params: vec![
                    ("inertia_kgm2", json!(f.inertia_kgm2)),
                    ("inertia_kgm2_ci95", json!(f.inertia_ci95_kgm2)),
                    ("stiffness_nm_per_rad", json!(f.stiffness_nm_per_rad)),
                    (
                        "stiffness_nm_per_rad_ci95",
                        json!(f.stiffness_ci95_nm_per_rad),
                    ),
                    ("damping_nms_per_rad", json!(f.damping_nms_per_rad)),
                    (
                        "damping_nms_per_rad_ci95",
                        json!(f.damping_ci95_nms_per_rad),
                    ),
                ],
                excess_ratio: f.excess_ratio,
                fit: f.fit,
                opts: fx::compliance_options(opts),
            })
        }
    })
}

/// The vocabulary's lift effects (`lift::effects`).
#[derive(Debug, Clone, Copy)]
pub(super) enum Candidate {
    Drag,
    Delay,
    Offset,
    Stribeck,
    Compliance,
}

/// A passing candidate whose refit leaves its residual within this ratio to the noise ends the
/// search. Measured (`examples/lift_effects_probe`): right effects leave 0.71–0.88 at the
/// stand's noise and 0.99–1.10 at twice it; a wrong one that passed the margins, 1.44–1.71
/// (`quadratic_drag` on a −10 mm H offset).
pub(super) const STOP_RATIO: f64 = 1.15;

impl Candidate {
    /// Its contract name.
    pub(super) fn name(self) -> &'static str {
        match self {
            Candidate::Drag => "quadratic_drag",
            Candidate::Delay => "sensor_delay",
            Candidate::Offset => "sensor_offset",
            Candidate::Stribeck => "stribeck",
            Candidate::Compliance => "drive_compliance",
        }
    }
    pub(super) const ALL: [Candidate; 5] = [
        Candidate::Drag,
        Candidate::Delay,
        Candidate::Offset,
        Candidate::Stribeck,
        Candidate::Compliance,
    ];
}

/// What a candidate tried ahead cost where the loop stopped before it (`report::fit_lift_trace`
/// runs `spare:<effect>` steps after its own): not part of the loop's decisions.
pub(super) struct Spare {
    pub(super) candidate: Candidate,
    pub(super) work: FitWork,
}

/// Tries each of `order` (`try_one`) and hands the results to `consume` in that order, until
/// it says stop; returns what candidates tried ahead and never consumed cost ([`Spare`]).
///
/// Where the OS offers two cores or more, two threads try the candidates ahead of `consume`,
/// in order, each under a budget of its own inside the caller's
/// (`numerics::budget::child`): once `consume` stops, those still running are cancelled, none
/// is started. Each refit is the same deterministic computation on any thread
/// (`identify::fit_map_in`) and `consume` sees the results in the same order, their work
/// counted on this thread first (`identify::count_on_this_thread`), so the loop's decisions
/// and its work per step are those of trying them one after the other; only the spare work is
/// added. Assumption: a lift's fit has the machine's cores to itself (the bench's one lift at a
/// time, the CLI); a worker running one fit per core pays the spare work for nothing.
pub(super) fn tried_in_order<T, C>(
    order: &[Candidate],
    try_one: impl Fn(Candidate) -> T + Sync,
    mut consume: C,
) -> Result<Vec<Spare>, LiftFitError>
where
    T: Send,
    C: FnMut(Candidate, T) -> Result<ControlFlow<()>, LiftFitError>,
{
    use crate::numerics::budget;
    let n = order.len();
    let cores = std::thread::available_parallelism().map_or(1, usize::from);
    if cores < 2 || n < 2 {
        for &c in order {
            if consume(c, try_one(c))?.is_break() {
                break;
            }
        }
        return Ok(Vec::new());
    }
    let next = AtomicUsize::new(0);
    let stop = AtomicBool::new(false);
    let slots: Mutex<Vec<Slot<T>>> = Mutex::new((0..n).map(|_| None).collect());
    let ready = Condvar::new();
    let parent = budget::current();
    let children: Vec<_> = (0..n).map(|_| budget::child(&parent)).collect();
    let lock = || slots.lock().unwrap_or_else(|p| p.into_inner());
    let mut consumed = 0;
    let outcome = std::thread::scope(|s| {
        for _ in 0..AHEAD_THREADS {
            s.spawn(|| {
                while !stop.load(Ordering::Relaxed) {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    if i >= n {
                        break;
                    }
                    let r = std::panic::catch_unwind(AssertUnwindSafe(|| {
                        budget::enter(&children[i].0, || {
                            let before = work_on_this_thread();
                            let r = try_one(order[i]);
                            (r, work_on_this_thread() - before)
                        })
                    }));
                    lock()[i] = Some(r);
                    ready.notify_all();
                }
            });
        }
        let mut outcome = Ok(());
        for (i, &c) in order.iter().enumerate() {
            let r = {
                let mut g = lock();
                loop {
                    if let Some(r) = g[i].take() {
                        break r;
                    }
                    g = ready.wait(g).unwrap_or_else(|p| p.into_inner());
                }
            };
            let (r, work) = match r {
                Ok(v) => v,
                Err(p) => {
                    stop.store(true, Ordering::Relaxed);
                    children.iter().for_each(|c| c.1.cancel());
                    std::panic::resume_unwind(p)
                }
            };
            count_on_this_thread(work);
            consumed = i + 1;
            match consume(c, r) {
                Ok(ControlFlow::Continue(())) => {}
                Ok(ControlFlow::Break(())) => break,
                Err(e) => {
                    outcome = Err(e);
                    break;
                }
            }
        }
        stop.store(true, Ordering::Relaxed);
        children[consumed..].iter().for_each(|c| c.1.cancel());
        outcome
    });
    outcome?;
    let slots = slots.into_inner().unwrap_or_else(|p| p.into_inner());
    Ok(slots
        .into_iter()
        .enumerate()
        .skip(consumed)
        .filter_map(|(i, r)| match r {
            Some(Ok((_, work))) => Some(Spare {
                candidate: order[i],
                work,
            }),
            _ => None,
        })
        .collect())
}

/// A candidate's result and work as a thread of [`tried_in_order`] left it (its panic, if it
/// panicked).
type Slot<T> = Option<std::thread::Result<(T, FitWork)>>;

/// Threads trying candidates ahead of the loop ([`tried_in_order`]): the bench's machine has
/// two cores, and the drag's and the compliant drive's two starts each run on two threads
/// already (`identify::join`).
const AHEAD_THREADS: usize = 2;

//! The lift fits' work, counted per thread: model evaluations and integrator steps
//! (deterministic, so the residual loop's cost is measured in it).

use std::cell::Cell;

thread_local! {
    /// This thread's lift-fit work so far: model evaluations (each one run with sensitivities)
    /// and their integrator steps ([`work_on_this_thread`]).
    static WORK: Cell<FitWork> = const { Cell::new(FitWork { evaluations: 0, steps: 0 }) };
}

/// Lift-fit work: model evaluations ([`fit_map`]'s, each one integration of the state with its
/// sensitivities) and the integrator steps they took. Deterministic (the same on a loaded
/// machine), so the residual loop's cost is measured in it (`report::LiftReport::work`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FitWork {
    pub evaluations: usize,
    pub steps: usize,
}

impl std::ops::Sub for FitWork {
    type Output = FitWork;
    fn sub(self, o: FitWork) -> FitWork {
        FitWork {
            evaluations: self.evaluations - o.evaluations,
            steps: self.steps - o.steps,
        }
    }
}

/// The lift fits' work on this thread since it started (differences of two readings give a
/// step's work).
pub fn work_on_this_thread() -> FitWork {
    WORK.with(Cell::get)
}

/// Count `evaluations` and `steps` as done on this thread.
pub(super) fn count_work(evaluations: usize, steps: usize) {
    WORK.with(|w| {
        let v = w.get();
        w.set(FitWork {
            evaluations: v.evaluations + evaluations,
            steps: v.steps + steps,
        })
    });
}

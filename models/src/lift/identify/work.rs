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

/// `a` on this thread and `b` on a scoped thread at once (where the OS offers more than one
/// core; else one after the other): `b` under this thread's fit budget
/// (`numerics::budget::enter`), its work counted on this thread when it ends, so the counts
/// are those of running them in turn. Each fit is the same deterministic computation on any
/// thread (`fit_map_in`), so the results are too.
pub fn join<A, B>(a: impl FnOnce() -> A, b: impl FnOnce() -> B + Send) -> (A, B)
where
    B: Send,
{
    if std::thread::available_parallelism().map_or(1, usize::from) < 2 {
        let ra = a();
        return (ra, b());
    }
    let budget = crate::numerics::budget::current();
    let (ra, (rb, w)) = std::thread::scope(|s| {
        let h = s.spawn(|| {
            crate::numerics::budget::enter(&budget, || {
                let before = work_on_this_thread();
                let r = b();
                (r, work_on_this_thread() - before)
            })
        });
        let ra = a();
        match h.join() {
            Ok(v) => (ra, v),
            Err(p) => std::panic::resume_unwind(p),
        }
    });
    count_work(w.evaluations, w.steps);
    (ra, rb)
}

/// Count `work` (done on another thread for this one) as done on this thread.
pub(crate) fn count_on_this_thread(work: FitWork) {
    count_work(work.evaluations, work.steps);
}

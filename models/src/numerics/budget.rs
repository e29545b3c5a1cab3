//! A fit's budget: how many model evaluations it may spend, and a flag that stops it early.
//! Set for the thread (and the threads it starts) that run one fit; the fitters charge it.
//!
//! Every Levenberg–Marquardt evaluation is charged one unit ([`charge`]); the integrators of
//! the lift and the quadrangle poll [`cancelled`] between steps, so one long evaluation is cut
//! short too. Once the budget is spent, every later charge fails at once, so a fit that keeps
//! going (a residual loop trying candidates) ends within one evaluation of each stage; the
//! caller of [`run`] learns that it was spent and must not use the result.
//!
//! Assumption: one evaluation is one simulation of the trace (with its sensitivities), the
//! unit of work every fitter shares; its cost differs by test kind (a pendulum ~0.1 ms, a lift
//! ~20 ms), so the budget bounds runaway iteration, while the wall-time limit is the caller's
//! (it flips the flag through a [`Canceller`]). Without a budget set, nothing is limited.

use std::cell::RefCell;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// Why a fit's budget ran out.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum Exhausted {
    /// More model evaluations than the budget allows.
    #[error("the fit needed more than {0} model evaluations")]
    Evaluations(u64),
    /// The caller stopped it (its wall-time limit, a shutdown).
    #[error("the fit was stopped by its caller")]
    Cancelled,
}

#[derive(Debug)]
struct Shared {
    max_evaluations: u64,
    evaluations: AtomicU64,
    cancel: Arc<AtomicBool>,
    /// The budget this one runs inside ([`child`]): charged with it, spent when it is.
    parent: Option<Arc<Shared>>,
}

impl Shared {
    fn state(&self) -> Result<(), Exhausted> {
        if self.cancel.load(Ordering::Relaxed) {
            Err(Exhausted::Cancelled)
        } else if self.evaluations.load(Ordering::Relaxed) > self.max_evaluations {
            Err(Exhausted::Evaluations(self.max_evaluations))
        } else {
            self.parent.as_ref().map_or(Ok(()), |p| p.state())
        }
    }
    /// Charges one evaluation here and to every budget this one runs inside.
    fn charge(&self) {
        self.evaluations.fetch_add(1, Ordering::Relaxed);
        if let Some(p) = &self.parent {
            p.charge();
        }
    }
}

/// A budget for one fit.
#[derive(Debug, Clone)]
pub struct Budget {
    shared: Arc<Shared>,
}

/// Stops the fit of a [`Budget`] from another thread.
#[derive(Debug, Clone)]
pub struct Canceller(Arc<AtomicBool>);

impl Canceller {
    pub fn cancel(&self) {
        self.0.store(true, Ordering::Relaxed);
    }
}

impl Budget {
    /// At most `max_evaluations` model evaluations.
    pub fn new(max_evaluations: u64) -> Self {
        Self {
            shared: Arc::new(Shared {
                max_evaluations,
                evaluations: AtomicU64::new(0),
                cancel: Arc::new(AtomicBool::new(false)),
                parent: None,
            }),
        }
    }

    /// A handle that stops this budget's fit.
    pub fn canceller(&self) -> Canceller {
        Canceller(self.shared.cancel.clone())
    }

    /// Evaluations charged so far.
    pub fn evaluations(&self) -> u64 {
        self.shared.evaluations.load(Ordering::Relaxed)
    }
}

thread_local! {
    static CURRENT: RefCell<Option<Arc<Shared>>> = const { RefCell::new(None) };
}

/// Restores the thread's previous budget when dropped (also on unwind).
struct Scope(Option<Arc<Shared>>);

impl Drop for Scope {
    fn drop(&mut self) {
        let prev = self.0.take();
        CURRENT.with(|c| *c.borrow_mut() = prev);
    }
}

/// Runs `f` under `budget` on this thread: `Err` when the budget ran out at any point (the
/// result of `f` is then dropped: it was computed with stages cut short).
pub fn run<R>(budget: &Budget, f: impl FnOnce() -> R) -> Result<R, Exhausted> {
    let prev = CURRENT.with(|c| c.borrow_mut().replace(budget.shared.clone()));
    let _scope = Scope(prev);
    let out = f();
    budget.shared.state().map(|()| out)
}

/// The budget set on this thread, to carry into threads a fit starts ([`enter`]).
#[derive(Debug, Clone, Default)]
pub struct Handle(Option<Arc<Shared>>);

/// This thread's budget, for [`enter`] in a worker thread.
pub fn current() -> Handle {
    Handle(CURRENT.with(|c| c.borrow().clone()))
}

/// A budget inside `h`'s (none: unlimited) that a [`Canceller`] of its own can stop without
/// stopping `h`'s fit: its evaluations are charged to `h`'s budget too, and it is spent or
/// cancelled whenever `h`'s is. For work started ahead of need that may be dropped (the lift
/// loop's candidates tried on another thread, `lift::report`). Run under it with [`enter`].
pub fn child(h: &Handle) -> (Handle, Canceller) {
    let cancel = Arc::new(AtomicBool::new(false));
    let shared = Arc::new(Shared {
        max_evaluations: u64::MAX,
        evaluations: AtomicU64::new(0),
        cancel: cancel.clone(),
        parent: h.0.clone(),
    });
    (Handle(Some(shared)), Canceller(cancel))
}

/// Runs `f` on this thread under the budget `h` was taken from.
pub fn enter<R>(h: &Handle, f: impl FnOnce() -> R) -> R {
    let prev = CURRENT.with(|c| std::mem::replace(&mut *c.borrow_mut(), h.0.clone()));
    let _scope = Scope(prev);
    f()
}

/// Charges one model evaluation; `Err` once the budget is spent or cancelled (then the caller
/// stops instead of evaluating). Without a budget, always `Ok`.
pub fn charge() -> Result<(), Exhausted> {
    CURRENT.with(|c| match &*c.borrow() {
        None => Ok(()),
        Some(s) => {
            s.charge();
            s.state()
        }
    })
}

/// Whether this thread's fit has been cancelled or has spent its evaluations (for loops inside
/// one evaluation, polled every few hundred steps).
pub fn cancelled() -> bool {
    CURRENT.with(|c| c.borrow().as_ref().is_some_and(|s| s.state().is_err()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn charges_past_the_limit_fail_and_the_run_says_so() {
        let b = Budget::new(3);
        let r = run(&b, || (0..10).filter(|_| charge().is_ok()).count());
        assert_eq!(r, Err(Exhausted::Evaluations(3)));
        assert_eq!(b.evaluations(), 10);
        // Outside the run nothing is limited.
        assert!(charge().is_ok() && !cancelled());
        let ok = run(&Budget::new(5), || {
            (0..5).filter(|_| charge().is_ok()).count()
        });
        assert_eq!(ok, Ok(5));
    }

    #[test]
    fn a_cancel_from_another_thread_stops_the_run_and_reaches_its_threads() {
        let b = Budget::new(u64::MAX);
        let c = b.canceller();
        let r = run(&b, || {
            let h = current();
            std::thread::scope(|s| {
                s.spawn(|| {
                    enter(&h, || {
                        c.cancel();
                        assert!(cancelled());
                        assert_eq!(charge(), Err(Exhausted::Cancelled));
                    })
                });
            });
            cancelled()
        });
        assert_eq!(r, Err(Exhausted::Cancelled));
    }

    #[test]
    fn a_child_charges_its_parent_and_stops_alone_or_with_it() {
        let b = Budget::new(5);
        let r = run(&b, || {
            let (h, stop) = child(&current());
            assert_eq!(enter(&h, || (0..3).filter(|_| charge().is_ok()).count()), 3);
            stop.cancel();
            assert_eq!(enter(&h, charge), Err(Exhausted::Cancelled));
            // The parent's fit goes on (the 5th charge: the child's cancelled one counted too).
            assert_eq!(charge(), Ok(()));
            // A second child ends with the parent's budget (the 6th charge is over it).
            let (h2, _) = child(&current());
            assert_eq!(enter(&h2, charge), Err(Exhausted::Evaluations(5)));
        });
        assert_eq!(r, Err(Exhausted::Evaluations(5)));
        assert_eq!(b.evaluations(), 6);
        // Without a budget a child is unlimited until cancelled.
        let (h, stop) = child(&Handle::default());
        assert!(enter(&h, || charge().is_ok() && !cancelled()));
        stop.cancel();
        assert_eq!(enter(&h, charge), Err(Exhausted::Cancelled));
    }
}

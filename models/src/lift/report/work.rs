//! What each step of a lift's residual loop cost (`report::fit_lift_trace`): model evaluations
//! and integrator steps (`identify::FitWork`), in the order the loop ran them.

use super::super::identify::{FitWork, work_on_this_thread};

/// One step of [`super::fit_lift_trace`]'s loop and its work (`identify::FitWork`): `plain`, the
/// reported-only refit `reported_only`, `holdout` (the base model's held-out refits), each
/// candidate's refit(s) `try:<effect>` and held-out refits `holdout:<effect>`, the named
/// effect's refit with every joint free `report:<effect>`; then `spare:<effect>`, candidates
/// tried ahead on another thread that the loop stopped before judging (not in its decisions).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LoopStep {
    pub step: String,
    pub work: FitWork,
}

/// Records the work of each loop step as it ends.
pub(super) struct Meter {
    last: FitWork,
    pub(super) steps: Vec<LoopStep>,
}

impl Meter {
    pub(super) fn start() -> Meter {
        Meter {
            last: work_on_this_thread(),
            steps: Vec::new(),
        }
    }
    /// The work since the last mark, as `step`.
    pub(super) fn mark(&mut self, step: impl Into<String>) {
        let now = work_on_this_thread();
        self.steps.push(LoopStep {
            step: step.into(),
            work: now - self.last,
        });
        self.last = now;
    }
    /// Work done on another thread for a step the loop did not use (`spare:<effect>`: a
    /// candidate tried ahead, `report::candidates::tried_in_order`), not counted on this one.
    pub(super) fn spare(&mut self, step: impl Into<String>, work: FitWork) {
        self.steps.push(LoopStep {
            step: step.into(),
            work,
        });
    }
}

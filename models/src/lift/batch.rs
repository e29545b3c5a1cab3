//! Many lift fits on all cores (issue 8: a year of monthly lift tests for a fleet): a work
//! queue of independent fits drained by scoped threads, results in input order.
//!
//! Plain `std::thread::scope` with an atomic next-item counter rather than rayon: the work items
//! are coarse (one fit is 0.1–1 s of CPU), so a shared counter is all the scheduling they need,
//! and the models crate stays free of a thread-pool dependency. Progress is reported through a
//! callback so only the caller (the CLI) knows about progress bars.

use std::num::NonZeroUsize;
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use super::dynamics::LiftModel;
use super::identify::{LiftFit, LiftFitError, LiftFitOptions, LiftTrace, fit_map};

/// Worker threads for `threads`: the number given, or every core the OS offers when `None`;
/// never more than there are items.
fn workers(threads: Option<NonZeroUsize>, items: usize) -> usize {
    let t = threads
        .or_else(|| std::thread::available_parallelism().ok())
        .map_or(1, NonZeroUsize::get);
    t.min(items).max(1)
}

/// Apply `f` to every item on `threads` worker threads (`None`: all cores), each thread taking
/// the next unclaimed item from a shared counter. Returns the results in input order.
/// `progress(done)` is called after each item completes with the number completed so far (from
/// the worker thread that completed it; calls from different threads may interleave, `done`
/// only grows). A panic in `f` propagates to the caller once the other workers stop.
pub fn map<T, R, F>(
    items: &[T],
    threads: Option<NonZeroUsize>,
    progress: &(dyn Fn(usize) + Sync),
    f: F,
) -> Vec<R>
where
    T: Sync,
    R: Send,
    F: Fn(&T) -> R + Sync,
{
    let n = items.len();
    if n == 0 {
        return Vec::new();
    }
    let next = AtomicUsize::new(0);
    let done = AtomicUsize::new(0);
    let slots: Mutex<Vec<Option<R>>> = Mutex::new((0..n).map(|_| None).collect());
    // The caller's fit budget (if any) holds in every worker thread.
    let budget = crate::numerics::budget::current();
    std::thread::scope(|scope| {
        for _ in 0..workers(threads, n) {
            scope.spawn(|| {
                crate::numerics::budget::enter(&budget, || {
                    loop {
                        let i = next.fetch_add(1, Ordering::Relaxed);
                        if i >= n {
                            break;
                        }
                        let r = f(&items[i]);
                        // A poisoned lock means another worker panicked: keep the result anyway,
                        // the scope re-raises that panic.
                        slots.lock().unwrap_or_else(|p| p.into_inner())[i] = Some(r);
                        progress(done.fetch_add(1, Ordering::Relaxed) + 1);
                    }
                })
            });
        }
    });
    slots
        .into_inner()
        .unwrap_or_else(|p| p.into_inner())
        .into_iter()
        .map(|r| r.expect("every item is claimed exactly once and filled"))
        .collect()
}

/// Fit every trace on its own ([`fit_map`] of one trace: one lift test of one pantograph) on
/// `threads` threads (`None`: all cores), the fits independent of each other and of the thread
/// count (each is the same deterministic computation as a lone [`fit_map`]). Results in input
/// order; a trace that cannot be fitted gives its error, the others still run.
/// `progress(done)`: see [`map`].
pub fn fit_many(
    model: &LiftModel,
    traces: &[LiftTrace<'_>],
    opts: &LiftFitOptions,
    threads: Option<NonZeroUsize>,
    progress: &(dyn Fn(usize) + Sync),
) -> Vec<Result<LiftFit, LiftFitError>> {
    map(traces, threads, progress, |t| {
        fit_map(model, std::slice::from_ref(t), opts)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicUsize;

    #[test]
    fn map_keeps_input_order_and_reports_every_item() {
        let items: Vec<u64> = (0..37).collect();
        let calls = AtomicUsize::new(0);
        let last = AtomicUsize::new(0);
        let progress = |d: usize| {
            calls.fetch_add(1, Ordering::Relaxed);
            last.fetch_max(d, Ordering::Relaxed);
        };
        let out = map(&items, NonZeroUsize::new(3), &progress, |&x| {
            // Uneven work so that threads finish out of order.
            std::hint::black_box((0..(x % 5) * 1000).fold(x, |a, b| a.wrapping_add(b % 3)));
            x * x
        });
        assert_eq!(out, items.iter().map(|x| x * x).collect::<Vec<_>>());
        assert_eq!(calls.load(Ordering::Relaxed), items.len());
        assert_eq!(last.load(Ordering::Relaxed), items.len());
        assert!(map(&[] as &[u8], None, &|_| {}, |&x| x).is_empty());
    }

    /// Two short noisy lifts (the first 1.5 s of the paper's raise, 250 Hz) fitted on two
    /// threads give exactly what lone sequential fits give.
    #[test]
    fn fit_many_equals_lone_fits_in_order() {
        use crate::lift::protocol::{LiftProtocol, record};
        use crate::lift::simulate::SimOptions;
        use crate::numerics::noise::Noise;
        let g = crate::lift::geometry::builtin_160ec();
        let m = LiftModel::new(g);
        let p = LiftProtocol {
            t_end_s: 1.0,
            sample_hz: 250.0,
            ..LiftProtocol::reference(g)
        };
        let mut worn = m.clone();
        worn.friction.dry_mu[crate::lift::topology::RevJoint::J3.index()] *= 1.5;
        let recs: Vec<_> = [&m, &worn]
            .iter()
            .map(|mm| record(mm, &p, &SimOptions::default()).unwrap())
            .collect();
        let hs: Vec<Vec<f64>> = recs
            .iter()
            .enumerate()
            .map(|(i, r)| {
                let mut rng = Noise::new(3 + i as u64);
                r.strip_height_m
                    .iter()
                    .map(|h| h + 1e-3 * rng.normal())
                    .collect()
            })
            .collect();
        let traces: Vec<LiftTrace> = recs
            .iter()
            .zip(&hs)
            .map(|(r, h)| LiftTrace {
                inputs: r.inputs(),
                strip_height_m: h,
            })
            .collect();
        let opts = LiftFitOptions::default();
        let many = fit_many(&m, &traces, &opts, NonZeroUsize::new(2), &|_| {});
        for (t, got) in traces.iter().zip(many) {
            let got = got.unwrap();
            let want = fit_map(&m, std::slice::from_ref(t), &opts).unwrap();
            let v = |f: &LiftFit| f.params.iter().map(|e| e.map_value).collect::<Vec<_>>();
            assert_eq!(v(&got), v(&want));
            assert_eq!(got.evaluations, want.evaluations);
        }
    }

    #[test]
    fn fit_many_reports_a_bad_trace_and_fits_the_rest() {
        let g = crate::lift::geometry::builtin_160ec();
        let m = LiftModel::new(g);
        let t: Vec<f64> = vec![0.0, 0.1];
        let short = vec![1.0, 1.0];
        let bad = LiftTrace {
            inputs: crate::lift::simulate::LiftInputs {
                t_s: &t,
                torque_nm: &short,
                fs_n: &short,
                fm_n: &[],
            },
            strip_height_m: &short[..1],
        };
        let out = fit_many(&m, &[bad, bad], &LiftFitOptions::default(), None, &|_| {});
        assert_eq!(out.len(), 2);
        for r in out {
            let e = r.unwrap_err().to_string();
            assert!(e.contains("`H_m`"), "{e}");
        }
    }
}

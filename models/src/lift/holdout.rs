//! The held-out test of a lift fit (issue 16, point 1): time blocks left out of a refit, and the
//! refit's error on them. What the fit did not see tells a model that follows the data from one
//! that only soaks it up.
//!
//! Protocol (stated choices, measured with `examples/lift_effects_probe`):
//! - Segments: the record in blocks of [`BLOCK_S`]; every fourth block (the third, seventh, …)
//!   is held out, a quarter of the record spread over the raise and the lower. Tried first and
//!   dropped: fitting the raise and judging the lower. A lift drives the model open-loop with
//!   almost no net stiffness, so the raise's friction extrapolated over the lower drifted by
//!   13–37 mm RMS on correct lifts (0.5 mm noise): that split judges extrapolation, not the
//!   model. Interleaved blocks keep the fit anchored on both sides of each held-out block.
//! - A record with fewer than [`MIN_HELD_OUT_BLOCKS`] held-out blocks (under 3.5 s) gets no
//!   held-out figure, and the residual says why ([`Holdout::Short`]).
//! - When: `report::fit_lift_trace` runs it only where an effect is tried (it judges the
//!   effect); run on every lift it doubled the fit's cost.
//! - The refit without the held-out blocks starts at the whole-trace fit's MAP
//!   (`LiftFitOptions::start`): a few evaluations instead of ~25. The start carries nothing of
//!   the held-out data but where to begin; the LM converges to the masked problem's own optimum
//!   (one basin: the whole-trace fit is its neighbour). The model at that optimum is then run
//!   over the whole record (one evaluation) and compared with the measured H on the held-out
//!   blocks.
//! - Effects that are fitted parameters (a drag) are refitted with the friction; a delay, a
//!   shift of the record, is held at the whole-trace value.

use super::dynamics::LiftModel;
use super::identify::{LiftFit, LiftFitError, LiftFitOptions, LiftTrace, fit_map};
use crate::joint::identify::lm::LmOptions;

/// Length of a block, s: several head-bounce periods (≈ 0.2 s on J9), short beside a lift.
pub const BLOCK_S: f64 = 0.5;
/// Every this-many blocks, one is held out (the third of each run of four).
pub const HOLD_EVERY: usize = 4;
/// Fewest held-out blocks for a held-out figure: 2, so the record needs 3.5 s.
pub const MIN_HELD_OUT_BLOCKS: usize = 2;

/// An effect must bring the held-out RMSE to at most this share of the plain model's: the
/// held-out segment is where a term that only soaks up noise or another error shows.
pub const MAX_HOLDOUT_RATIO: f64 = 0.75;

/// An effect whose held-out RMSE is within this multiple of the sensor noise (and below the
/// plain model's) passes too: it predicts the held-out blocks as well as the noise lets any
/// model. Without it a lift whose plain model happened to miss little on the held-out blocks
/// (measured: c_a 4, plain 1.38 mm on the whole trace but 0.66 mm held out, noise 0.5 mm)
/// could not pass at all, since 0.75 × 0.66 mm is under the noise. The same 1.15 as the
/// search's stop (`report`): right effects leave 0.71–1.10× the noise.
pub const HOLDOUT_NOISE_RATIO: f64 = 1.15;

/// Does `after` (the augmented model's test) pass against `before` (the plain model's)?
/// `noise_m` is the sensor noise the augmented fit's residual shows (first differences).
/// Where either test was not run, nothing to judge: true (the residual says why).
pub fn improves(before: &Holdout, after: &Holdout, noise_m: f64) -> bool {
    match (before.holdout_rmse_m(), after.holdout_rmse_m()) {
        (Some(b), Some(a)) => {
            a <= MAX_HOLDOUT_RATIO * b || (a < b && a <= HOLDOUT_NOISE_RATIO * noise_m)
        }
        _ => true,
    }
}

/// The held-out test's outcome.
#[derive(Debug, Clone, PartialEq)]
pub enum Holdout {
    /// RMSE on the fit segment (after the refit on it) and on the held-out one, m.
    Judged {
        held_out_samples: usize,
        fit_rmse_m: f64,
        holdout_rmse_m: f64,
    },
    /// No held-out test: the reason, in words.
    Short(String),
}

impl Holdout {
    pub fn holdout_rmse_m(&self) -> Option<f64> {
        match self {
            Holdout::Judged { holdout_rmse_m, .. } => Some(*holdout_rmse_m),
            Holdout::Short(_) => None,
        }
    }
}

/// Which samples are held out: those in every [`HOLD_EVERY`]th block of [`BLOCK_S`] (block
/// index ≡ 2 mod 4), and how many whole blocks that holds out.
pub fn mask(t_s: &[f64]) -> (Vec<bool>, usize) {
    let Some(&t0) = t_s.first() else {
        return (Vec::new(), 0);
    };
    let block = |t: f64| ((t - t0) / BLOCK_S).floor().max(0.0) as usize;
    let m: Vec<bool> = t_s.iter().map(|&t| block(t) % HOLD_EVERY == 2).collect();
    let last = t_s.last().map_or(0, |&t| block(t));
    // Whole held-out blocks: those that end before the record does.
    let whole = (0..last).filter(|b| b % HOLD_EVERY == 2).count();
    (m, whole)
}

/// Refits `trace` without its held-out blocks, starting from `full` (its whole-trace fit with
/// `opts`), and judges it on them.
pub fn blocks(
    model: &LiftModel,
    trace: &LiftTrace,
    full: &LiftFit,
    opts: &LiftFitOptions,
) -> Result<Holdout, LiftFitError> {
    let t = trace.inputs.t_s;
    let h = trace.strip_height_m;
    let n = h.len().min(t.len());
    let (held, whole) = mask(&t[..n]);
    if whole < MIN_HELD_OUT_BLOCKS {
        let span = if n > 1 { t[n - 1] - t[0] } else { 0.0 };
        return Ok(Holdout::Short(format!(
            "held-out test not run: the record is {span:.2} s; holding out every {HOLD_EVERY}th \
             {BLOCK_S} s block needs at least {MIN_HELD_OUT_BLOCKS} whole blocks held out \
             (3.5 s of record)"
        )));
    }
    let masked = LiftFitOptions {
        start: Some(full.start_point()),
        holdout_mask: Some(held.clone()),
        ..opts.clone()
    };
    let refit = match fit_map(model, std::slice::from_ref(trace), &masked) {
        Ok(f) => f,
        Err(LiftFitError::Failed(e)) => {
            return Ok(Holdout::Short(format!(
                "held-out test not run: the fit without the held-out blocks failed ({e})"
            )));
        }
        Err(e) => return Err(e),
    };
    // The whole record at the masked optimum: one evaluation, no step.
    let predict = LiftFitOptions {
        start: Some(refit.start_point()),
        lm: LmOptions {
            max_iter: 0,
            ..opts.lm
        },
        ..opts.clone()
    };
    let whole_run = match fit_map(model, std::slice::from_ref(trace), &predict) {
        Ok(f) => f,
        Err(LiftFitError::Failed(e)) => {
            return Ok(Holdout::Short(format!(
                "held-out test not run: the refit's model does not run over the record ({e})"
            )));
        }
        Err(e) => return Err(e),
    };
    let Some(model_h) = whole_run.fitted_height_m.first().filter(|m| m.len() == n) else {
        return Ok(Holdout::Short(
            "held-out test not run: no prediction".into(),
        ));
    };
    let (mut ss_fit, mut n_fit, mut ss_out, mut n_out) = (0.0, 0usize, 0.0, 0usize);
    for k in 0..n {
        let e2 = (model_h[k] - h[k]).powi(2);
        if held[k] {
            ss_out += e2;
            n_out += 1;
        } else {
            ss_fit += e2;
            n_fit += 1;
        }
    }
    Ok(Holdout::Judged {
        held_out_samples: n_out,
        fit_rmse_m: (ss_fit / n_fit.max(1) as f64).sqrt(),
        holdout_rmse_m: (ss_out / n_out.max(1) as f64).sqrt(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_fourth_block_is_held_out() {
        let t: Vec<f64> = (0..2000).map(|k| k as f64 / 500.0).collect();
        let (m, whole) = mask(&t);
        // 4 s: blocks 0–7, held out 2 and 6 (1.0–1.5 s and 3.0–3.5 s).
        assert_eq!(whole, 2);
        assert!(!m[499] && m[500] && m[749] && !m[750]);
        assert!(m[1500] && !m[1750]);
        assert_eq!(m.iter().filter(|v| **v).count(), 500);
        let (_, short) = mask(&t[..1500]);
        assert_eq!(short, 1);
        assert_eq!(mask(&[]).1, 0);
    }
}

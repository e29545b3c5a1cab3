//! A designed on-vehicle lift test (issue 15, point 3): what a protocol can tell about every
//! Table 4 parameter (Fisher information, predicted sds with H and input noise), the stand's
//! limits a protocol must keep, and a D-optimal sequence of drive set-point moves within them.
//!
//! The family searched: the paper's raise (`LiftProtocol::reference`, 0–3.5 s), then moves, each
//! a pressure step of the pneumatic drive to the frictionless holding torque of a target height
//! at one of several speeds (time constant τ), held for one of several dwells. Greedy
//! sequential design: each step appends the move that most raises log det of the posterior
//! information (Bayesian D-optimality with the fit's Table 4 prior), until the duration limit.

use nalgebra::DMatrix;

use super::dynamics::LiftModel;
use super::geometry::Geometry;
use super::identify::{LiftFitError, LiftFitOptions, inverse_spd, scaled_jacobian};
use super::inputs::{ChannelReconstruction, InputReconstruction};
use super::protocol::{LiftProtocol, Move, record};
use super::sensitivity::LiftParam;
use super::sensors::LiftSensorNoise;
use super::simulate::SimOptions;
use super::statics::{StaticFriction, alpha_at_height, static_point};

/// What a lift protocol may ask of the stand and the drive. Every number is an assumption
/// about the depot's stand, stated here and in the README:
/// - heights: Table 1's operating range 0.8–1.8 m, extended to the paper's own test top 1.84 m;
/// - τ ≥ 0.4 s: the pneumatic drive's pressure response, half the 0.8 s the reference trace's
///   raise shows (`lift-example.meta.json`) — bellows fill no faster; τ ≤ 4 s (slow ramps);
/// - dwell ≥ 1 s between moves (the head settles, ~0.2 s bounce period on J9);
/// - a test lasts at most 12 s (8 s in the paper): the longest whose fit was validated, not
///   the stand's own limit (`[stand] duration_max_s` of the geometry file states why);
/// - set torque within the drive's range (`[drive] torque_range_Nm` of the geometry file).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProtocolLimits {
    pub height_range_m: [f64; 2],
    pub tau_range_s: [f64; 2],
    pub dwell_min_s: f64,
    pub duration_max_s: f64,
    pub torque_range_nm: [f64; 2],
}

impl ProtocolLimits {
    /// The stated stand (type doc) for geometry `g`.
    pub fn stand(g: &Geometry) -> Self {
        let s = g
            .stand
            .or(super::geometry::builtin_160ec().stand)
            .expect("the built-in geometry file states [stand] (geometry::tests)");
        Self {
            height_range_m: s.height_range_m,
            tau_range_s: s.tau_range_s,
            dwell_min_s: s.dwell_min_s,
            duration_max_s: s.duration_max_s,
            torque_range_nm: g.drive_torque_range_nm.unwrap_or([0.0, f64::INFINITY]),
        }
    }

    /// The protocol within the limits, or the first field outside them (`moves[2].tau_s`, …).
    pub fn check(&self, p: &LiftProtocol) -> Result<(), ProtocolError> {
        let err = |field: String, message: String| Err(ProtocolError { field, message });
        let dur = p.t_end_s - p.t_start_s;
        if !(dur.is_finite() && dur > 0.0) {
            return err("t_end_s".into(), "the test must end after it starts".into());
        }
        if dur > self.duration_max_s {
            return err(
                "t_end_s".into(),
                format!(
                    "the test lasts {dur:.1} s, over the {} s limit",
                    self.duration_max_s
                ),
            );
        }
        if !(p.sample_hz.is_finite() && p.sample_hz > 0.0 && p.sample_hz <= 10_000.0) {
            return err("sample_hz".into(), "must be in (0, 10000] Hz".into());
        }
        let [tlo, thi] = self.torque_range_nm;
        for (name, v) in [
            ("torque_initial_nm", p.torque_initial_nm),
            ("torque_final_nm", p.torque_final_nm),
        ] {
            if !(tlo..=thi).contains(&v) {
                return err(
                    name.into(),
                    format!("{v} N·m is outside the drive's range [{tlo}, {thi}] N·m"),
                );
            }
        }
        let [taulo, tauhi] = self.tau_range_s;
        let mut prev_t = 0.0;
        for (i, m) in p.moves.iter().enumerate() {
            let f = |k: &str| format!("moves[{i}].{k}");
            if !m.t_s.is_finite() || m.t_s < prev_t + self.dwell_min_s {
                return err(
                    f("t_s"),
                    format!(
                        "{} s: a move starts at least {} s after the previous one (or the raise at 0 s)",
                        m.t_s, self.dwell_min_s
                    ),
                );
            }
            if !(taulo..=tauhi).contains(&m.tau_s) {
                return err(
                    f("tau_s"),
                    format!(
                        "{} s is outside the drive's response [{taulo}, {tauhi}] s",
                        m.tau_s
                    ),
                );
            }
            if !(tlo..=thi).contains(&m.torque_nm) {
                return err(
                    f("torque_nm"),
                    format!(
                        "{} N·m is outside the drive's range [{tlo}, {thi}] N·m",
                        m.torque_nm
                    ),
                );
            }
            if let Some(h) = m.height_m {
                let [hlo, hhi] = self.height_range_m;
                if !(hlo..=hhi).contains(&h) {
                    return err(
                        f("height_m"),
                        format!("{h} m is outside the working range [{hlo}, {hhi}] m"),
                    );
                }
            }
            prev_t = m.t_s;
        }
        if p.t_end_s < prev_t + self.dwell_min_s {
            return err(
                "t_end_s".into(),
                format!(
                    "the last move needs {} s of dwell before the end",
                    self.dwell_min_s
                ),
            );
        }
        Ok(())
    }
}

/// A protocol outside the stand's limits: the field and why.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{field}: {message}")]
pub struct ProtocolError {
    pub field: String,
    pub message: String,
}

/// Error of a design computation.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DesignError {
    #[error(transparent)]
    Fit(#[from] LiftFitError),
    #[error(transparent)]
    Protocol(#[from] ProtocolError),
    #[error("design: {0}")]
    Statics(String),
}

/// The frictionless set torque that holds the strip at `height_m` under the protocol's lowering
/// spring (weight cut): where a move to that height brings the head, friction aside.
pub fn holding_torque_nm(
    model: &LiftModel,
    g: &Geometry,
    protocol: &LiftProtocol,
    height_m: f64,
) -> Result<f64, DesignError> {
    let load_n = protocol.spring.force_n(height_m);
    let range = (g.alpha_min_rad, g.alpha_max_rad);
    let st = |e: super::statics::StaticsError| DesignError::Statics(e.to_string());
    let alpha = alpha_at_height(model, height_m, load_n, range).map_err(st)?;
    Ok(static_point(model, alpha, load_n, StaticFriction::None)
        .map_err(st)?
        .drive_torque_nm)
}

/// The paper's raise (0–3.5 s), then `rounds` rounds of moves to each of `heights_m` in turn,
/// each a pressure step to the height's frictionless holding torque at time constant `tau_s`,
/// held `dwell_s`: a hand-made protocol beside [`design`]'s (`examples/lift_long_protocols`).
/// Not checked against the stand's limits ([`ProtocolLimits::check`]).
pub fn rounds_of_moves(
    model: &LiftModel,
    g: &Geometry,
    heights_m: &[f64],
    tau_s: f64,
    dwell_s: f64,
    rounds: usize,
) -> Result<LiftProtocol, DesignError> {
    let mut p = LiftProtocol {
        t_end_s: 3.5,
        ..LiftProtocol::reference(g)
    };
    let torques: Vec<f64> = heights_m
        .iter()
        .map(|&h| holding_torque_nm(model, g, &p, h))
        .collect::<Result<_, _>>()?;
    let mut t_s = p.t_end_s;
    for _ in 0..rounds {
        for (&h, &torque_nm) in heights_m.iter().zip(&torques) {
            p.moves.push(Move {
                t_s,
                torque_nm,
                tau_s,
                height_m: Some(h),
            });
            t_s += dwell_s;
        }
    }
    p.t_end_s = t_s;
    Ok(p)
}

/// What a protocol is predicted to tell, before any data: per parameter (friction in the
/// order of `opts.friction_params`, then the torque offset), in scaled units (friction relative
/// to Table 4, offset in N·m).
#[derive(Debug, Clone)]
pub struct Prediction {
    pub params: Vec<LiftParam>,
    /// JᵀJ/σ_H² at Table 4, σ_H the stand's H noise.
    pub fisher: DMatrix<f64>,
    /// Posterior sd with H noise alone.
    pub sd_h: Vec<f64>,
    /// Posterior sd with the inputs' noise added (linearised, `INPUT_DRAWS`): the criterion's
    /// covariance, and what decides `informed`.
    pub sd: Vec<f64>,
    /// The linearised spread of the MAP estimate itself over repeated tests at Table 4: A⁻¹FA⁻¹
    /// (A the posterior information, F the data's) plus the inputs' share. Below `sd` where the
    /// prior holds a parameter. Not the design's final prediction: for J3 dry it overstates
    /// what repeated fits realise 2× (designed) to 10× (raise and lower); [`simulated_spread`]
    /// is what the design test compares with realised fits.
    pub sd_sampling: Vec<f64>,
    /// Posterior sd below the prior's / `opts.informed_factor`.
    pub informed: Vec<bool>,
    /// D-criterion: −log det of the posterior covariance with the inputs' noise (scaled
    /// units); with no input draws, log det of the posterior information.
    pub log_det: f64,
}

impl Prediction {
    /// The sd of parameter `p` (scaled units), if it is one of the prediction's.
    pub fn sd_of(&self, p: LiftParam) -> Option<f64> {
        self.params.iter().position(|q| *q == p).map(|i| self.sd[i])
    }
}

/// The stand's noise as the fit's input reconstruction would estimate it (`lift::inputs`):
/// every input channel smoothed at its sensor's sd.
fn stand_infos(noise: &LiftSensorNoise, sample_hz: f64) -> InputReconstruction {
    let ch = |sd: f64| ChannelReconstruction {
        noise_sd: sd,
        jumps: 0,
        smoothed: sd > 0.0,
    };
    InputReconstruction {
        sample_hz,
        torque: ch(noise.torque_sd_nm),
        fs: ch(noise.fs_sd_n),
        fm: ch(noise.fm_sd_n),
        ..Default::default()
    }
}

/// The fit's prior sd of parameter `i` of `p` (friction first, the offset last).
fn prior_sd(i: usize, p: usize, opts: &LiftFitOptions) -> f64 {
    if i + 1 < p {
        opts.prior_relative_sd
    } else {
        opts.offset_prior_sd_nm
    }
}

/// Posterior information (F + P⁻¹) and its log det, with the fit's prior.
fn posterior_info(fisher: &DMatrix<f64>, opts: &LiftFitOptions) -> (DMatrix<f64>, f64) {
    let p = fisher.nrows();
    let mut post = fisher.clone();
    for i in 0..p {
        post[(i, i)] += prior_sd(i, p, opts).powi(-2);
    }
    let log_det = match post.clone().cholesky() {
        Some(c) => 2.0 * c.l().diagonal().iter().map(|d| d.ln()).sum::<f64>(),
        None => f64::NEG_INFINITY,
    };
    (post, log_det)
}

/// Input-noise draws in the design's criterion and its linearised predictions
/// (`input_noise::covariance`). The design needs them where a fit does not (a fit's default is
/// none, `LiftFitOptions`): without the inputs' noise every added second only adds information
/// and the greedy search runs to the duration limit. They rank candidates; they do not predict
/// a fit's spread (the final prediction is [`simulated_spread`]): measured over 16
/// realistic-noise fits (`examples/lift_design -- 16`), J3 dry realised 0.49× its linearised
/// spread on the designed protocol (0.09× on the raise and lower), J5 and J8 dry 1.3× and 1.2×.
pub const INPUT_DRAWS: usize = 12;

/// Predicted sds of `protocol` at Table 4 (`model`) on a stand with `noise`: the posterior
/// with the stand's H noise (σ_H = `noise.h_sd_m`, the Jacobian from the noise-free record's
/// inputs), plus — when `input_draws` > 0 — the inputs' noise propagated as a fit does it
/// (`input_noise::covariance`, the same draws). Assumes the fit's prior and the estimate near
/// Table 4 (linearisation there).
pub fn predict(
    model: &LiftModel,
    protocol: &LiftProtocol,
    noise: &LiftSensorNoise,
    opts: &LiftFitOptions,
    input_draws: usize,
) -> Result<Prediction, DesignError> {
    let rec =
        record(model, protocol, &SimOptions::default()).map_err(|e| DesignError::Fit(e.into()))?;
    let o = LiftFitOptions {
        h_noise_m: noise.h_sd_m.max(1e-6),
        input_noise_draws: input_draws,
        ..opts.clone()
    };
    let (params, jd) = scaled_jacobian(model, &rec.inputs(), &o)?;
    let fisher = jd.tr_mul(&jd);
    if fisher.iter().any(|v| !v.is_finite()) {
        return Err(DesignError::Statics(
            "the protocol's sensitivities are not finite (the model cannot follow it)".into(),
        ));
    }
    let (post, log_det_h) = posterior_info(&fisher, &o);
    let cov_h = inverse_spd(&post);
    let mut cov = cov_h.clone();
    let mut cov_sampling = &cov_h * &fisher * &cov_h;
    if input_draws > 0 {
        let trace = rec.trace();
        let inputs = super::input_noise::covariance(
            model,
            &[trace],
            &[stand_infos(noise, protocol.sample_hz)],
            &[0.0],
            &jd,
            &cov_h,
            1.0,
            &o,
        )?;
        cov += &inputs;
        cov_sampling += inputs;
    }
    let p = params.len();
    let log_det = if input_draws > 0 {
        match cov.clone().cholesky() {
            Some(c) => -2.0 * c.l().diagonal().iter().map(|d| d.ln()).sum::<f64>(),
            None => f64::NEG_INFINITY,
        }
    } else {
        log_det_h
    };
    let sd_of = |c: &DMatrix<f64>| {
        (0..p)
            .map(|i| c[(i, i)].max(0.0).sqrt())
            .collect::<Vec<_>>()
    };
    let sd = sd_of(&cov);
    let informed = (0..p)
        .map(|i| sd[i] < prior_sd(i, p, opts) / opts.informed_factor)
        .collect();
    Ok(Prediction {
        params,
        sd_h: sd_of(&cov_h),
        sd_sampling: sd_of(&cov_sampling),
        sd,
        informed,
        fisher,
        log_det,
    })
}

/// The moves a design may choose from at each step.
#[derive(Debug, Clone, PartialEq)]
pub struct DesignSpace {
    pub heights_m: Vec<f64>,
    pub taus_s: Vec<f64>,
    pub dwells_s: Vec<f64>,
}

impl DesignSpace {
    /// Six heights across the working range, three drive speeds, two dwells (36 moves).
    pub fn stand(limits: &ProtocolLimits) -> Self {
        let [lo, hi] = limits.height_range_m;
        Self {
            heights_m: (0..6).map(|i| lo + (hi - lo) * i as f64 / 5.0).collect(),
            taus_s: vec![limits.tau_range_s[0], 1.0, 2.5],
            dwells_s: vec![2.0, 4.0],
        }
    }
}

/// One step of the greedy design: the move chosen and the criterion it reached.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DesignStep {
    pub chosen: Move,
    pub dwell_s: f64,
    pub log_det: f64,
}

/// A designed protocol and how it was reached.
#[derive(Debug, Clone)]
pub struct Design {
    pub protocol: LiftProtocol,
    pub steps: Vec<DesignStep>,
    /// Candidate protocols whose information was computed.
    pub evaluated: usize,
}

/// Greedy D-optimal design within `limits`: from the paper's raise, append the move of `space`
/// (height, τ, dwell) that most raises the D-criterion per second of test — −log det of the
/// posterior covariance a fit would report: H noise `noise.h_sd_m`, the inputs' noise by
/// [`INPUT_DRAWS`] draws (the same seeds for every candidate), the fit's prior — while
/// the test fits in the duration limit and a move still adds information. The inputs' noise
/// must be in the criterion: driven open-loop by the measured torque, the model integrates the
/// torque's noise twice (measured on a raise and lower: H moved 2–35 mm RMS by the stand's
/// input noise, `examples/lift_input_effect`), so a longer test can tell less. Candidates
/// are computed on `threads` workers (`batch::map`); `progress(done, total)` after each step.
/// Every candidate passes `limits.check`. Assumes the information at Table 4 stands for a worn
/// pantograph's (local design).
#[allow(clippy::too_many_arguments)]
pub fn design(
    model: &LiftModel,
    g: &Geometry,
    limits: &ProtocolLimits,
    space: &DesignSpace,
    noise: &LiftSensorNoise,
    opts: &LiftFitOptions,
    threads: Option<std::num::NonZeroUsize>,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Design, DesignError> {
    let mut protocol = LiftProtocol {
        t_end_s: 3.5,
        ..LiftProtocol::reference(g)
    };
    let torques: Vec<f64> = space
        .heights_m
        .iter()
        .map(|&h| holding_torque_nm(model, g, &protocol, h))
        .collect::<Result<_, _>>()?;
    let min_dwell = space.dwells_s.iter().copied().fold(f64::INFINITY, f64::min);
    let total_steps =
        ((limits.duration_max_s - (protocol.t_end_s - protocol.t_start_s)) / min_dwell) as usize;
    let mut steps = Vec::new();
    let mut evaluated = 0;
    loop {
        let t_now = protocol.t_end_s;
        let mut cands = Vec::new();
        for (hi, &h) in space.heights_m.iter().enumerate() {
            for &tau in &space.taus_s {
                for &dwell in &space.dwells_s {
                    let mut c = protocol.clone();
                    c.moves.push(Move {
                        t_s: t_now,
                        torque_nm: torques[hi],
                        tau_s: tau,
                        height_m: Some(h),
                    });
                    c.t_end_s = t_now + dwell;
                    if limits.check(&c).is_ok() {
                        cands.push((c, dwell));
                    }
                }
            }
        }
        if cands.is_empty() {
            break;
        }
        // Information per second of test: a long dwell must earn its time.
        let scored = super::batch::map(&cands, threads, &|_| {}, |(c, dwell)| {
            predict(model, c, noise, opts, INPUT_DRAWS).map(|p| (p.log_det, *dwell))
        });
        evaluated += cands.len();
        let base = steps.last().map_or_else(
            || predict(model, &protocol, noise, opts, INPUT_DRAWS).map(|p| p.log_det),
            |s: &DesignStep| Ok(s.log_det),
        )?;
        let mut best: Option<(usize, f64, f64)> = None;
        for (i, s) in scored.into_iter().enumerate() {
            // A candidate the model cannot run (a stiff corner) is not a design.
            let Ok((ld, dwell)) = s else { continue };
            if !ld.is_finite() {
                continue;
            }
            let rate = (ld - base) / dwell;
            if best.is_none_or(|(_, r, _)| rate > r) {
                best = Some((i, rate, ld));
            }
        }
        let Some((i, rate, ld)) = best else { break };
        if rate <= 0.0 {
            break;
        }
        let (c, dwell) = cands.swap_remove(i);
        steps.push(DesignStep {
            chosen: *c.moves.last().expect("a candidate has a move"),
            dwell_s: dwell,
            log_det: ld,
        });
        protocol = c;
        progress(steps.len(), total_steps.max(steps.len()));
    }
    Ok(Design {
        protocol,
        steps,
        evaluated,
    })
}

mod simulated;
pub use simulated::{SIMULATED_FITS, SIMULATED_SEED0, SimulatedSpread, simulated_spread};

#[cfg(test)]
mod tests;

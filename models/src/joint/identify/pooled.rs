//! A pooled single-joint fit (issue 36, point 5): several recordings of one rig — the same body
//! and joint, released at different angles or on different days — fitted with one set of
//! physical parameters and each recording's own start and sensor zero.
//!
//! Shared: the friction law's free parameters and the body/readout effects (`inertia_error`,
//! sensor delay, backlash) — properties of the rig and its logger. Per recording: the release
//! state (q₀, ω₀), the sensor zero (an encoder's zero is where it was powered on) and a measured
//! input's zero. The residual vector is the recordings' residuals one after another, so the
//! cost is the sum of their squared errors, each in its own channel units (one rig, one sensor).

use nalgebra::DMatrix;

use super::{
    FitError, FitOptions, FitOutcome, FitSpec, InitialEstimate, JointTest, OutputError, Param,
    covariance, fit_window, intervals, lm, start_vector,
};

/// One recording of a pooled fit: the test and the window fitted (from its release).
#[derive(Debug, Clone, Copy)]
pub struct Recording<'a> {
    pub test: &'a JointTest,
    pub start: usize,
    pub n_fit: usize,
    /// Its own fit's estimate: the starting point of its per-recording parameters.
    pub init: InitialEstimate,
}

/// Whether a parameter belongs to one recording (its start, its zeros) or to the rig.
pub fn per_recording(p: Param) -> bool {
    matches!(
        p,
        Param::Q0 | Param::V0 | Param::Offset | Param::InputOffset
    )
}

/// The pooled least-squares problem: each recording's [`OutputError`] over its window, the
/// shared columns summed into the rig's parameters.
struct Pooled<'a> {
    parts: Vec<OutputError<'a>>,
    /// For each part: its local parameter index → global index.
    maps: Vec<Vec<usize>>,
    n_global: usize,
    /// Residual offset of each part.
    rows: Vec<usize>,
    n_rows: usize,
}

impl lm::Problem for Pooled<'_> {
    fn n_params(&self) -> usize {
        self.n_global
    }
    fn n_residuals(&self) -> usize {
        self.n_rows
    }
    fn eval(&mut self, x: &[f64], r: &mut [f64], jac: &mut DMatrix<f64>) -> Result<(), String> {
        jac.fill(0.0);
        for (i, part) in self.parts.iter_mut().enumerate() {
            let map = &self.maps[i];
            let xl: Vec<f64> = map.iter().map(|&g| x[g]).collect();
            let n = part.times.len();
            let mut rl = vec![0.0; n];
            let mut jl = DMatrix::zeros(n, map.len());
            lm::Problem::eval(part, &xl, &mut rl, &mut jl)?;
            let row0 = self.rows[i];
            r[row0..row0 + n].copy_from_slice(&rl);
            for (jlocal, &g) in map.iter().enumerate() {
                for k in 0..n {
                    jac[(row0 + k, g)] = jl[(k, jlocal)];
                }
            }
        }
        Ok(())
    }
    fn lower_bounds(&self) -> Vec<f64> {
        self.bounds(|p| lm::Problem::lower_bounds(p))
    }
    fn upper_bounds(&self) -> Vec<f64> {
        self.bounds(|p| lm::Problem::upper_bounds(p))
    }
}

impl Pooled<'_> {
    fn bounds(&self, of: impl Fn(&OutputError) -> Vec<f64>) -> Vec<f64> {
        let mut out = vec![f64::NAN; self.n_global];
        for (part, map) in self.parts.iter().zip(&self.maps) {
            for (b, &g) in of(part).iter().zip(map) {
                out[g] = *b;
            }
        }
        out
    }
}

/// A pooled fit's answer: the rig's parameters with their intervals, and per recording a fit
/// outcome whose friction, body terms and intervals are the pooled ones (its start, zero and
/// residual its own), so reports and the residual loop read it like a single fit.
#[derive(Debug, Clone)]
pub struct PooledFit {
    /// Global parameter names: the shared ones first, then each recording's.
    pub params: Vec<(Option<usize>, Param)>,
    pub values: Vec<f64>,
    pub ci95: Vec<[f64; 2]>,
    pub per_recording: Vec<FitOutcome>,
    /// Sum over recordings of n·ln(RSS/n) plus the parameters' k·ln(N) (BIC of the pooled fit).
    pub bic: f64,
    pub iterations: usize,
}

impl PooledFit {
    /// A shared parameter's value and 95 % interval.
    pub fn shared(&self, p: Param) -> Option<(f64, [f64; 2])> {
        self.params
            .iter()
            .position(|x| *x == (None, p))
            .map(|i| (self.values[i], self.ci95[i]))
    }
}

/// Fit `spec` to every recording with one set of shared parameters. Each recording's
/// per-recording parameters start at its own estimate; the shared ones at `spec`'s law with
/// viscous and dry from the first recording's estimate.
pub fn fit_pooled(
    recs: &[Recording],
    spec: &FitSpec,
    shared_init: &InitialEstimate,
    opts: &FitOptions,
) -> Result<PooledFit, FitError> {
    if recs.is_empty() {
        return Err(FitError::TooShort(0));
    }
    let local = spec.params();
    let shared: Vec<Param> = local
        .iter()
        .copied()
        .filter(|p| !per_recording(*p))
        .collect();
    let mut params: Vec<(Option<usize>, Param)> = shared.iter().map(|p| (None, *p)).collect();
    let mut x0: Vec<f64> = start_vector(&shared, spec, shared_init);
    let mut parts = Vec::new();
    let mut maps = Vec::new();
    let mut rows = Vec::new();
    let mut n_rows = 0;
    for (i, rec) in recs.iter().enumerate() {
        if rec.n_fit < 20 {
            return Err(FitError::TooShort(rec.n_fit));
        }
        let part = OutputError::new(rec.test, rec.start, rec.n_fit, spec, opts);
        let own = start_vector(&local, spec, &rec.init);
        let mut map = Vec::new();
        for (j, p) in local.iter().enumerate() {
            if per_recording(*p) {
                map.push(params.len());
                params.push((Some(i), *p));
                x0.push(own[j]);
            } else {
                map.push(shared.iter().position(|s| s == p).expect("shared"));
            }
        }
        rows.push(n_rows);
        n_rows += rec.n_fit;
        parts.push(part);
        maps.push(map);
    }
    let mut prob = Pooled {
        parts,
        maps,
        n_global: params.len(),
        rows,
        n_rows,
    };
    let rep = lm::minimize(&mut prob, &x0, &opts.lm);
    if let lm::Termination::EvaluationFailed(e) = &rep.termination {
        return Err(FitError::Start(e.clone()));
    }
    // The covariance of the stacked problem; each recording's own residual correlation enters
    // through its block of the residual vector (the sandwich reads lag-1 correlation over the
    // stacked vector: one seam per recording, negligible against thousands of samples).
    let cov = covariance::sandwich(&rep.jacobian, &rep.residuals);
    let lb = lm::Problem::lower_bounds(&prob);
    let (_, ci95) = intervals(&rep.x, &cov, &lb);
    // Per recording: the single-fit outcome at the pooled values (one evaluation, no steps),
    // with the shared parameters' pooled intervals.
    let mut per = Vec::new();
    let mut bic = 0.0;
    let mut n_all = 0usize;
    for (i, rec) in recs.iter().enumerate() {
        let map = &prob.maps[i];
        let mut s = spec.clone();
        let at = |p: Param| local.iter().position(|x| *x == p).map(|j| rep.x[map[j]]);
        for d in &spec.free {
            if let Some(v) = at(Param::Dyn(*d)) {
                s.law.set(*d, v);
            }
        }
        if s.inertia.is_some() {
            s.inertia = at(Param::Inertia);
        }
        if s.delay.is_some() {
            s.delay = at(Param::Delay);
        }
        if s.backlash.is_some() {
            s.backlash = at(Param::Backlash);
        }
        if s.input_offset.is_some() {
            s.input_offset = at(Param::InputOffset);
        }
        let init = InitialEstimate {
            viscous: s.law.viscous,
            dry: s.law.dry,
            offset: at(Param::Offset).unwrap_or(0.0),
            q0: at(Param::Q0).unwrap_or(rec.init.q0),
            v0: at(Param::V0).unwrap_or(rec.init.v0),
        };
        let mut eval_only = *opts;
        eval_only.lm.max_iter = 0;
        let mut f = fit_window(rec.test, rec.start, rec.n_fit, &s, &init, &eval_only)?;
        for (j, &g) in map.iter().enumerate() {
            f.values[j] = rep.x[g];
            f.ci95[j] = ci95[g];
            f.std[j] = cov.std(g);
        }
        let n = rec.n_fit as f64;
        let rss = f.residual.iter().map(|r| r * r).sum::<f64>().max(1e-300);
        bic += n * (rss / n).ln();
        n_all += rec.n_fit;
        per.push(f);
    }
    bic += params.len() as f64 * (n_all as f64).ln();
    Ok(PooledFit {
        params,
        values: rep.x,
        ci95,
        per_recording: per,
        bic,
        iterations: rep.iterations,
    })
}

//! The lift fit's least-squares problem: H residuals of every trace over σ_H, pooled gauge
//! readings over their noise, and the prior rows, with their Jacobian (`identify::fit_map_in`
//! builds and minimises it).

use super::*;

pub(super) struct MapProblem<'a, 'w> {
    /// The buffers every evaluation's sensitivity run reuses.
    pub(super) ws: &'w mut SensWorkspace,
    pub(super) base: &'a LiftModel,
    pub(super) traces: &'a [LiftTrace<'a>],
    pub(super) fric: &'a [LiftParam],
    pub(super) baseline: &'a [f64],
    pub(super) opts: &'a LiftFitOptions,
    /// `fric`, the offset, then the effects: the sensitivity run's parameters.
    pub(super) with_offset: Vec<LiftParam>,
    /// Priors of the effects (`opts.effect_params`), in their order.
    pub(super) effect_priors: &'a [EffectPrior],
    pub(super) n_data: usize,
    /// Each pooled gauge record's readings at the baseline (`opts.gauge_records`' order).
    pub(super) gauge_warm: &'a [Vec<crate::lift::gauge::solve::Warm>],
    /// Readings of every pooled gauge record.
    pub(super) n_gauge: usize,
    /// Index in `fric` of each `opts.per_trace` parameter.
    pub(super) per_trace_ix: &'a [usize],
}

impl MapProblem<'_, '_> {
    /// Index of the first per-trace deviation (`opts.per_trace`), after the gauge zeros.
    pub(super) fn u0(&self) -> usize {
        self.fric.len()
            + self.traces.len()
            + self.effect_priors.len()
            + self.opts.gauge_records.len()
    }
    pub(super) fn model_at(&self, x: &[f64]) -> LiftModel {
        let mut m = self.base.clone();
        let mut dummy = 0.0;
        for (i, p) in self.fric.iter().enumerate() {
            p.set(&mut m, &mut dummy, x[i] * self.baseline[i]);
        }
        let e0 = self.fric.len() + self.traces.len();
        for (i, p) in self.opts.effect_params.iter().enumerate() {
            p.set(&mut m, &mut dummy, x[e0 + i]);
        }
        m
    }

    /// One continuation stage (`fit_map_in`): the fit over each trace's first `ends[i]`
    /// samples from `x`. A stage only has to bring the next one into its quadratic region: a
    /// few iterations, stopping once a step would move the parameters by less than one standard
    /// error. No noise floor here: the stages choose the basin the whole-trace fit settles in,
    /// and cut short they took a lift with head drag (c_a 4, seed 3) to a plain fit that
    /// absorbed the drag (1.49× the noise) instead of leaving it to be named (tests/cli.rs).
    /// The stages are short: without the floor the fleet still gains 12 % of the 14 %. Nor the
    /// cliff rule (`LiftFitOptions::default`), measured on whole-trace fits only.
    pub(super) fn stage(
        &mut self,
        ends: &[usize],
        x: &[f64],
    ) -> crate::joint::identify::lm::LmReport {
        let short: Vec<LiftTrace> = self
            .traces
            .iter()
            .zip(ends)
            .map(|(t, &e)| LiftTrace {
                inputs: LiftInputs {
                    t_s: &t.inputs.t_s[..e],
                    torque_nm: &t.inputs.torque_nm[..e],
                    fs_n: &t.inputs.fs_n[..e],
                    fm_n: if t.inputs.fm_n.is_empty() {
                        &[]
                    } else {
                        &t.inputs.fm_n[..e]
                    },
                },
                strip_height_m: &t.strip_height_m[..e],
            })
            .collect();
        let mut stage = MapProblem {
            ws: &mut *self.ws,
            base: self.base,
            traces: &short,
            fric: self.fric,
            baseline: self.baseline,
            opts: self.opts,
            n_data: ends.iter().sum(),
            with_offset: self.with_offset.clone(),
            effect_priors: self.effect_priors,
            gauge_warm: self.gauge_warm,
            n_gauge: self.n_gauge,
            per_trace_ix: self.per_trace_ix,
        };
        let lm = LmOptions {
            max_iter: self.opts.lm.max_iter.min(5),
            dtol: self.opts.lm.dtol.max(1.0),
            noise_sd: 0.0,
            cliff_sd: 0.0,
            // A stage fits part of the trace: its cost is not the level a caller needs.
            give_up_cost: 0.0,
            ..self.opts.lm
        };
        minimize(&mut stage, x, &lm)
    }
}

impl Problem for MapProblem<'_, '_> {
    fn n_params(&self) -> usize {
        self.u0() + self.traces.len() * self.per_trace_ix.len()
    }
    fn n_residuals(&self) -> usize {
        self.n_data + self.n_gauge + self.n_params()
    }
    fn eval(&mut self, x: &[f64], r: &mut [f64], jac: &mut DMatrix<f64>) -> Result<(), String> {
        count_work(1, 0);
        let pf = self.fric.len();
        let e0 = pf + self.traces.len();
        let m = self.model_at(x);
        let sigma = self.opts.h_noise_m;
        // The H delay, if fitted: its index among the effects and its value, s.
        let delay = self
            .opts
            .effect_params
            .iter()
            .position(|p| *p == LiftParam::SensorDelay)
            .map(|e| (e, x[e0 + e]));
        // The H zero offset, if fitted, m (`sensor_offset`: H_meas = H + b).
        let h_offset_m = self
            .opts
            .effect_params
            .iter()
            .position(|p| *p == LiftParam::SensorOffset)
            .map_or(0.0, |e| x[e0 + e]);
        jac.fill(0.0);
        let mut row = 0;
        let (u0, q) = (self.u0(), self.per_trace_ix.len());
        for (ti, tr) in self.traces.iter().enumerate() {
            // This trace's own deviations of the `per_trace` coefficients, if any.
            let mt = (q > 0).then(|| {
                let mut mt = m.clone();
                let mut dummy = 0.0;
                for (k, &i) in self.per_trace_ix.iter().enumerate() {
                    let v = (x[i] + x[u0 + ti * q + k]).max(0.0) * self.baseline[i];
                    self.fric[i].set(&mut mt, &mut dummy, v);
                }
                mt
            });
            let run = simulate_sensitivities_in(
                self.ws,
                mt.as_ref().unwrap_or(&m),
                &tr.inputs,
                &self.with_offset,
                x[pf + ti],
                &self.opts.sim,
            )
            .map_err(|e| e.to_string())?;
            count_work(0, run.steps);
            let p = self.with_offset.len();
            let mask = self.opts.holdout_mask.as_deref().filter(|_| ti == 0);
            // `sensor_delay`: the model's H read τ late, H(t_k − τ), linear between samples
            // (the record starts at rest: before its first sample, the first), ∂/∂τ = −Ḣ.
            let t_s = tr.inputs.t_s;
            let mut j = 0;
            for k in 0..tr.strip_height_m.len() {
                if mask.is_some_and(|m| m.get(k) == Some(&true)) {
                    r[row] = 0.0;
                    row += 1;
                    continue;
                }
                // Sample j and its weight w toward j + 1 (w = 0: sample k itself).
                let (jk, w, slope) = match delay {
                    None => (k, 0.0, 0.0),
                    Some((_, tau)) => {
                        let t = t_s[k] - tau;
                        while j + 1 < k && t_s[j + 1] <= t {
                            j += 1;
                        }
                        if t <= t_s[0] {
                            (0, 0.0, 0.0)
                        } else {
                            let dt = t_s[j + 1] - t_s[j];
                            let w = ((t - t_s[j]) / dt).clamp(0.0, 1.0);
                            let dh = run.strip_height_m[j + 1] - run.strip_height_m[j];
                            (j, w, dh / dt)
                        }
                    }
                };
                let at = |v: &dyn Fn(usize) -> f64| {
                    if w == 0.0 {
                        v(jk)
                    } else {
                        v(jk) + w * (v(jk + 1) - v(jk))
                    }
                };
                r[row] =
                    (at(&|q| run.strip_height_m[q]) + h_offset_m - tr.strip_height_m[k]) / sigma;
                for i in 0..pf {
                    jac[(row, i)] = at(&|q| run.d_height[q * p + i]) * self.baseline[i] / sigma;
                }
                jac[(row, pf + ti)] = at(&|q| run.d_height[q * p + pf]) / sigma;
                for (k, &i) in self.per_trace_ix.iter().enumerate() {
                    jac[(row, u0 + ti * q + k)] = jac[(row, i)];
                }
                let mut col = pf + 1;
                for (e, ep) in self.opts.effect_params.iter().enumerate() {
                    jac[(row, e0 + e)] = if *ep == LiftParam::SensorDelay {
                        -slope / sigma
                    } else if *ep == LiftParam::SensorOffset {
                        1.0 / sigma
                    } else {
                        col += 1;
                        at(&|q| run.d_height[q * p + col - 1]) / sigma
                    };
                }
                row += 1;
            }
        }
        // Pooled gauge records: (F_model + b_g − F)/σ_g, ∂/∂x of the dry μ by forward
        // differences, each record's zero b_g a nuisance (as the gauge fit's, `gauge::fit`).
        let z0 = pf + self.traces.len() + self.effect_priors.len();
        for (gi, (g, warm)) in self
            .opts
            .gauge_records
            .iter()
            .zip(self.gauge_warm)
            .enumerate()
        {
            let sigma = g.sigma_n();
            let zero_n = x[z0 + gi];
            let ar = m.alpha_range_rad;
            let f = crate::lift::gauge::solve::forces_near(&m, ar, &g.drive, &g.record, warm)
                .map_err(|e| e.to_string())?;
            let n = f.len();
            for (k, (a, b)) in f.iter().zip(&g.record.forces_n).enumerate() {
                r[row + k] = (a + zero_n - b) / sigma;
                jac[(row + k, z0 + gi)] = 1.0 / sigma;
            }
            for (i, p) in self.fric.iter().enumerate() {
                let LiftParam::Dry(j) = p else { continue };
                if *j == RevJoint::J6 {
                    continue;
                }
                let mut mi = m.clone();
                mi.friction.dry_mu[j.index()] = (x[i] + GAUGE_FD_STEP) * self.baseline[i];
                let fi = crate::lift::gauge::solve::forces_near(&mi, ar, &g.drive, &g.record, warm)
                    .map_err(|e| e.to_string())?;
                for (k, (a, b)) in fi.iter().zip(&f).enumerate() {
                    jac[(row + k, i)] = (a - b) / (GAUGE_FD_STEP * sigma);
                }
            }
            row += n;
        }
        // Prior rows: (x − mean)/sd for friction (`LiftFitOptions::prior_of`), offset/s_T for the offsets.
        for i in 0..pf {
            let (mean, sd) = self.opts.prior_of(self.fric[i]);
            r[row] = (x[i] - mean) / sd;
            jac[(row, i)] = 1.0 / sd;
            row += 1;
        }
        for ti in 0..self.traces.len() {
            r[row] = x[pf + ti] / self.opts.offset_prior_sd_nm;
            jac[(row, pf + ti)] = 1.0 / self.opts.offset_prior_sd_nm;
            row += 1;
        }
        for (e, pr) in self.effect_priors.iter().enumerate() {
            r[row] = (x[e0 + e] - pr.mean) / pr.sd;
            jac[(row, e0 + e)] = 1.0 / pr.sd;
            row += 1;
        }
        for gi in 0..self.opts.gauge_records.len() {
            let pr = GAUGE_ZERO_PRIOR;
            r[row] = (x[z0 + gi] - pr.mean) / pr.sd;
            jac[(row, z0 + gi)] = 1.0 / pr.sd;
            row += 1;
        }
        for ti in 0..self.traces.len() {
            for (k, (_, tau)) in self.opts.per_trace.iter().enumerate() {
                r[row] = x[u0 + ti * q + k] / tau;
                jac[(row, u0 + ti * q + k)] = 1.0 / tau;
                row += 1;
            }
        }
        Ok(())
    }
    fn lower_bounds(&self) -> Vec<f64> {
        let mut v = vec![0.0; self.fric.len()];
        v.extend(std::iter::repeat_n(f64::NEG_INFINITY, self.traces.len()));
        v.extend(self.effect_priors.iter().map(|p| p.lower));
        v.extend(
            self.opts
                .gauge_records
                .iter()
                .map(|_| GAUGE_ZERO_PRIOR.lower),
        );
        v.extend(std::iter::repeat_n(
            -MAX_MULTIPLE,
            self.traces.len() * self.per_trace_ix.len(),
        ));
        v
    }
    /// At most 10× Table 4 (20 prior sd): far beyond any worn joint, and it keeps trial steps
    /// out of absurd, stiff corners of the model.
    fn upper_bounds(&self) -> Vec<f64> {
        let mut v = vec![MAX_MULTIPLE; self.fric.len()];
        v.extend(std::iter::repeat_n(f64::INFINITY, self.traces.len()));
        v.extend(self.effect_priors.iter().map(|p| p.upper));
        v.extend(
            self.opts
                .gauge_records
                .iter()
                .map(|_| GAUGE_ZERO_PRIOR.upper),
        );
        v.extend(std::iter::repeat_n(
            MAX_MULTIPLE,
            self.traces.len() * self.per_trace_ix.len(),
        ));
        v
    }
}

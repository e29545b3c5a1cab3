//! Pooled lift fits: several lifts of one pantograph (and its force-gauge records) fitted
//! together, friction shared, the result reported on the newest lift.

use super::super::identify::{LiftFitError, LiftFitOptions, LiftTrace, fit_map};
use super::super::simulate::LiftInputs;
use super::{LiftChannels, LiftReport, build_result, builtin_model};
use crate::contract::drift::DriftThresholds;

/// Fit several lift traces of one pantograph together (friction shared, one torque offset per
/// trace; `fit_map` pools them) and report the result on the first, the newest test (issue 15):
/// a lift hardly informs J2/J2'/J5 alone, a few together can. `trace_ids` name `channels` in
/// the same order, newest first; `window_days` is recorded in the result's `pooled` block.
pub fn fit_pooled_lift_traces(
    channels: &[LiftChannels],
    trace_ids: &[String],
    window_days: f64,
    thresholds: &DriftThresholds,
) -> Result<LiftReport, LiftFitError> {
    fit_pooled_lift_and_gauge_traces(channels, trace_ids, &[], &[], window_days, thresholds)
}

/// [`fit_pooled_lift_traces`] with force-gauge records (`static_force` traces) of the same
/// pantograph pooled in (issue 20, point 3): their readings join the fit's residuals, scaled by
/// the gauge's noise (`LiftFitOptions::gauge_records`), each measured under the type's drive
/// characteristic (`lift::static_force::DriveLine::from_lift_test`). The result is reported on
/// the newest lift (`channels[0]`); `gauge_ids` follow the lifts' ids in `pooled.trace_ids`.
/// One lift with one gauge record or more is a pool; without gauge records, 2 lifts or more.
pub fn fit_pooled_lift_and_gauge_traces(
    channels: &[LiftChannels],
    trace_ids: &[String],
    gauges: &[super::super::gauge::GaugeChannels],
    gauge_ids: &[String],
    window_days: f64,
    thresholds: &DriftThresholds,
) -> Result<LiftReport, LiftFitError> {
    fit_pooled_lift_and_gauge_traces_with(
        channels,
        trace_ids,
        gauges,
        gauge_ids,
        window_days,
        thresholds,
        &[],
    )
}

/// [`fit_pooled_lift_and_gauge_traces`] under `friction_prior` for the parameters it names
/// (`LiftFitOptions::friction_prior`: the fleet's, as a single lift's fit); empty: Table 4.
pub fn fit_pooled_lift_and_gauge_traces_with(
    channels: &[LiftChannels],
    trace_ids: &[String],
    gauges: &[super::super::gauge::GaugeChannels],
    gauge_ids: &[String],
    window_days: f64,
    thresholds: &DriftThresholds,
    friction_prior: &[(super::super::sensitivity::LiftParam, f64, f64)],
) -> Result<LiftReport, LiftFitError> {
    let least = if gauges.is_empty() { 2 } else { 1 };
    if channels.len() < least
        || channels.len() != trace_ids.len()
        || gauges.len() != gauge_ids.len()
    {
        return Err(LiftFitError::Invalid(format!(
            "a pooled fit needs {least} or more lift traces with an id each (and an id per gauge \
             record), got {} traces and {} ids, {} gauge records and {} ids",
            channels.len(),
            trace_ids.len(),
            gauges.len(),
            gauge_ids.len()
        )));
    }
    let model = builtin_model();
    let drive = super::super::static_force::DriveLine::from_lift_test(
        super::super::geometry::builtin_160ec(),
    );
    let gauge_records = gauges
        .iter()
        .zip(gauge_ids)
        .map(|(g, id)| {
            super::super::gauge::GaugeRecord::new(
                g.strip_height_m.to_vec(),
                g.force_n.to_vec(),
                g.resolution_n,
            )
            .map(|record| super::super::identify::PooledGauge { record, drive })
            .map_err(|e| LiftFitError::Invalid(format!("gauge record {id}: {e}")))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let opts = LiftFitOptions {
        thresholds: *thresholds,
        gauge_records,
        per_trace: super::super::identify::POOLED_PER_TRACE.to_vec(),
        param_interval_scale: super::super::identify::POOLED_INTERVAL_SCALE.to_vec(),
        friction_prior: friction_prior.to_vec(),
        ..LiftFitOptions::default()
    };
    let traces: Vec<LiftTrace> = channels
        .iter()
        .map(|c| LiftTrace {
            inputs: LiftInputs {
                t_s: c.t_s,
                torque_nm: c.torque_nm,
                fs_n: c.fs_n,
                fm_n: c.fm_n,
            },
            strip_height_m: c.strip_height_m,
        })
        .collect();
    let fit = fit_map(model, &traces, &opts)?;
    let fitted_height_m = fit.fitted_height_m.first().cloned().unwrap_or_default();
    // Not gated, only reported (each lift was judged alone; one withheld is not pooled).
    let mut result = build_result(
        model,
        &fit,
        &traces[0],
        &fitted_height_m,
        &opts,
        &trace_ids[0],
        false,
    );
    result.pooled = Some(crate::contract::report::PooledTests {
        trace_ids: trace_ids.iter().chain(gauge_ids).cloned().collect(),
        window_days,
    });
    Ok(LiftReport {
        result,
        fit,
        fitted_height_m,
        plain_fitted_height_m: None,
        work: Vec::new(),
    })
}

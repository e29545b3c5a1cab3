//! The fleet prior in the service (issue 37, point 3): learned from the workshop fits in the
//! store (`models::lift::fleet_prior`), versioned (`fleet_priors`), used by every lift and
//! force-gauge fit.
//!
//! - **Learning**: each pantograph's latest informing workshop test (pendulum, slider,
//!   quadrangle swing) per joint and parameter (`param_evidence`), read as θ/θ₀ with its sd
//!   (the 95 % interval's half-width / 1.96, over the type file's Table 4 baseline): one
//!   estimate per unit and parameter, as the model's empirical Bayes wants. Lift and gauge fits
//!   are not learned from: they are fitted under the prior.
//! - **Trigger** (stated choice): explicit — `POST /v1/fleet/prior` or `pantowatch prior learn`.
//!   A relearn publishes a new version only when some joint's mean or sd moves by more than
//!   `[fleet_prior] version_tolerance_relative` from the newest version (or from the type file's,
//!   version 0, when none is stored): a prior that changes every fit must be an act someone
//!   can name, not a side effect of the thousandth upload.
//! - **Use**: a lift fit, a lift's pooled fit (`pooled`, under its lift's prior) and a
//!   force-gauge (`static_force`) fit take the newest version of their type (`FitPrior`),
//!   learned sds widened × `[fleet_prior] fit_sd_scale` (1.5, where `FleetPrior::for_fit` is
//!   documented), and record it in `fit.prior` and `fits.prior_version`. The gauge fit reads the
//!   dry μ entries as a per-joint prior in ln μ (`lift::gauge::fit`). Without a stored version:
//!   version 0, the type file's Table 4 ± floor — the fit as before this module (the floor is
//!   the fits' own `prior_relative_sd`, 0.5).
//! - **Refit on change**: publishing version n queues, in the same transaction, every lift and
//!   force-gauge record ([`PRIOR_KINDS`]) whose current fit used an older prior (none recorded
//!   counts as version 0), at model version `{MODEL_VERSION}; fleet prior vn` ([`refit_prefix`]),
//!   the existing `refit` queue; the worker fits such a job with version n (a lift's pool too,
//!   recording n: it is not queued again until a newer version).

use std::collections::BTreeMap;

use pantowatch_models::data::{PantographType, builtin};
use pantowatch_models::evidence::PriorUsed;
use pantowatch_models::lift::fleet_prior::{FleetPrior, ParamPrior, WorkshopEstimate, learn};
use pantowatch_models::lift::sensitivity::LiftParam;
use pantowatch_models::numerics::stats::Z95;
use pantowatch_models::report::MODEL_VERSION;
use serde::Serialize;
use utoipa::ToSchema;

use crate::store::{EvidenceRow, NewPrior, Store, StoreError, StoredPrior};

/// The test kinds a prior is learned from: the workshop's.
pub const WORKSHOP_KINDS: [&str; 3] = ["pendulum", "slider", "quadrangle_swing"];
/// The test kinds fitted under the prior, refitted when it changes.
pub const PRIOR_KINDS: [&str; 2] = ["lift", crate::trace::STATIC_FORCE];
/// What a refit's model version adds to `MODEL_VERSION` before the prior's version.
const REFIT_TAG: &str = "; fleet prior v";

/// The model version of the refits a new prior version queues, less the version number.
pub fn refit_prefix() -> String {
    format!("{MODEL_VERSION}{REFIT_TAG}")
}

/// The prior version a job's model version names (a refit queued by a new prior), if any.
pub fn version_of_job(model_version: &str) -> Option<i64> {
    model_version
        .strip_prefix(MODEL_VERSION)?
        .strip_prefix(REFIT_TAG)?
        .parse()
        .ok()
        .filter(|v| *v > 0)
}

/// The prior one fit uses: what it records and the lift fit's `friction_prior`.
#[derive(Debug, Clone, PartialEq)]
pub struct FitPrior {
    pub used: PriorUsed,
    pub friction_prior: Vec<(LiftParam, f64, f64)>,
}

/// A fleet prior as the API shows it: the stored version, or version 0 (the type file's).
#[derive(Debug, Clone, Serialize, ToSchema, PartialEq)]
pub struct FleetPriorView {
    /// 0: none learned yet, the type file's Table 4 ± `[fleet_prior] floor_relative_sd`.
    pub version: i64,
    /// The pantograph type (`160EC`).
    pub model: String,
    /// When the version was published; absent for version 0.
    pub learned_at: Option<chrono::DateTime<chrono::Utc>>,
    /// `learned` (some joint's spread is the fleet's) or `type_file` (every joint at the floor).
    pub source: String,
    /// Pantographs whose workshop fits it rests on.
    pub n_units: i64,
    /// The floor applied where a joint and parameter had fewer than `min_fits` fits, Table 4 units.
    pub floor_relative_sd: f64,
    /// Each learned sd × this in a fit (`[fleet_prior] fit_sd_scale`).
    pub fit_sd_scale: f64,
    /// Per joint and parameter: mean, sd, between-unit spread (Table 4 units), fits, learned.
    pub params: Vec<ParamPrior>,
}

impl FleetPriorView {
    fn of(p: &StoredPrior) -> Self {
        Self {
            version: p.version,
            model: p.model.clone(),
            learned_at: Some(p.learned_at),
            source: p.source.clone(),
            n_units: p.n_units,
            floor_relative_sd: p.floor_relative_sd,
            fit_sd_scale: p.fit_sd_scale,
            params: p.params.clone(),
        }
    }

    /// Version 0 of `model`: the type file's prior.
    fn type_file(model: &str, t: &PantographType) -> Self {
        let s = t.fleet_prior();
        let prior = learn(&[], s);
        Self {
            version: 0,
            model: model.to_owned(),
            learned_at: None,
            source: prior.source().to_owned(),
            n_units: 0,
            floor_relative_sd: s.floor_relative_sd,
            fit_sd_scale: s.fit_sd_scale,
            params: prior.params,
        }
    }

    fn prior(&self) -> FleetPrior {
        FleetPrior {
            params: self.params.clone(),
        }
    }

    /// What a fit under this prior uses and records.
    pub fn fit_prior(&self) -> FitPrior {
        let prior = self.prior();
        let learned = prior.source() == "learned";
        FitPrior {
            used: PriorUsed {
                version: self.version,
                source: self.source.clone(),
                sd_scale: if learned { self.fit_sd_scale } else { 1.0 },
            },
            friction_prior: prior.for_fit(self.fit_sd_scale),
        }
    }
}

/// Why a prior could not be read or learned.
#[derive(Debug, thiserror::Error)]
pub enum PriorError {
    #[error(transparent)]
    Store(#[from] StoreError),
    #[error("pantograph type `{0}` has no data here")]
    NoModel(String),
}

/// The type's data, when compiled in.
fn type_of(model: &str) -> Result<&'static PantographType, PriorError> {
    builtin(model).ok_or_else(|| PriorError::NoModel(model.to_owned()))
}

/// The Table 4 baseline of a joint's parameter in the type file (the unit its fits report).
fn baseline_of(t: &PantographType, joint: &str, param: &str) -> Option<f64> {
    let j = t.joint(joint)?;
    let b = match param {
        "viscous" => j.viscous_baseline(),
        "dry" => j.dry_mu,
        _ => return None,
    };
    (b.is_finite() && b > 0.0).then_some(b)
}

/// The workshop estimates of `model`'s pantographs in `rows` (`param_evidence`): per unit,
/// joint and parameter its latest informing workshop test, θ/θ₀ with its sd; and the units.
pub fn workshop_estimates(
    rows: &[EvidenceRow],
    model: &str,
    t: &PantographType,
) -> (Vec<WorkshopEstimate>, usize) {
    let mut latest: BTreeMap<(&str, &str, &str), &EvidenceRow> = BTreeMap::new();
    for r in rows
        .iter()
        .filter(|r| r.model == model && WORKSHOP_KINDS.contains(&r.kind.as_str()))
    {
        let key = (r.serial.as_str(), r.joint.as_str(), r.param.as_str());
        let newer = latest
            .get(&key)
            .is_none_or(|o| (r.recorded_at, &r.trace_id) > (o.recorded_at, &o.trace_id));
        if newer {
            latest.insert(key, r);
        }
    }
    let mut units = std::collections::BTreeSet::new();
    let est = latest
        .values()
        .filter_map(|r| {
            let param = LiftParam::named(&r.joint, &r.param)?;
            let b = baseline_of(t, &r.joint, &r.param)?;
            let sd = (r.ci95[1] - r.ci95[0]) / (2.0 * Z95) / b;
            let ratio = r.value / b;
            (ratio.is_finite() && sd.is_finite() && sd > 0.0).then(|| {
                units.insert(r.serial.as_str());
                WorkshopEstimate {
                    param,
                    ratio,
                    sd_ratio: sd,
                }
            })
        })
        .collect();
    (est, units.len())
}

/// Version `version` of `model`'s prior, or (`None`) its newest; version 0 (the type file's)
/// when none is stored, or when `version` is 0.
pub async fn view(
    store: &Store,
    model: &str,
    version: Option<i64>,
) -> Result<FleetPriorView, PriorError> {
    let t = type_of(model)?;
    if version == Some(0) {
        return Ok(FleetPriorView::type_file(model, t));
    }
    Ok(match store.fleet_prior(model, version).await? {
        Some(p) => FleetPriorView::of(&p),
        None => FleetPriorView::type_file(model, t),
    })
}

/// The prior a fit of a `model` pantograph under job model version `job_version` uses: the
/// version the job names (a refit a new prior queued), else the newest. `None` for a type
/// without data here (its fit keeps Table 4 and records nothing).
pub async fn for_job(
    store: &Store,
    model: &str,
    job_version: &str,
) -> Result<Option<FitPrior>, StoreError> {
    if builtin(model).is_none() {
        return Ok(None);
    }
    let version = version_of_job(job_version);
    match view(store, model, version).await {
        Ok(v) => Ok(Some(v.fit_prior())),
        Err(PriorError::Store(e)) => Err(e),
        Err(PriorError::NoModel(_)) => Ok(None),
    }
}

/// What a relearn did.
#[derive(Debug, Clone, Serialize, ToSchema, PartialEq)]
pub struct Relearned {
    /// The current prior after the relearn (the new version when one was published).
    pub prior: FleetPriorView,
    /// Whether a new version was published.
    pub published: bool,
    /// Lift and force-gauge fits queued for a refit under the new version (0 when none was
    /// published).
    pub queued: u64,
    /// Workshop estimates (unit × joint × parameter) the learning read.
    pub n_estimates: usize,
}

/// Learn `model`'s prior from the workshop fits in the store and publish it as a new version
/// when it differs from the current one by more than `[fleet_prior] version_tolerance_relative`;
/// a new version queues the refit of every lift and gauge record fitted under an older one.
pub async fn relearn(store: &Store, model: &str) -> Result<Relearned, PriorError> {
    let t = type_of(model)?;
    let s = t.fleet_prior();
    let rows = store.param_evidence(None).await?;
    let (est, n_units) = workshop_estimates(&rows, model, t);
    let learned = learn(&est, s);
    let current = view(store, model, None).await?;
    if !learned.differs(&current.prior(), s.version_tolerance_relative) {
        return Ok(Relearned {
            prior: current,
            published: false,
            queued: 0,
            n_estimates: est.len(),
        });
    }
    let new = NewPrior {
        model: model.to_owned(),
        source: learned.source().to_owned(),
        n_units: n_units as i64,
        floor_relative_sd: s.floor_relative_sd,
        fit_sd_scale: s.fit_sd_scale,
        params: learned.params,
    };
    let p = store
        .publish_fleet_prior(&new, &PRIOR_KINDS, &refit_prefix())
        .await?;
    tracing::info!(model, version = p.prior.version, source = %p.prior.source, queued = p.queued,
        "fleet prior published");
    Ok(Relearned {
        prior: FleetPriorView::of(&p.prior),
        published: true,
        queued: p.queued,
        n_estimates: est.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_refit_names_its_prior_version_and_nothing_else_does() {
        assert_eq!(version_of_job(&format!("{}7", refit_prefix())), Some(7));
        assert_eq!(version_of_job(MODEL_VERSION), None);
        assert_eq!(version_of_job(&format!("{}0", refit_prefix())), None);
        assert_eq!(version_of_job(&format!("{}x", refit_prefix())), None);
        assert_eq!(version_of_job(&crate::pooled::pooled_version(3)), None);
    }

    #[test]
    fn version_zero_is_the_type_files_table_4_prior_unwidened() {
        let t = builtin("160EC").expect("160EC");
        let v = FleetPriorView::type_file("160EC", t);
        assert_eq!(v.source, "type_file");
        let f = v.fit_prior();
        assert_eq!(f.used.version, 0);
        assert_eq!(f.used.sd_scale, 1.0);
        // Every friction parameter at Table 4 (1) ± the floor: the fit as without a prior.
        assert!(!f.friction_prior.is_empty());
        for (_, m, sd) in &f.friction_prior {
            assert_eq!(*m, 1.0);
            assert_eq!(*sd, t.fleet_prior().floor_relative_sd);
        }
    }
}

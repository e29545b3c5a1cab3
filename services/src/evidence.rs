//! What each joint's state rests on, and which workshop test to do next (issue 37, points 1–2).
//!
//! Reads `param_evidence` (each parameter's latest informing test of each kind, written with
//! every fit) and hands the numbers to `models::contract::{evidence, plan}`: no statistics here.
//! - *Evidence*: per joint and parameter, the latest informing test over the kinds (kind, trace,
//!   date), its value and interval then, and the belief now — that interval widened by the time
//!   since at the parameter's wear rate: its own trend (stored after each fit, [`refresh_trends`])
//!   when it has ≥ 3 informing tests, else the fleet's (`[test_plan] fleet_wear_sd_per_year` of
//!   the type's data file; issue 37 point 3's learned fleet prior plugs in at [`fleet_rate`]).
//!   A parameter is `never_measured`, `measured` (judged now as a fit would judge that
//!   interval) or `uncertain` (measured on a date, its interval now wider than the watch band).
//! - *Plan*: the tests a depot can do — a swing of each joint (`pendulum`, `slider`), and each
//!   whole-pantograph kind (`lift`, `static_force`, …) — each informing a parameter as that kind
//!   last did on this pantograph (its interval's Fisher information), else as it does on average
//!   across the fleet; a kind that never informed a parameter is not credited with it. Ranked by
//!   `models::contract::plan::rank`.
//! - *Test due*: a joint whose older parameter's evidence is older than the type's
//!   `[test_plan] max_evidence_age_days` for it (`test_due`).

use std::collections::{BTreeMap, HashMap};

use chrono::{DateTime, Utc};
use pantowatch_models::data::{PantographType, TestPlanData, builtin};
use pantowatch_models::drift::{DriftThresholds, Status};
use pantowatch_models::evidence::{Belief, WearRate, information_of_interval};
use pantowatch_models::plan::{Informs, ParamNow, PlanItem, TestOption, rank};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::health::Param;
use crate::store::{EvidenceRow, JointPoint, Store, StoreError, StoredTrend};

/// Where a parameter's state stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum Standing {
    /// No test has informed it: the prior the lift fit assumes.
    NeverMeasured,
    /// Measured, and its interval now still judges (`status_now`).
    Measured,
    /// Measured on `test.recorded_at`; its interval now is wider than the watch band.
    Uncertain,
}

/// The test that last informed a parameter.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct EvidenceTest {
    pub kind: String,
    pub trace_id: String,
    pub recorded_at: DateTime<Utc>,
    pub value: f64,
    pub ci95: [f64; 2],
    /// Its verdict then.
    pub status: Status,
}

/// One parameter's evidence.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct EvidenceParam {
    pub param: Param,
    pub standing: Standing,
    /// Table 4 baseline.
    pub baseline: f64,
    /// `null` when never measured.
    pub test: Option<EvidenceTest>,
    /// Days from the test to `at`.
    pub age_days: Option<f64>,
    /// The wear rate the interval widened at.
    pub rate: WearRate,
    /// The belief now (`ci95` widened by the age at `rate`).
    pub now: Belief,
    /// That interval judged as a fit's would be (`unknown` when wider than the watch band).
    pub status_now: Status,
    /// Probability past the watch band (alarm included) and past the alarm band now.
    pub p_watch: f64,
    pub p_alarm: f64,
    /// "never measured", "measured on 2026-01-03", "measured on 2026-01-03, now uncertain".
    pub summary: String,
}

/// One joint's evidence.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct EvidenceJoint {
    pub joint: String,
    /// Age of its older parameter's evidence, days; `null` when one was never measured.
    pub age_days: Option<f64>,
    /// How old it may get before a workshop test is due (`[test_plan]`); `null`: never due.
    pub max_age_days: Option<f64>,
    /// Evidence older than `max_age_days`.
    pub test_due: bool,
    pub viscous: EvidenceParam,
    pub dry: EvidenceParam,
}

/// `GET /v1/pantographs/{serial}/evidence`.
#[derive(Debug, Clone, PartialEq, Serialize, ToSchema)]
pub struct PantographEvidence {
    pub serial: String,
    pub model: String,
    /// The time the ages and beliefs are at.
    pub at: DateTime<Utc>,
    pub joints: Vec<EvidenceJoint>,
}

/// `GET /v1/pantographs/{serial}/plan`.
#[derive(Debug, Clone, PartialEq, Serialize, ToSchema)]
pub struct PantographPlan {
    pub serial: String,
    pub at: DateTime<Utc>,
    /// Ranked, most bought first.
    pub tests: Vec<PlanItem>,
}

/// One entry of the fleet plan: a pantograph's test.
#[derive(Debug, Clone, PartialEq, Serialize, ToSchema)]
pub struct FleetPlanEntry {
    pub serial: String,
    /// Age of the pantograph's oldest joint evidence, days (never-measured joints aside).
    pub oldest_evidence_days: Option<f64>,
    /// The age that joint's evidence may reach before a test is due (`null`: never due).
    pub oldest_allowed_days: Option<f64>,
    /// The joints whose test is due.
    pub tests_due: Vec<String>,
    #[serde(flatten)]
    pub test: PlanItem,
}

/// `GET /v1/fleet/plan`.
#[derive(Debug, Clone, PartialEq, Serialize, ToSchema)]
pub struct FleetPlan {
    pub at: DateTime<Utc>,
    pub pantographs: usize,
    /// Each pantograph's best test, ranked across the fleet; at most `limit`.
    pub tests: Vec<FleetPlanEntry>,
}

/// Single-joint test kinds: a swing of one joint informs that joint.
pub(crate) const JOINT_KINDS: [&str; 2] = ["pendulum", "slider"];

/// The type's plan data, if any.
fn plan_data(t: &PantographType) -> Option<&TestPlanData> {
    t.test_plan.as_ref()
}

/// The fleet's wear rate of a parameter with this baseline. Issue 37 point 3's learned fleet
/// prior plugs in here; until then the type's `[test_plan] fleet_wear_sd_per_year`.
pub fn fleet_rate(t: &PantographType, baseline: f64) -> WearRate {
    WearRate::fleet(
        baseline,
        plan_data(t).map_or(0.0, |d| d.fleet_wear_sd_per_year),
    )
}

pub(crate) fn baseline_of(t: &PantographType, joint: &str, p: Param) -> Option<f64> {
    let j = t.joint(joint)?;
    let b = match p {
        Param::Viscous => j.viscous_baseline(),
        Param::Dry => j.dry_mu,
    };
    (b.is_finite() && b > 0.0).then_some(b)
}

/// The newest evidence row of `joint`'s parameter `p` (ties broken by trace id), if any.
pub(crate) fn latest_row<'a>(
    rows: &[&'a EvidenceRow],
    joint: &str,
    p: Param,
) -> Option<&'a EvidenceRow> {
    rows.iter()
        .copied()
        .filter(|r| r.joint == joint && r.param == p.as_str())
        .max_by(|a, b| {
            a.recorded_at
                .cmp(&b.recorded_at)
                .then(a.trace_id.cmp(&b.trace_id))
        })
}

pub(crate) fn days(from: DateTime<Utc>, to: DateTime<Utc>) -> f64 {
    ((to - from).num_milliseconds() as f64 / 86_400_000.0).max(0.0)
}

/// The evidence of one pantograph from its `param_evidence` rows, at `at`.
pub fn pantograph_evidence(
    serial: &str,
    t: &PantographType,
    rows: &[&EvidenceRow],
    at: DateTime<Utc>,
) -> PantographEvidence {
    let th = DriftThresholds::default();
    let unmeasured_sd = plan_data(t).map_or(0.5, |d| d.unmeasured_relative_sd);
    let joints = t
        .joints
        .keys()
        .filter_map(|joint| {
            let param = |p: Param| -> Option<EvidenceParam> {
                let baseline = baseline_of(t, joint, p)?;
                let latest = latest_row(rows, joint, p);
                let fleet = fleet_rate(t, baseline);
                let measured =
                    latest.and_then(|r| Some((r, Belief::from_interval(r.value, r.ci95)?)));
                let Some((r, then)) = measured else {
                    let now = Belief::unmeasured(baseline, unmeasured_sd);
                    let [p_watch, p_alarm] = ParamNow {
                        joint: joint.clone(),
                        param: p.as_str().into(),
                        baseline,
                        belief: now,
                        seen: Status::Unknown,
                    }
                    .p_past(&th);
                    return Some(EvidenceParam {
                        param: p,
                        standing: Standing::NeverMeasured,
                        baseline,
                        test: None,
                        age_days: None,
                        rate: fleet,
                        now,
                        status_now: Status::Unknown,
                        p_watch,
                        p_alarm,
                        summary: "never measured".into(),
                    });
                };
                let rate = match r.trend {
                    Some(tr) => {
                        WearRate::from_trend(tr.slope_per_day, tr.slope_ci95, tr.significant, fleet)
                    }
                    None => fleet,
                };
                let age = days(r.recorded_at, at);
                let now = then.widened(age, &rate);
                let status_now = th.judge(now.ci95, now.mean, Some(baseline)).status;
                let [p_watch, p_alarm] = ParamNow {
                    joint: joint.clone(),
                    param: p.as_str().into(),
                    baseline,
                    belief: now,
                    seen: r.status,
                }
                .p_past(&th);
                let date = r.recorded_at.format("%Y-%m-%d");
                let (standing, summary) = if status_now == Status::Unknown {
                    (
                        Standing::Uncertain,
                        format!("measured on {date}, now uncertain"),
                    )
                } else {
                    (Standing::Measured, format!("measured on {date}"))
                };
                Some(EvidenceParam {
                    param: p,
                    standing,
                    baseline,
                    test: Some(EvidenceTest {
                        kind: r.kind.clone(),
                        trace_id: r.trace_id.clone(),
                        recorded_at: r.recorded_at,
                        value: r.value,
                        ci95: r.ci95,
                        status: r.status,
                    }),
                    age_days: Some(age),
                    rate,
                    now,
                    status_now,
                    p_watch,
                    p_alarm,
                    summary,
                })
            };
            let (viscous, dry) = (param(Param::Viscous)?, param(Param::Dry)?);
            let age_days = viscous.age_days.zip(dry.age_days).map(|(a, b)| a.max(b));
            let max_age_days =
                plan_data(t).and_then(|d| d.max_evidence_age_days.get(joint).copied());
            Some(EvidenceJoint {
                joint: joint.clone(),
                test_due: age_days.zip(max_age_days).is_some_and(|(a, m)| a > m),
                age_days,
                max_age_days,
                viscous,
                dry,
            })
        })
        .collect();
    PantographEvidence {
        serial: serial.to_owned(),
        model: t.model.clone(),
        at,
        joints,
    }
}

/// Mean Fisher information per (kind, joint, param) over the fleet's evidence rows: what a kind
/// of test gives on a parameter of a pantograph that has never had it.
pub type KindInformation = HashMap<(String, String, String), f64>;

/// The fleet's [`KindInformation`] from every evidence row: the information of the mean sd.
pub fn kind_information(rows: &[EvidenceRow]) -> KindInformation {
    let mut sums: HashMap<(String, String, String), (f64, usize)> = HashMap::new();
    for r in rows {
        if let Some(info) = information_of_interval(r.ci95) {
            let e = sums
                .entry((r.kind.clone(), r.joint.clone(), r.param.clone()))
                .or_insert((0.0, 0));
            e.0 += info.sqrt().recip();
            e.1 += 1;
        }
    }
    sums.into_iter()
        .map(|(k, (sd, n))| (k, (sd / n as f64).powi(-2)))
        .collect()
}

/// The plan of one pantograph: its evidence, its own rows (what each kind gave it) and the
/// fleet's information per kind.
pub fn plan_of(
    ev: &PantographEvidence,
    rows: &[&EvidenceRow],
    fleet: &KindInformation,
) -> Vec<PlanItem> {
    let params: Vec<ParamNow> = ev
        .joints
        .iter()
        .flat_map(|j| [&j.viscous, &j.dry].map(|p| (j.joint.clone(), p)))
        .map(|(joint, p)| ParamNow {
            joint,
            param: p.param.as_str().into(),
            baseline: p.baseline,
            belief: p.now,
            seen: p.test.as_ref().map_or(Status::Unknown, |t| t.status),
        })
        .collect();
    // What each kind informs: this pantograph's own last test of it, else the fleet's mean.
    let mut by_kind: BTreeMap<(String, Option<String>), Vec<Informs>> = BTreeMap::new();
    let own = |kind: &str, joint: &str, param: &str| {
        rows.iter()
            .find(|r| r.kind == kind && r.joint == joint && r.param == param)
            .and_then(|r| information_of_interval(r.ci95))
    };
    for ((kind, joint, param), fleet_info) in fleet {
        let info = own(kind, joint, param).unwrap_or(*fleet_info);
        let key = if JOINT_KINDS.contains(&kind.as_str()) {
            (kind.clone(), Some(joint.clone()))
        } else {
            (kind.clone(), None)
        };
        by_kind.entry(key).or_default().push(Informs {
            joint: joint.clone(),
            param: param.clone(),
            info,
        });
    }
    let options: Vec<TestOption> = by_kind
        .into_iter()
        .map(|((kind, joint), mut informs)| {
            informs.sort_by(|a, b| (&a.joint, &a.param).cmp(&(&b.joint, &b.param)));
            TestOption {
                kind,
                joint,
                informs,
            }
        })
        .collect();
    rank(&params, &options, &DriftThresholds::default())
}

/// The type of a pantograph model, when compiled in.
pub fn type_of(model: &str) -> Option<&'static PantographType> {
    builtin(model)
}

/// Groups the fleet's rows by serial.
pub fn by_serial(rows: &[EvidenceRow]) -> BTreeMap<&str, Vec<&EvidenceRow>> {
    let mut m: BTreeMap<&str, Vec<&EvidenceRow>> = BTreeMap::new();
    for r in rows {
        m.entry(r.serial.as_str()).or_default().push(r);
    }
    m
}

/// The fleet plan from every evidence row: each pantograph's best test, ranked by what it buys.
/// `models` maps the model name of each serial; `pantographs` without a row (never measured at
/// all) are not in it.
pub fn fleet_plan(rows: &[EvidenceRow], at: DateTime<Utc>, limit: usize) -> FleetPlan {
    fleet_plan_with(rows, &kind_information(rows), at, limit)
}

/// [`fleet_plan`] with the fleet's information per kind computed already (kept with the rows).
pub fn fleet_plan_with(
    rows: &[EvidenceRow],
    fleet: &KindInformation,
    at: DateTime<Utc>,
    limit: usize,
) -> FleetPlan {
    let grouped = by_serial(rows);
    let mut tests: Vec<FleetPlanEntry> = grouped
        .iter()
        .filter_map(|(serial, rs)| {
            let t = type_of(&rs.first()?.model)?;
            let ev = pantograph_evidence(serial, t, rs, at);
            let best = plan_of(&ev, rs, fleet).into_iter().next()?;
            let oldest = ev
                .joints
                .iter()
                .filter(|j| j.age_days.is_some())
                .max_by(|a, b| {
                    a.age_days
                        .partial_cmp(&b.age_days)
                        .unwrap_or(std::cmp::Ordering::Equal)
                });
            Some(FleetPlanEntry {
                serial: (*serial).to_owned(),
                oldest_evidence_days: oldest.and_then(|j| j.age_days),
                oldest_allowed_days: oldest.and_then(|j| j.max_age_days),
                tests_due: ev
                    .joints
                    .iter()
                    .filter(|j| j.test_due)
                    .map(|j| j.joint.clone())
                    .collect(),
                test: best,
            })
        })
        .collect();
    tests.sort_by(|a, b| {
        b.test
            .buys
            .total_cmp(&a.test.buys)
            .then(b.test.info_bits.total_cmp(&a.test.info_bits))
            .then_with(|| a.serial.cmp(&b.serial))
    });
    tests.truncate(limit);
    FleetPlan {
        at,
        pantographs: grouped.len(),
        tests,
    }
}

/// The oldest measured joint evidence of a pantograph, days.
pub fn oldest_days(ev: &PantographEvidence) -> Option<f64> {
    ev.joints
        .iter()
        .flat_map(|j| [j.viscous.age_days, j.dry.age_days])
        .flatten()
        .reduce(f64::max)
}

/// Writes each parameter's trend of `serial` on its evidence rows (after a fit of it): the
/// trend over its informing tests (`health::param_trend`, `models::trend`).
pub async fn refresh_trends(store: &Store, serial: &str) -> Result<(), StoreError> {
    let history = store.serial_history(serial).await?;
    let mut by_joint: BTreeMap<&str, Vec<JointPoint>> = BTreeMap::new();
    for p in &history {
        by_joint
            .entry(p.fit.joint.as_str())
            .or_default()
            .push(p.clone());
    }
    let mut trends = Vec::new();
    for (joint, points) in by_joint {
        for p in Param::BOTH {
            let tr = crate::health::param_trend(&points, p, None, [0.5, 2.0]);
            let stored = tr.trend.map(|t| StoredTrend {
                slope_per_day: t.slope_per_day,
                slope_ci95: t.slope_ci95,
                significant: t.significant,
            });
            trends.push((joint.to_owned(), p.as_str().to_owned(), stored));
        }
    }
    store.set_param_trends(serial, &trends).await
}

/// Why evidence could not be read for a pantograph.
#[derive(Debug, thiserror::Error)]
pub enum EvidenceError {
    #[error(transparent)]
    Store(#[from] StoreError),
    #[error("no pantograph `{0}`")]
    NoPantograph(String),
    #[error("pantograph type `{0}` has no data here")]
    NoModel(String),
}

/// A pantograph's evidence, its own rows and the fleet's information per kind, read from the
/// store.
pub async fn load(
    store: &Store,
    serial: &str,
    at: DateTime<Utc>,
) -> Result<(PantographEvidence, Vec<PlanItem>), EvidenceError> {
    let model = store
        .pantograph_model(serial)
        .await?
        .ok_or_else(|| EvidenceError::NoPantograph(serial.to_owned()))?;
    let t = type_of(&model).ok_or_else(|| EvidenceError::NoModel(model.clone()))?;
    let all = store.param_evidence(None).await?;
    let fleet = kind_information(&all);
    let own: Vec<&EvidenceRow> = all.iter().filter(|r| r.serial == serial).collect();
    let ev = pantograph_evidence(serial, t, &own, at);
    let plan = plan_of(&ev, &own, &fleet);
    Ok((ev, plan))
}

/// The alert name of a joint's test due (`J5 test due`; one live alert per joint).
pub fn test_due_alert(joint: &str) -> String {
    format!("{joint} test due")
}

/// The evidence of a pantograph at its newest test (the time `test due` is judged at): the
/// evidence rows of the serial, read again after a fit.
pub async fn at_newest_test(
    store: &Store,
    serial: &str,
) -> Result<Option<PantographEvidence>, StoreError> {
    let Some(model) = store.pantograph_model(serial).await? else {
        return Ok(None);
    };
    let Some(t) = type_of(&model) else {
        return Ok(None);
    };
    let rows = store.param_evidence(Some(serial)).await?;
    let newest = store
        .latest_test_at(serial)
        .await?
        .or_else(|| rows.iter().map(|r| r.recorded_at).max());
    let Some(at) = newest else {
        return Ok(None);
    };
    let own: Vec<&EvidenceRow> = rows.iter().collect();
    Ok(Some(pantograph_evidence(serial, t, &own, at)))
}

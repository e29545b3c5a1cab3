//! The fleet plan from kept evidence (issue 37): the fleet's `param_evidence` rows grouped once
//! per evidence version — each parameter's latest test, its wear rate, each test option and the
//! information it gives — so a request at an `at` only widens ~18 beliefs and scores ~10 options
//! per pantograph; and [`PlanCache`], which keeps that index and the last `at`'s ranking until a
//! fit moves the store's evidence version.
//!
//! A plan at `at` is two steps: [`FleetIndex::rank`] scores each pantograph's best test (only
//! the numbers the order needs: each parameter's widened belief and its `p_unseen`, one band's
//! `erfc`s) and [`FleetIndex::served`] builds the full entries of the first `limit` only (a
//! selection, then a sort of those). The numbers are [`crate::evidence::fleet_plan`]'s, computed
//! by the same functions in the same order (`models::plan::{p_past, p_unseen_of, p_unseen_at}`,
//! `Belief::{widened, sd_after}`, the same sums and the same orderings); `evidence::fleet_plan`
//! stays the reference a test compares this with.

use std::cmp::Ordering;
use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};

use chrono::{DateTime, Utc};
use pantowatch_models::data::PantographType;
use pantowatch_models::drift::{DriftThresholds, Status};
use pantowatch_models::evidence::{Belief, WearRate, information_of_interval};
use pantowatch_models::plan::{PlanItem, PlanParam, p_past, p_unseen_at, p_unseen_of};

use crate::evidence::{
    FleetPlan, FleetPlanEntry, JOINT_KINDS, KindInformation, baseline_of, by_serial, days,
    fleet_rate, kind_information, latest_row, type_of,
};
use crate::health::Param;
use crate::store::{EvidenceRow, Store, StoreError};

/// A parameter's state apart from the time: the prior (never measured) or its latest test.
#[derive(Debug, Clone)]
enum Then {
    /// The prior's belief, its `[p_watch, p_alarm]` and `p_unseen` (the same at every `at`).
    Never {
        belief: Belief,
        past: [f64; 2],
        p_unseen: f64,
    },
    Measured {
        then: Belief,
        rate: WearRate,
        recorded_at: DateTime<Utc>,
        seen: Status,
    },
}

#[derive(Debug, Clone)]
struct ParamIndex {
    joint: String,
    param: Param,
    baseline: f64,
    then: Then,
    /// Whether a test option informs it (else ranking needs nothing of it).
    informed: bool,
}

#[derive(Debug, Clone)]
struct JointIndex {
    name: String,
    max_age_days: Option<f64>,
    /// Indices of its viscous and dry parameters.
    params: [usize; 2],
}

/// A test option: kind, swung joint, and (parameter index, information) in `(joint, param)`
/// order — only the parameters the pantograph's evidence has.
#[derive(Debug, Clone)]
struct OptionIndex {
    kind: String,
    joint: Option<String>,
    informs: Vec<(usize, f64)>,
}

#[derive(Debug, Clone)]
struct PantographIndex {
    serial: String,
    params: Vec<ParamIndex>,
    joints: Vec<JointIndex>,
    options: Vec<OptionIndex>,
}

/// A parameter at `at`.
#[derive(Debug, Clone, Copy)]
struct Now {
    belief: Belief,
    age_days: Option<f64>,
    past: [f64; 2],
    p_unseen: f64,
}

/// The fleet's evidence grouped per pantograph (serial order), ready to plan at any `at`.
#[derive(Debug, Clone, Default)]
pub struct FleetIndex {
    /// Serials with evidence (of a known type or not).
    pantographs: usize,
    entries: Vec<PantographIndex>,
}

/// A (joint, param, information) an option informs, before it is resolved to an index.
type Informs<'a> = (&'a str, &'a str, f64);

/// One pantograph's index from its rows (as `evidence::pantograph_evidence` and
/// `evidence::plan_of` read them).
fn pantograph(
    serial: &str,
    t: &PantographType,
    rows: &[&EvidenceRow],
    fleet: &KindInformation,
    th: &DriftThresholds,
) -> PantographIndex {
    let unmeasured_sd = t
        .test_plan
        .as_ref()
        .map_or(0.5, |d| d.unmeasured_relative_sd);
    let mut params = Vec::new();
    let mut joints = Vec::new();
    for joint in t.joints.keys() {
        let param = |p: Param| -> Option<ParamIndex> {
            let baseline = baseline_of(t, joint, p)?;
            let latest = latest_row(rows, joint, p);
            let fleet = fleet_rate(t, baseline);
            let measured = latest.and_then(|r| Some((r, Belief::from_interval(r.value, r.ci95)?)));
            let then = match measured {
                None => {
                    let belief = Belief::unmeasured(baseline, unmeasured_sd);
                    let past = p_past(&belief, baseline, th);
                    Then::Never {
                        belief,
                        past,
                        p_unseen: p_unseen_of(Status::Unknown, past),
                    }
                }
                Some((r, then)) => Then::Measured {
                    then,
                    rate: match r.trend {
                        Some(tr) => WearRate::from_trend(
                            tr.slope_per_day,
                            tr.slope_ci95,
                            tr.significant,
                            fleet,
                        ),
                        None => fleet,
                    },
                    recorded_at: r.recorded_at,
                    seen: r.status,
                },
            };
            Some(ParamIndex {
                joint: joint.clone(),
                param: p,
                baseline,
                then,
                informed: false,
            })
        };
        let (Some(viscous), Some(dry)) = (param(Param::Viscous), param(Param::Dry)) else {
            continue;
        };
        let at = params.len();
        params.push(viscous);
        params.push(dry);
        joints.push(JointIndex {
            name: joint.clone(),
            max_age_days: t
                .test_plan
                .as_ref()
                .and_then(|d| d.max_evidence_age_days.get(joint).copied()),
            params: [at, at + 1],
        });
    }
    // The options, as `evidence::plan_of` builds them: this pantograph's own last test of a
    // kind, else the fleet's mean; grouped by (kind, swung joint), informs by (joint, param).
    let mut by_kind: BTreeMap<(String, Option<String>), Vec<Informs>> = BTreeMap::new();
    for ((kind, joint, param), fleet_info) in fleet {
        let info = rows
            .iter()
            .find(|r| r.kind == *kind && r.joint == *joint && r.param == *param)
            .and_then(|r| information_of_interval(r.ci95))
            .unwrap_or(*fleet_info);
        let key = if JOINT_KINDS.contains(&kind.as_str()) {
            (kind.clone(), Some(joint.clone()))
        } else {
            (kind.clone(), None)
        };
        by_kind
            .entry(key)
            .or_default()
            .push((joint.as_str(), param.as_str(), info));
    }
    let options: Vec<OptionIndex> = by_kind
        .into_iter()
        .filter_map(|((kind, joint), mut informs)| {
            informs.sort_by(|a, b| (a.0, a.1).cmp(&(b.0, b.1)));
            let informs: Vec<(usize, f64)> = informs
                .into_iter()
                .filter_map(|(j, p, info)| {
                    let i = params
                        .iter()
                        .position(|x| x.joint == j && x.param.as_str() == p)?;
                    Some((i, info))
                })
                .collect();
            (!informs.is_empty()).then_some(OptionIndex {
                kind,
                joint,
                informs,
            })
        })
        .collect();
    for o in &options {
        for &(i, _) in &o.informs {
            params[i].informed = true;
        }
    }
    PantographIndex {
        serial: serial.to_owned(),
        params,
        joints,
        options,
    }
}

/// A parameter at `at` as ranking needs it: its belief and `p_unseen` (not `p_watch`/`p_alarm`).
#[derive(Debug, Clone, Copy)]
struct Scored {
    belief: Belief,
    p_unseen: f64,
}

/// What an option buys at `at` (`models::plan::rank`'s sums): `(buys, info_bits)`, `None`
/// when it shrinks no parameter's uncertainty.
fn score(o: &OptionIndex, now: &[Scored]) -> Option<(f64, f64)> {
    let (mut buys, mut bits, mut any) = (0.0, 0.0, false);
    for &(i, info) in &o.informs {
        let b = &now[i].belief;
        let sd_now = b.sd;
        let sd_after = b.sd_after(info);
        if !(sd_now > 0.0 && sd_after < sd_now) {
            continue;
        }
        buys += now[i].p_unseen * (1.0 - sd_after / sd_now);
        bits += (sd_now / sd_after).log2();
        any = true;
    }
    any.then_some((buys, bits))
}

/// The ranked test of an option in full (`models::plan::rank`'s item).
fn item(o: &OptionIndex, p: &PantographIndex, now: &[Now]) -> PlanItem {
    let mut item = PlanItem {
        kind: o.kind.clone(),
        joint: o.joint.clone(),
        buys: 0.0,
        p_unseen: 0.0,
        p_watch: 0.0,
        p_alarm: 0.0,
        info_bits: 0.0,
        params: Vec::with_capacity(o.informs.len()),
    };
    for &(i, info) in &o.informs {
        let n = &now[i];
        let sd_now = n.belief.sd;
        let sd_after = n.belief.sd_after(info);
        if !(sd_now > 0.0 && sd_after < sd_now) {
            continue;
        }
        let [p_watch, p_alarm] = n.past;
        item.buys += n.p_unseen * (1.0 - sd_after / sd_now);
        item.p_unseen = item.p_unseen.max(n.p_unseen);
        item.info_bits += (sd_now / sd_after).log2();
        item.p_watch = item.p_watch.max(p_watch);
        item.p_alarm = item.p_alarm.max(p_alarm);
        item.params.push(PlanParam {
            joint: p.params[i].joint.clone(),
            param: p.params[i].param.as_str().into(),
            p_watch,
            p_alarm,
            p_unseen: n.p_unseen,
            sd_now,
            sd_after,
        });
    }
    item
}

/// `rank`'s order: most bought first, then most bits, then kind and joint.
fn rank_order(a: (f64, f64, &OptionIndex), b: (f64, f64, &OptionIndex)) -> Ordering {
    b.0.total_cmp(&a.0)
        .then(b.1.total_cmp(&a.1))
        .then_with(|| a.2.kind.cmp(&b.2.kind))
        .then_with(|| a.2.joint.cmp(&b.2.joint))
}

/// One pantograph's best option at `at`: (its index in the fleet, option index, buys, bits).
type Best = (usize, usize, f64, f64);

/// Each pantograph's best test at an `at`, scored, in fleet (serial) order: what a plan at that
/// `at` serves the first `limit` of ([`FleetIndex::served`]).
#[derive(Debug, Clone)]
pub struct Ranked {
    at: DateTime<Utc>,
    best: Vec<Best>,
}

impl FleetIndex {
    /// Groups every evidence row of the fleet (the work done once per evidence version).
    pub fn build(rows: &[EvidenceRow]) -> FleetIndex {
        Self::build_with(rows, &kind_information(rows))
    }

    /// [`FleetIndex::build`] with the fleet's information per kind computed already.
    pub fn build_with(rows: &[EvidenceRow], fleet: &KindInformation) -> FleetIndex {
        let th = DriftThresholds::default();
        let grouped = by_serial(rows);
        let entries = grouped
            .iter()
            .filter_map(|(serial, rs)| {
                let t = type_of(&rs.first()?.model)?;
                Some(pantograph(serial, t, rs, fleet, &th))
            })
            .collect();
        FleetIndex {
            pantographs: grouped.len(),
            entries,
        }
    }

    /// The parameters of pantograph `p` at `at` (`evidence::pantograph_evidence`'s beliefs).
    fn now(p: &PantographIndex, at: DateTime<Utc>, th: &DriftThresholds, out: &mut Vec<Now>) {
        out.clear();
        out.extend(p.params.iter().map(|x| match &x.then {
            Then::Never {
                belief,
                past,
                p_unseen,
            } => Now {
                belief: *belief,
                age_days: None,
                past: *past,
                p_unseen: *p_unseen,
            },
            Then::Measured {
                then,
                rate,
                recorded_at,
                seen,
            } => {
                let age = days(*recorded_at, at);
                let belief = then.widened(age, rate);
                let past = p_past(&belief, x.baseline, th);
                Now {
                    belief,
                    age_days: Some(age),
                    past,
                    p_unseen: p_unseen_of(*seen, past),
                }
            }
        }));
    }

    /// The parameters of pantograph `p` at `at` as ranking needs them: the widened belief and
    /// `p_unseen` of each parameter an option informs (`p_unseen_at`: one band, not both).
    fn scored(p: &PantographIndex, at: DateTime<Utc>, th: &DriftThresholds, out: &mut Vec<Scored>) {
        out.clear();
        out.extend(p.params.iter().map(|x| match &x.then {
            Then::Never {
                belief, p_unseen, ..
            } => Scored {
                belief: *belief,
                p_unseen: *p_unseen,
            },
            Then::Measured { .. } if !x.informed => Scored {
                belief: Belief::new(f64::NAN, f64::NAN),
                p_unseen: f64::NAN,
            },
            Then::Measured {
                then,
                rate,
                recorded_at,
                seen,
            } => {
                let belief = then.widened(days(*recorded_at, at), rate);
                Scored {
                    belief,
                    p_unseen: p_unseen_at(&belief, x.baseline, *seen, th),
                }
            }
        }));
    }

    /// Each pantograph's best test at `at`, scored (`models::plan::rank`'s first item, by the
    /// same sums), without building any item.
    pub fn rank(&self, at: DateTime<Utc>) -> Ranked {
        let th = DriftThresholds::default();
        let mut now = Vec::new();
        let mut best: Vec<Best> = Vec::with_capacity(self.entries.len());
        for (k, p) in self.entries.iter().enumerate() {
            Self::scored(p, at, &th, &mut now);
            let mut top: Option<(f64, f64, usize)> = None;
            for (i, o) in p.options.iter().enumerate() {
                let Some((buys, bits)) = score(o, &now) else {
                    continue;
                };
                let better = top.is_none_or(|(b, n, j)| {
                    rank_order((buys, bits, o), (b, n, &p.options[j])) == Ordering::Less
                });
                if better {
                    top = Some((buys, bits, i));
                }
            }
            if let Some((buys, bits, i)) = top {
                best.push((k, i, buys, bits));
            }
        }
        Ranked { at, best }
    }

    /// The first `limit` tests of a ranking, each entry built in full: `evidence::fleet_plan`'s
    /// order (most bought, most bits, then serial — a total order, serials being unique, so a
    /// selection of the first `limit` and a sort of them give its stable sort's first `limit`).
    pub fn served(&self, ranked: &Ranked, limit: usize) -> FleetPlan {
        let order = |a: &Best, b: &Best| {
            b.2.total_cmp(&a.2)
                .then(b.3.total_cmp(&a.3))
                .then_with(|| self.entries[a.0].serial.cmp(&self.entries[b.0].serial))
        };
        let mut top = ranked.best.clone();
        if limit == 0 {
            top.clear();
        } else if limit < top.len() {
            top.select_nth_unstable_by(limit - 1, order);
            top.truncate(limit);
        }
        top.sort_unstable_by(order);
        let th = DriftThresholds::default();
        let mut now = Vec::new();
        let tests = top
            .iter()
            .map(|&(k, i, _, _)| {
                let p = &self.entries[k];
                Self::now(p, ranked.at, &th, &mut now);
                self.entry(p, &p.options[i], &now)
            })
            .collect();
        FleetPlan {
            at: ranked.at,
            pantographs: self.pantographs,
            tests,
        }
    }

    /// The fleet plan at `at`, its first `limit` tests: `evidence::fleet_plan`'s answer.
    pub fn plan(&self, at: DateTime<Utc>, limit: usize) -> FleetPlan {
        self.served(&self.rank(at), limit)
    }

    fn entry(&self, p: &PantographIndex, o: &OptionIndex, now: &[Now]) -> FleetPlanEntry {
        let age = |j: &JointIndex| {
            now[j.params[0]]
                .age_days
                .zip(now[j.params[1]].age_days)
                .map(|(a, b)| a.max(b))
        };
        let oldest = p
            .joints
            .iter()
            .filter_map(|j| Some((j, age(j)?)))
            .max_by(|a, b| a.1.partial_cmp(&b.1).unwrap_or(Ordering::Equal));
        FleetPlanEntry {
            serial: p.serial.clone(),
            oldest_evidence_days: oldest.map(|(_, a)| a),
            oldest_allowed_days: oldest.and_then(|(j, _)| j.max_age_days),
            tests_due: p
                .joints
                .iter()
                .filter(|j| age(j).zip(j.max_age_days).is_some_and(|(a, m)| a > m))
                .map(|j| j.name.clone())
                .collect(),
            test: item(o, p, now),
        }
    }
}

/// The fleet's evidence, grouped ([`FleetIndex`]), and the last `at`'s ranking computed from it,
/// kept in memory until the store's evidence version moves (a fit's refresh or trends):
/// reading 16–40 rows per pantograph and grouping them cost more than the plan itself. One
/// entry; a plan at another `at` is ranked from the kept index, and each request builds only
/// the entries it serves.
#[derive(Debug, Clone, Default)]
pub struct PlanCache(Arc<Mutex<Option<CachedPlan>>>);

#[derive(Debug)]
struct CachedPlan {
    version: i64,
    index: Arc<FleetIndex>,
    ranked: Option<Arc<Ranked>>,
}

impl PlanCache {
    /// The fleet plan at `at`, its first `limit` tests, from the kept index (and the kept
    /// ranking when `at` is the last one's) while the evidence version stands, else read and
    /// grouped again. One store query when kept: the evidence version.
    pub async fn fleet_plan(
        &self,
        store: &Store,
        at: DateTime<Utc>,
        limit: usize,
    ) -> Result<FleetPlan, StoreError> {
        let version = store.evidence_version().await?;
        let kept = {
            let g = self.0.lock().unwrap_or_else(|e| e.into_inner());
            match g.as_ref() {
                Some(c) if c.version == version => {
                    Some((c.index.clone(), c.ranked.clone().filter(|r| r.at == at)))
                }
                _ => None,
            }
        };
        let (index, ranked) = match kept {
            Some(k) => k,
            None => {
                let rows = store.param_evidence(None).await?;
                let index = tokio::task::spawn_blocking(move || Arc::new(FleetIndex::build(&rows)))
                    .await
                    .map_err(|e| StoreError::Task(e.to_string()))?;
                (index, None)
            }
        };
        let fresh = ranked.is_none();
        let (ranked, plan) = {
            let index = index.clone();
            tokio::task::spawn_blocking(move || {
                let ranked = ranked.unwrap_or_else(|| Arc::new(index.rank(at)));
                let plan = index.served(&ranked, limit);
                (ranked, plan)
            })
            .await
            .map_err(|e| StoreError::Task(e.to_string()))?
        };
        if fresh {
            let mut g = self.0.lock().unwrap_or_else(|e| e.into_inner());
            *g = Some(CachedPlan {
                version,
                index,
                ranked: Some(ranked),
            });
        }
        Ok(plan)
    }
}

#[cfg(test)]
mod tests {
    use chrono::TimeZone;

    use super::*;
    use crate::evidence::fleet_plan;
    use crate::store::StoredTrend;

    /// splitmix64: a reproducible stream for the random fleet.
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        }
        fn unit(&mut self) -> f64 {
            (self.next() >> 11) as f64 / (1u64 << 53) as f64
        }
        fn pick<'a, T>(&mut self, xs: &'a [T]) -> &'a T {
            &xs[(self.next() % xs.len() as u64) as usize]
        }
    }

    /// A random fleet's `param_evidence`: pantographs of the 160EC (and one of a type not
    /// compiled in), each parameter's latest test of each kind at a random date and factor
    /// over its baseline, some intervals empty or not numbers, some rows with a trend, some
    /// tests at the same instant.
    fn random_rows(seed: u64, serials: usize) -> Vec<EvidenceRow> {
        let mut r = Rng(seed);
        let t = type_of("160EC").expect("160EC");
        let kinds = ["lift", "pendulum", "slider", "static_force", "quadrangle"];
        let statuses = [Status::Ok, Status::Ok, Status::Watch, Status::Alarm];
        let t0 = Utc
            .with_ymd_and_hms(2025, 1, 1, 8, 0, 0)
            .single()
            .expect("date");
        let mut rows = Vec::new();
        for s in 0..serials {
            let serial = format!("160EC-{s:04}");
            let model = if s == 3 { "999XY" } else { "160EC" };
            for joint in t.joints.keys() {
                for p in Param::BOTH {
                    let base = baseline_of(t, joint, p).unwrap_or(0.1);
                    for kind in kinds {
                        if r.unit() < 0.6 {
                            continue;
                        }
                        let value = base * (0.4 + 2.2 * r.unit());
                        let half = value * (0.02 + 0.5 * r.unit());
                        let ci95 = match r.next() % 20 {
                            0 => [value, value],
                            1 => [f64::NAN, value],
                            _ => [value - half, value + half],
                        };
                        let day = (r.next() % 400) as i64;
                        let trend = (r.unit() < 0.3).then(|| {
                            let slope = base * (r.unit() - 0.3) * 1e-3;
                            StoredTrend {
                                slope_per_day: slope,
                                slope_ci95: [slope - base * 1e-4, slope + base * 1e-4],
                                significant: r.unit() < 0.5,
                            }
                        });
                        rows.push(EvidenceRow {
                            serial: serial.clone(),
                            model: model.into(),
                            joint: joint.clone(),
                            param: p.as_str().into(),
                            trace_id: format!("{serial}-{}", r.next() % 50),
                            fit_id: rows.len() as i64,
                            kind: kind.into(),
                            recorded_at: t0 + chrono::TimeDelta::days(day),
                            value,
                            ci95,
                            status: *r.pick(&statuses),
                            trend,
                        });
                    }
                }
            }
        }
        // The store's order is not the plan's: shuffle.
        for i in (1..rows.len()).rev() {
            rows.swap(i, (r.next() % (i as u64 + 1)) as usize);
        }
        rows
    }

    #[test]
    fn the_grouped_plan_is_the_plan_from_scratch_on_random_fleets() {
        for seed in 0..6 {
            let rows = random_rows(seed, 25);
            let index = FleetIndex::build(&rows);
            for (days, limit) in [(0, 1000), (90, 5), (200, 1000), (500, 10), (1500, 1000)] {
                let at = Utc
                    .with_ymd_and_hms(2025, 1, 1, 0, 0, 0)
                    .single()
                    .expect("date")
                    + chrono::TimeDelta::days(days)
                    + chrono::TimeDelta::minutes(seed as i64 * 37);
                let scratch = fleet_plan(&rows, at, limit);
                let grouped = index.plan(at, limit);
                assert!(
                    !scratch.tests.is_empty(),
                    "seed {seed}: an empty plan tests nothing"
                );
                assert_eq!(grouped, scratch, "seed {seed}, at {at}, limit {limit}");
            }
        }
        // No evidence: no plan.
        assert_eq!(FleetIndex::build(&[]).plan(Utc::now(), 0).tests, Vec::new());
        assert_eq!(
            FleetIndex::build(&[]).plan(Utc::now(), 10).tests,
            Vec::new()
        );
    }

    /// Ties in score: pantographs whose evidence is another's (serials sorting before, between
    /// and after the others) score alike and are ordered by serial; every `limit` that cuts a
    /// tie serves `evidence::fleet_plan`'s first `limit`, whether ranked afresh or from a kept
    /// ranking.
    #[test]
    fn a_limit_that_cuts_through_ties_serves_the_plan_from_scratch() {
        let mut rows = random_rows(41, 8);
        let copies: Vec<EvidenceRow> = rows
            .iter()
            .filter(|r| r.serial == "160EC-0001" || r.serial == "160EC-0005")
            .flat_map(|r| {
                ["160EC-0000-a", "160EC-0001-b", "160EC-0009"].map(|prefix| EvidenceRow {
                    serial: format!("{prefix}-{}", r.serial),
                    ..r.clone()
                })
            })
            .collect();
        rows.extend(copies);
        let index = FleetIndex::build(&rows);
        for days in [30, 400, 900] {
            let at = Utc
                .with_ymd_and_hms(2025, 1, 1, 0, 0, 0)
                .single()
                .expect("date")
                + chrono::TimeDelta::days(days);
            let all = fleet_plan(&rows, at, usize::MAX);
            let ties = all
                .tests
                .windows(2)
                .filter(|w| {
                    w[0].test.buys == w[1].test.buys && w[0].test.info_bits == w[1].test.info_bits
                })
                .count();
            assert!(
                ties >= 4,
                "at {at}: {ties} ties in {} tests",
                all.tests.len()
            );
            let ranked = index.rank(at);
            for limit in 0..=all.tests.len() + 1 {
                let scratch = fleet_plan(&rows, at, limit);
                assert_eq!(index.plan(at, limit), scratch, "at {at}, limit {limit}");
                assert_eq!(index.served(&ranked, limit), scratch, "kept, limit {limit}");
            }
        }
    }
}

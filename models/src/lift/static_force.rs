//! The static contact force characteristic (issue 20): the strip force over the working height
//! range for quasi-static raising and lowering, with reaction-dependent dry friction at every joint.
//!
//! What a depot measures with a force gauge (EN 50206-1): the drive holds its set torque while the
//! pantograph is raised or lowered slowly against the gauge; the gauge reads the strip force.
//! Here, at each strip height H:
//! - the drive torque is the pantograph's drive characteristic, [`DriveLine`]: **assumed** the
//!   straight line in H through the two lift-test states of the geometry file (`[lift_test]`),
//!   the only drive torques the paper gives; a pantograph's real characteristic replaces it there;
//! - the strip force F solves T_static(α(H, F), F, motion) = T_drive(H), where T_static is
//!   [`statics::static_point`] — Kane's generalized gravity/spring force plus each revolute joint's
//!   dry torque N·R·μ opposing the impending motion, N the joint's reaction, which itself depends
//!   on the friction torques and on F (the fixed-point iteration of the statics). The outer
//!   equation in F is solved by the secant method (T_static is all but affine in F);
//! - **assumed quasi-static**: the speed is small enough that viscous terms (D·ω, J8's and J9's
//!   dampers) and inertia vanish; the J8 slide is at its frictionless static travel (its dry
//!   band of ±0.5 mm of travel changes H by as much, not F); J6 is locked in the plane (no work);
//! - the drive line's slope is the type's unless a gauge record named another spring rate
//!   (`spring_rate`, factor k: [`RateEstimate`], [`characteristic_rated`]; issue 39, point 5).
//!
//! The 95 % band is propagated from each joint's dry-μ interval (the fit that informed it), and
//! from k's, by evaluating F with that parameter at the interval's ends, all others at their
//! values, and adding the per-parameter changes (an interval sum, not a root-sum-square: the
//! store keeps no covariance between parameters and a lift's friction estimates are strongly
//! correlated, so the sum is the bound that holds for any correlation). A joint without an
//! interval adds nothing, nor the type's spring.

use super::dynamics::{DynamicsError, LiftModel};
use super::geometry::Geometry;
use super::statics::{StaticFriction, StaticsError, alpha_at_height, static_point};
use super::topology::{N_REV, RevJoint};

/// The drive torque over strip height: a straight line through two (H, T) points.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriveLine {
    pub h0_m: f64,
    pub t0_nm: f64,
    pub h1_m: f64,
    pub t1_nm: f64,
}

impl DriveLine {
    /// The line through the geometry file's two lift-test states (initial and final H, T).
    pub fn from_lift_test(g: &Geometry) -> Self {
        let (a, b) = (g.lift_test.initial, g.lift_test.final_);
        Self {
            h0_m: a.h_m,
            t0_nm: a.t_nm,
            h1_m: b.h_m,
            t1_nm: b.t_nm,
        }
    }

    /// This line with its slope × `factor` about its first point (h0, t0): the torque there
    /// kept, its rate of change with height scaled — a spring whose rate differs from the
    /// type's (the `spring_rate` a gauge record names; **assumed** the drive's torque at the lift
    /// test's initial state is what the depot sets, so the pivot).
    pub fn with_rate_factor(&self, factor: f64) -> DriveLine {
        DriveLine {
            t1_nm: self.t0_nm + factor * (self.t1_nm - self.t0_nm),
            ..*self
        }
    }

    pub fn torque_nm(&self, strip_height_m: f64) -> f64 {
        let dh = self.h1_m - self.h0_m;
        if dh.abs() < 1e-12 {
            return 0.5 * (self.t0_nm + self.t1_nm);
        }
        self.t0_nm + (self.t1_nm - self.t0_nm) * (strip_height_m - self.h0_m) / dh
    }
}

/// One joint's dry friction coefficient with its 95 % interval; `None` interval: no test has
/// measured it (the value is then the type's baseline and adds nothing to the band).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MuEstimate {
    pub value: f64,
    pub ci95: Option<[f64; 2]>,
}

/// The drive's spring-rate factor k a prediction uses ([`DriveLine::with_rate_factor`]) with its
/// 95 % interval: [`RateEstimate::TYPE`] (1, no interval) for the type's spring; a gauge record's
/// named `spring_rate` otherwise (`gauge::report::spring_rate_of`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RateEstimate {
    pub factor: f64,
    pub ci95: Option<[f64; 2]>,
}

impl RateEstimate {
    /// The type's spring: k = 1, nothing added to the band.
    pub const TYPE: RateEstimate = RateEstimate {
        factor: 1.0,
        ci95: None,
    };

    fn is_valid(&self) -> bool {
        let ok_ci = match self.ci95 {
            None => true,
            Some([lo, hi]) => lo.is_finite() && hi.is_finite() && 0.0 < lo && lo <= hi,
        };
        self.factor.is_finite() && self.factor > 0.0 && ok_ci
    }
}

/// The predicted characteristic. Forces in N on the strip, positive down (the gauge's reading).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct StaticForceCurve {
    pub heights_m: Vec<f64>,
    pub drive_torque_nm: Vec<f64>,
    /// Without friction (the balance of drive, gravity and springs).
    pub frictionless_n: Vec<f64>,
    /// Raising slowly: friction opposes the drive, the strip force is lower.
    pub raise_n: Vec<f64>,
    pub raise_lo_n: Vec<f64>,
    pub raise_hi_n: Vec<f64>,
    /// Lowering slowly: friction helps hold the pantograph up, the strip force is higher.
    pub lower_n: Vec<f64>,
    pub lower_lo_n: Vec<f64>,
    pub lower_hi_n: Vec<f64>,
}

/// Why a characteristic could not be computed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StaticForceError {
    #[error(transparent)]
    Statics(#[from] StaticsError),
    #[error("invalid input: {0}")]
    Invalid(String),
    #[error("strip force did not converge at H = {strip_height_m} m")]
    NotConverged { strip_height_m: f64 },
}

/// Equally spaced heights from `range_m[0]` to `range_m[1]` by about `step_m` (both ends kept).
pub fn height_grid(range_m: [f64; 2], step_m: f64) -> Result<Vec<f64>, StaticForceError> {
    let [a, b] = range_m;
    if !(a.is_finite() && b.is_finite() && step_m.is_finite() && step_m > 0.0 && b > a) {
        return Err(StaticForceError::Invalid(format!(
            "height range {a}..{b} m by {step_m} m"
        )));
    }
    let n = ((b - a) / step_m).round().clamp(1.0, 1000.0) as usize;
    Ok((0..=n).map(|k| a + (b - a) * k as f64 / n as f64).collect())
}

/// The strip force at which `drive_torque_nm` holds (or just moves) the pantograph with its strip
/// at `strip_height_m`.
pub fn strip_force_n(
    model: &LiftModel,
    alpha_range_rad: (f64, f64),
    strip_height_m: f64,
    drive_torque_nm: f64,
    friction: StaticFriction,
) -> Result<f64, StaticForceError> {
    let range = alpha_range_rad;
    let residual = |f_n: f64| -> Result<f64, StaticForceError> {
        let a = alpha_at_height(model, strip_height_m, f_n, range)?;
        Ok(static_point(model, a, f_n, friction)?.drive_torque_nm - drive_torque_nm)
    };
    let (mut f0, mut f1) = (0.0, 100.0);
    let (mut r0, mut r1) = (residual(f0)?, residual(f1)?);
    for _ in 0..40 {
        if r1 == 0.0 {
            return Ok(f1);
        }
        let slope = (r1 - r0) / (f1 - f0);
        if !slope.is_finite() || slope == 0.0 {
            break;
        }
        let f2 = f1 - r1 / slope;
        if !f2.is_finite() {
            break;
        }
        (f0, r0) = (f1, r1);
        f1 = f2;
        r1 = residual(f1)?;
        if (f1 - f0).abs() < 1e-9 * (1.0 + f1.abs()) {
            return Ok(f1);
        }
    }
    Err(StaticForceError::NotConverged { strip_height_m })
}

fn with_mu(base: &LiftModel, mu: &[f64; N_REV]) -> LiftModel {
    let mut m = base.clone();
    m.friction.dry_mu = *mu;
    m
}

/// The characteristic of the pantograph of geometry `g` (its links, masses, springs) with the
/// dry friction `mu` (one per revolute joint, [`RevJoint`] order), at `heights_m`, driven by `drive`.
pub fn characteristic(
    g: &Geometry,
    mu: &[MuEstimate; N_REV],
    drive: &DriveLine,
    heights_m: &[f64],
) -> Result<StaticForceCurve, StaticForceError> {
    characteristic_rated(g, mu, drive, &RateEstimate::TYPE, heights_m)
}

/// [`characteristic`] with `drive`'s slope × the spring-rate factor `rate`
/// ([`DriveLine::with_rate_factor`]); k's interval adds to the band as a μ's does (F at each end
/// of it, the others at their values; module doc).
pub fn characteristic_rated(
    g: &Geometry,
    mu: &[MuEstimate; N_REV],
    drive: &DriveLine,
    rate: &RateEstimate,
    heights_m: &[f64],
) -> Result<StaticForceCurve, StaticForceError> {
    if !rate.is_valid() {
        return Err(StaticForceError::Invalid(format!(
            "spring-rate factor {rate:?}"
        )));
    }
    for j in RevJoint::ALL {
        let e = mu[j.index()];
        let ok_ci = match e.ci95 {
            None => true,
            Some([lo, hi]) => lo.is_finite() && hi.is_finite() && lo <= hi,
        };
        if !(e.value.is_finite() && e.value >= 0.0 && ok_ci) {
            return Err(StaticForceError::Invalid(format!(
                "dry friction of {}: {:?}",
                j.name(),
                e
            )));
        }
    }
    if heights_m.iter().any(|h| !h.is_finite()) {
        return Err(StaticForceError::Invalid("a height is not finite".into()));
    }
    let base = LiftModel::new(g);
    let base = &base;
    let ar = (g.alpha_min_rad, g.alpha_max_rad);
    let values: [f64; N_REV] = std::array::from_fn(|i| mu[i].value);
    let model = with_mu(base, &values);
    let frictionless_model = with_mu(base, &[0.0; N_REV]);
    let rated = drive.with_rate_factor(rate.factor);
    // The models with one μ at an end of its interval (negative ends clipped to 0: μ ≥ 0), then
    // the drive at each end of k's: pairs of (model, drive).
    let mut ends: Vec<(LiftModel, DriveLine)> = Vec::new();
    for (i, e) in mu.iter().enumerate() {
        if let Some([lo, hi]) = e.ci95 {
            for v in [lo.max(0.0), hi.max(0.0)] {
                let mut m = values;
                m[i] = v;
                ends.push((with_mu(base, &m), rated));
            }
        }
    }
    if let Some([lo, hi]) = rate.ci95 {
        for k in [lo, hi] {
            ends.push((model.clone(), drive.with_rate_factor(k)));
        }
    }
    let mut c = StaticForceCurve {
        heights_m: heights_m.to_vec(),
        drive_torque_nm: Vec::with_capacity(heights_m.len()),
        frictionless_n: Vec::new(),
        raise_n: Vec::new(),
        raise_lo_n: Vec::new(),
        raise_hi_n: Vec::new(),
        lower_n: Vec::new(),
        lower_lo_n: Vec::new(),
        lower_hi_n: Vec::new(),
    };
    for &h in heights_m {
        let t = rated.torque_nm(h);
        c.drive_torque_nm.push(t);
        c.frictionless_n.push(strip_force_n(
            &frictionless_model,
            ar,
            h,
            t,
            StaticFriction::None,
        )?);
        for (dir, (v, lo, hi)) in [
            (
                StaticFriction::Raising,
                (&mut c.raise_n, &mut c.raise_lo_n, &mut c.raise_hi_n),
            ),
            (
                StaticFriction::Lowering,
                (&mut c.lower_n, &mut c.lower_lo_n, &mut c.lower_hi_n),
            ),
        ] {
            let f = strip_force_n(&model, ar, h, t, dir)?;
            let (mut down, mut up) = (0.0, 0.0);
            for pair in ends.chunks(2) {
                let d: Vec<f64> = pair
                    .iter()
                    .map(|(m, dr)| strip_force_n(m, ar, h, dr.torque_nm(h), dir).map(|x| x - f))
                    .collect::<Result<_, _>>()?;
                let (dmin, dmax) = d
                    .iter()
                    .fold((0.0f64, 0.0f64), |(a, b), &x| (a.min(x), b.max(x)));
                down += dmin;
                up += dmax;
            }
            v.push(f);
            lo.push(f + down);
            hi.push(f + up);
        }
    }
    Ok(c)
}

/// Limits on the characteristic (the type's data file, `[static_force]`): the nominal force line
/// over height, the tolerance either side, the largest raise/lower difference.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForceLimits {
    /// Nominal force at two heights, (H m, F N); linear in between and beyond.
    pub nominal_n: [[f64; 2]; 2],
    pub tolerance_n: f64,
    pub max_raise_lower_difference_n: f64,
}

impl ForceLimits {
    pub fn nominal_at_n(&self, strip_height_m: f64) -> f64 {
        let [[h0, f0], [h1, f1]] = self.nominal_n;
        if (h1 - h0).abs() < 1e-12 {
            return 0.5 * (f0 + f1);
        }
        f0 + (f1 - f0) * (strip_height_m - h0) / (h1 - h0)
    }
}

impl From<&crate::data::StaticForceData> for ForceLimits {
    fn from(d: &crate::data::StaticForceData) -> Self {
        Self {
            nominal_n: d.nominal_force_points,
            tolerance_n: d.tolerance_n,
            max_raise_lower_difference_n: d.max_raise_lower_difference_n,
        }
    }
}

/// A pantograph's predicted characteristic over its type's working range and where it leaves the
/// type's limits.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Prediction {
    pub curve: StaticForceCurve,
    pub findings: Vec<LimitFinding>,
}

/// [`characteristic`] over `data`'s working range (the type's `[static_force]`), driven by the
/// lift-test drive line of `g`, with the findings against `data`'s limits.
pub fn predict(
    g: &Geometry,
    data: &crate::data::StaticForceData,
    mu: &[MuEstimate; N_REV],
) -> Result<Prediction, StaticForceError> {
    predict_rated(g, data, mu, &RateEstimate::TYPE)
}

/// [`predict`] with the drive line's slope × `rate` (a gauge record's named `spring_rate`; its
/// interval in the band).
pub fn predict_rated(
    g: &Geometry,
    data: &crate::data::StaticForceData,
    mu: &[MuEstimate; N_REV],
    rate: &RateEstimate,
) -> Result<Prediction, StaticForceError> {
    let heights = height_grid(data.working_height_m, data.height_step_m)?;
    let curve = characteristic_rated(g, mu, &DriveLine::from_lift_test(g), rate, &heights)?;
    let findings = curve.findings(&ForceLimits::from(data));
    Ok(Prediction { curve, findings })
}

/// Where a predicted band leaves the limits.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct LimitFinding {
    pub height_m: f64,
    /// `raise_below_min`, `lower_above_max`, `raise_above_max`, `lower_below_min`, `difference_above_max`.
    pub what: &'static str,
    /// The band's edge that leaves, and the limit it passes, N.
    pub value_n: f64,
    pub limit_n: f64,
}

impl StaticForceCurve {
    /// Every height where a band leaves the limits: a raise or lower band outside nominal ±
    /// tolerance, or the raise/lower difference (lower's upper edge less raise's lower edge) above
    /// the largest allowed.
    pub fn findings(&self, lim: &ForceLimits) -> Vec<LimitFinding> {
        let mut out = Vec::new();
        for (i, &h) in self.heights_m.iter().enumerate() {
            let nom = lim.nominal_at_n(h);
            let (lo_lim, hi_lim) = (nom - lim.tolerance_n, nom + lim.tolerance_n);
            let checks = [
                ("raise_below_min", self.raise_lo_n[i], lo_lim, true),
                ("lower_below_min", self.lower_lo_n[i], lo_lim, true),
                ("raise_above_max", self.raise_hi_n[i], hi_lim, false),
                ("lower_above_max", self.lower_hi_n[i], hi_lim, false),
                (
                    "difference_above_max",
                    self.lower_hi_n[i] - self.raise_lo_n[i],
                    lim.max_raise_lower_difference_n,
                    false,
                ),
            ];
            for (what, v, limit, below) in checks {
                if (below && v < limit) || (!below && v > limit) {
                    out.push(LimitFinding {
                        height_m: h,
                        what,
                        value_n: v,
                        limit_n: limit,
                    });
                }
            }
        }
        out
    }
}

impl From<DynamicsError> for StaticForceError {
    fn from(e: DynamicsError) -> Self {
        StaticForceError::Statics(e.into())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lift::geometry::builtin_160ec;
    use crate::lift::statics::static_h_m;
    use crate::lift::topology::BodyId;

    fn baseline_mu(g: &Geometry) -> [MuEstimate; N_REV] {
        std::array::from_fn(|i| MuEstimate {
            value: g.revolute[i].dry_mu,
            ci95: None,
        })
    }

    /// The paper's heights, taken from the geometry file's lift-test states.
    fn paper_heights(g: &Geometry) -> Vec<f64> {
        vec![
            g.lift_test.initial.h_m,
            1.2,
            1.5,
            g.lift_test.final_.h_m,
            0.9,
        ]
    }

    /// Independent route, virtual work with h held at its static travel: the potential of
    /// gravity V(α) = −Σ m g·r_com and the strip height H(α), each by central differences of the
    /// assembled positions (not Kane's terms): F = (T + (−dV/dα)) / (dH/dα). The head's travel
    /// for the load F is re-solved (two passes: h moves by F/k).
    fn virtual_work_force_n(g: &Geometry, h_strip_m: f64, t_nm: f64) -> (f64, f64, f64, f64) {
        let m = LiftModel::new(g);
        let range = (g.alpha_min_rad, g.alpha_max_rad);
        let mut f = 90.0;
        let mut out = (0.0, 0.0, 0.0, 0.0);
        for _ in 0..4 {
            let a = alpha_at_height(&m, h_strip_m, f, range).unwrap();
            let h = static_h_m(&m, &m.linkage.pose(a).unwrap(), f);
            let potential = |alpha: f64| -> (f64, f64) {
                let pose = m.linkage.pose(alpha).unwrap();
                let head = m.linkage.head(&pose, h, 0.0, 0.0);
                let mut v = 0.0;
                for b in BodyId::ALL {
                    let r = match b {
                        BodyId::Head => head.com,
                        _ => pose.body(b).com.p,
                    };
                    v -= m.mass_kg[b.index()] * m.gravity.dot(r);
                }
                (v, head.strip.y)
            };
            let d = 1e-6;
            let (vp, hp) = potential(a + d);
            let (vm, hm) = potential(a - d);
            let dv = (vp - vm) / (2.0 * d);
            let dh = (hp - hm) / (2.0 * d);
            f = (t_nm - dv) / dh;
            out = (f, a, h, dh);
        }
        out
    }

    /// Relative angle of joint j's second body to its first (ground: 0), rad.
    fn rel_angle(m: &LiftModel, alpha: f64, j: RevJoint) -> f64 {
        let pose = m.linkage.pose(alpha).unwrap();
        let (a, b) = j.bodies();
        let th = |b: BodyId| pose.body(b).theta_rad();
        let d = th(b) - a.map(th).unwrap_or(0.0);
        d.sin().atan2(d.cos())
    }

    /// The raise/lower gap by virtual work: each joint's dry torques at the raising and lowering
    /// states (from the statics' reactions) times |dθ_rel/dα| (central differences of the body
    /// angles), over dH/dα.
    fn gap_by_virtual_work_n(
        g: &Geometry,
        mu: &[f64; N_REV],
        h_strip_m: f64,
        t_nm: f64,
    ) -> [f64; N_REV] {
        let mut m = LiftModel::new(g);
        m.friction.dry_mu = *mu;
        let (f0, a, _, dh_da) = virtual_work_force_n(g, h_strip_m, t_nm);
        let up = static_point(&m, a, f0, StaticFriction::Raising).unwrap();
        let down = static_point(&m, a, f0, StaticFriction::Lowering).unwrap();
        let d = 1e-6;
        std::array::from_fn(|i| {
            let j = RevJoint::ALL[i];
            let dth = (rel_angle(&m, a + d, j) - rel_angle(&m, a - d, j)) / (2.0 * d);
            (up.dry_torque_nm[i].abs() + down.dry_torque_nm[i].abs()) * dth.abs() / dh_da
        })
    }

    #[test]
    fn baseline_characteristic_matches_virtual_work_and_the_papers_states() {
        let g = builtin_160ec();
        let drive = DriveLine::from_lift_test(g);
        let hs = paper_heights(g);
        let c = characteristic(g, &baseline_mu(g), &drive, &hs).unwrap();
        let mu: [f64; N_REV] = std::array::from_fn(|i| g.revolute[i].dry_mu);
        for (i, &h) in hs.iter().enumerate() {
            let (f_vw, ..) = virtual_work_force_n(g, h, c.drive_torque_nm[i]);
            let gap_vw: f64 = gap_by_virtual_work_n(g, &mu, h, c.drive_torque_nm[i])
                .iter()
                .sum();
            let gap = c.lower_n[i] - c.raise_n[i];
            eprintln!(
                "H {h:.3} m: T {:.1} N·m  F0 {:.3} N (virtual work {f_vw:.3})  raise {:.3}  lower {:.3}  gap {gap:.3} N (virtual work {gap_vw:.3})",
                c.drive_torque_nm[i], c.frictionless_n[i], c.raise_n[i], c.lower_n[i]
            );
            assert!((c.frictionless_n[i] - f_vw).abs() < 0.5, "H {h}");
            assert!(
                (gap - gap_vw).abs() < 0.5,
                "gap at H {h}: {gap} vs {gap_vw}"
            );
            // Friction splits the curves around the frictionless one, raising below.
            assert!(c.raise_n[i] < c.frictionless_n[i] && c.frictionless_n[i] < c.lower_n[i]);
            // The band is empty without intervals.
            assert_eq!(c.raise_lo_n[i], c.raise_n[i]);
            assert_eq!(c.lower_hi_n[i], c.lower_n[i]);
        }
        // The lift-test states: the frictionless characteristic passes through their strip loads.
        let (s0, s1) = (g.lift_test.initial, g.lift_test.final_);
        assert!(
            (c.frictionless_n[0] - s0.strip_load_n()).abs() < 0.5,
            "{}",
            c.frictionless_n[0]
        );
        assert!(
            (c.frictionless_n[3] - s1.strip_load_n()).abs() < 0.5,
            "{}",
            c.frictionless_n[3]
        );
    }

    #[test]
    fn doubling_j3_friction_widens_the_gap_by_what_the_statics_predict() {
        let g = builtin_160ec();
        let drive = DriveLine::from_lift_test(g);
        let hs = paper_heights(g);
        let base = baseline_mu(g);
        let mut doubled = base;
        let j3 = RevJoint::J3.index();
        doubled[j3].value *= 2.0;
        let c0 = characteristic(g, &base, &drive, &hs).unwrap();
        let c2 = characteristic(g, &doubled, &drive, &hs).unwrap();
        let mu: [f64; N_REV] = std::array::from_fn(|i| g.revolute[i].dry_mu);
        for (i, &h) in hs.iter().enumerate() {
            let widen = (c2.lower_n[i] - c2.raise_n[i]) - (c0.lower_n[i] - c0.raise_n[i]);
            // J3's share of the baseline gap by virtual work: doubling μ adds it once more.
            let predicted = gap_by_virtual_work_n(g, &mu, h, c0.drive_torque_nm[i])[j3];
            eprintln!(
                "H {h:.3} m: J3 x2 widens the gap by {widen:.3} N (statics predict {predicted:.3} N)"
            );
            assert!(predicted > 1.0, "J3 matters in the statics: {predicted}");
            assert!(
                (widen - predicted).abs() < 0.05 * predicted + 0.1,
                "H {h}: {widen} vs {predicted}"
            );
        }
    }

    #[test]
    fn the_band_contains_the_curve_and_grows_with_the_interval() {
        let g = builtin_160ec();
        let drive = DriveLine::from_lift_test(g);
        let hs = [1.04, 1.6];
        let mut mu = baseline_mu(g);
        let j3 = RevJoint::J3.index();
        let v = mu[j3].value;
        mu[j3].ci95 = Some([0.8 * v, 1.2 * v]);
        let narrow = characteristic(g, &mu, &drive, &hs).unwrap();
        mu[j3].ci95 = Some([0.5 * v, 1.5 * v]);
        let wide = characteristic(g, &mu, &drive, &hs).unwrap();
        for i in 0..hs.len() {
            assert!(
                narrow.raise_lo_n[i] < narrow.raise_n[i]
                    && narrow.raise_n[i] < narrow.raise_hi_n[i]
            );
            assert!(
                narrow.lower_lo_n[i] < narrow.lower_n[i]
                    && narrow.lower_n[i] < narrow.lower_hi_n[i]
            );
            let w_n = narrow.lower_hi_n[i] - narrow.lower_lo_n[i];
            let w_w = wide.lower_hi_n[i] - wide.lower_lo_n[i];
            // Affine in μ to first order: 2.5 times the interval, about 2.5 times the band.
            assert!((w_w / w_n - 2.5).abs() < 0.1, "{w_n} {w_w}");
        }
    }

    #[test]
    fn findings_name_a_band_outside_the_limits() {
        let lim = ForceLimits {
            nominal_n: [[1.0, 100.0], [2.0, 90.0]],
            tolerance_n: 10.0,
            max_raise_lower_difference_n: 15.0,
        };
        assert_eq!(lim.nominal_at_n(1.5), 95.0);
        let c = StaticForceCurve {
            heights_m: vec![1.0, 2.0],
            drive_torque_nm: vec![0.0; 2],
            frictionless_n: vec![100.0, 90.0],
            raise_n: vec![95.0, 80.0],
            raise_lo_n: vec![94.0, 79.0],
            raise_hi_n: vec![96.0, 81.0],
            lower_n: vec![105.0, 95.0],
            lower_lo_n: vec![104.0, 94.0],
            lower_hi_n: vec![106.0, 96.0],
        };
        let f = c.findings(&lim);
        let whats: Vec<_> = f.iter().map(|x| (x.height_m, x.what)).collect();
        assert_eq!(
            whats,
            vec![(2.0, "raise_below_min"), (2.0, "difference_above_max")]
        );
    }

    /// The built-in type's limits: the Table 4 baseline inside them, J3's dry friction ×3 out.
    #[test]
    fn the_builtin_limits_pass_the_baseline_and_catch_a_worn_j3() {
        let g = builtin_160ec();
        let data = crate::data::builtin_160ec().static_force.as_ref().unwrap();
        let base = baseline_mu(g);
        let p = predict(g, data, &base).unwrap();
        assert_eq!(p.curve.heights_m.len(), 14);
        assert!(p.findings.is_empty(), "{:?}", p.findings);
        let mut mild = base;
        mild[RevJoint::J3.index()].value *= 1.8;
        let p = predict(g, data, &mild).unwrap();
        assert!(p.findings.is_empty(), "J3 x1.8: {:?}", p.findings);
        let mut worn = base;
        worn[RevJoint::J3.index()].value *= 3.0;
        let p = predict(g, data, &worn).unwrap();
        eprintln!("J3 x3: {:?}", p.findings.first());
        assert!(
            p.findings.iter().any(|f| f.what == "difference_above_max"),
            "{:?}",
            p.findings
        );
    }

    #[test]
    fn bad_input_is_an_error_not_a_panic() {
        let g = builtin_160ec();
        let drive = DriveLine::from_lift_test(g);
        let mut mu = baseline_mu(g);
        mu[0].value = f64::NAN;
        assert!(characteristic(g, &mu, &drive, &[1.0]).is_err());
        let mu = baseline_mu(g);
        assert!(characteristic(g, &mu, &drive, &[f64::INFINITY]).is_err());
        // Far above the linkage's reach: no equilibrium, an error.
        assert!(characteristic(g, &mu, &drive, &[9.0]).is_err());
        assert!(height_grid([1.0, 0.5], 0.1).is_err());
        assert_eq!(height_grid([0.8, 1.84], 0.08).unwrap().len(), 14);
    }
}

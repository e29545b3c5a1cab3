//! Closed-chain kinematics of the two articulated quadrangles: positions in closed form
//! (circle intersections), first and second derivatives in α from the loop Jacobians.
//!
//! Every linkage body's configuration depends on the lower-arm angle α alone; the head adds
//! its travel h along the J8 slide. Derivatives are with respect to α (velocity = ′·α̇,
//! acceleration = ′·α̈ + ″·α̇²), so the equations of motion need no constraint stabilisation.

use super::geometry::{Geometry, Points};
use super::topology::{BodyId, N_REV, RevJoint};
use super::vec2::{Rot, V2};

/// The linkage cannot be assembled at this α (a loop's circles do not meet).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("linkage does not assemble at alpha = {alpha_rad} rad: {loop_name} loop cannot close")]
pub struct AssemblyError {
    pub alpha_rad: f64,
    pub loop_name: &'static str,
}

/// A point of the mechanism: position and its first two derivatives in α.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PointKin {
    pub p: V2,
    pub d1: V2,
    pub d2: V2,
}

/// One body's configuration: rotation, angle derivatives in α, and an anchor point (a joint
/// whose motion is known) from which any of its points follow.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodyKin {
    pub rot: Rot,
    /// dθ/dα and d²θ/dα².
    pub w1: f64,
    pub w2: f64,
    anchor: PointKin,
    anchor_local: V2,
    /// Centre of mass.
    pub com: PointKin,
}

impl BodyKin {
    pub(crate) fn new(
        rot: Rot,
        w1: f64,
        w2: f64,
        anchor: PointKin,
        anchor_local: V2,
        com_local: V2,
    ) -> Self {
        let mut b = Self {
            rot,
            w1,
            w2,
            anchor,
            anchor_local,
            com: PointKin::default(),
        };
        b.com = b.at(com_local);
        b
    }

    /// A point given in the body frame: P = A + R·(q − q_A), P′ = A′ + θ′ k×(P − A),
    /// P″ = A″ + θ″ k×(P − A) − θ′²(P − A).
    #[inline]
    pub fn at(&self, local: V2) -> PointKin {
        let r = self.rot.apply(local - self.anchor_local);
        PointKin {
            p: self.anchor.p + r,
            d1: self.anchor.d1 + self.w1 * r.perp(),
            d2: self.anchor.d2 + self.w2 * r.perp() - (self.w1 * self.w1) * r,
        }
    }

    /// Body angle θ in (−π, π].
    pub fn theta_rad(&self) -> f64 {
        self.rot.angle()
    }
}

/// The link geometry in the form the kinematics uses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Linkage {
    pub ground_j1: V2,
    pub ground_j2: V2,
    pub pts: Points,
    /// Centres of mass in body frames, [`BodyId`] order.
    pub com_local: [V2; 7],
    pub lower_sign: f64,
    pub upper_sign: f64,
    /// Head slide direction in the suspension frame and the strip offset at h = 0.
    pub slide_axis: V2,
    pub strip_offset_m: f64,
    // Loop link vectors and lengths, precomputed.
    d_u: V2,
    d_c: V2,
    d_s: V2,
    d_b: V2,
    r_u: f64,
    r_c: f64,
    r_s: f64,
    r_b: f64,
}

/// The linkage at one α: every body and joint with derivatives in α.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkagePose {
    pub alpha_rad: f64,
    /// Linkage bodies in [`BodyId`] order, the head excluded (it needs h: [`HeadKin`]).
    pub bodies: [BodyKin; 6],
    /// Revolute joint centres in [`RevJoint`] order.
    pub joints: [PointKin; N_REV],
    /// Base point of the J8 slide line on the suspension.
    pub j8: PointKin,
}

impl LinkagePose {
    pub fn body(&self, b: BodyId) -> &BodyKin {
        &self.bodies[b.index()]
    }
    pub fn joint(&self, j: RevJoint) -> &PointKin {
        &self.joints[j.index()]
    }
    /// Relative-rate coefficient of a revolute joint: ω_rel = r·α̇ (0 for J6, locked).
    #[inline]
    pub fn rel_rate(&self, j: RevJoint) -> f64 {
        let (a, b) = j.bodies();
        self.bodies[b.index()].w1 - a.map_or(0.0, |a| self.bodies[a.index()].w1)
    }
}

/// The head at (α, h, α̇, ḣ): its points and the partial velocities of its centre of mass.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeadKin {
    /// Slide direction in the world (positive h).
    pub u: V2,
    pub strip: V2,
    /// ∂strip/∂α at constant h (∂strip/∂h = u).
    pub strip_d_alpha: V2,
    pub com: V2,
    /// ∂com/∂α at constant h (∂com/∂h = u).
    pub com_d_alpha: V2,
    /// Centre-of-mass acceleration at α̈ = ḧ = 0 (velocity-product terms).
    pub com_acc0: V2,
}

/// Intersection of circle (a, r1) and circle (b, r2) on the side `sign` (+1: left of a → b).
#[inline]
fn circle_intersection(a: V2, r1: f64, b: V2, r2: f64, sign: f64) -> Option<V2> {
    let d = b - a;
    let dd = d.norm();
    if dd == 0.0 {
        return None;
    }
    let e = d * (1.0 / dd);
    let x = (r1 * r1 - r2 * r2 + dd * dd) / (2.0 * dd);
    let y2 = r1 * r1 - x * x;
    if y2.is_nan() || y2 < 0.0 {
        return None;
    }
    Some(a + e * x + e.perp() * (sign * y2.sqrt()))
}

/// Solve x·a + y·b = rhs (2×2, columns a and b).
#[inline]
fn solve2(a: V2, b: V2, rhs: V2) -> (f64, f64) {
    let det = a.cross(b);
    (rhs.cross(b) / det, a.cross(rhs) / det)
}

impl Linkage {
    pub fn new(g: &Geometry) -> Self {
        let p = g.points;
        let d_u = p.upper_arm_j2p - p.upper_arm_j3;
        let d_c = p.coupling_rod_j2p - p.coupling_rod_j2;
        let d_s = p.shaft_j7 - p.shaft_j5;
        let d_b = p.balance_rod_j7 - p.balance_rod_j4;
        let mut com_local = [V2::ZERO; 7];
        for b in BodyId::ALL {
            com_local[b.index()] = g.body(b).com_m;
        }
        Self {
            ground_j1: g.ground_j1_m,
            ground_j2: g.ground_j2_m,
            pts: p,
            com_local,
            lower_sign: g.lower_loop_sign,
            upper_sign: g.upper_loop_sign,
            slide_axis: g.slide.axis,
            strip_offset_m: g.slide.strip_offset_m,
            d_u,
            d_c,
            d_s,
            d_b,
            r_u: d_u.norm(),
            r_c: d_c.norm(),
            r_s: d_s.norm(),
            r_b: d_b.norm(),
        }
    }

    /// Assemble the linkage at α and differentiate it twice.
    pub fn pose(&self, alpha_rad: f64) -> Result<LinkagePose, AssemblyError> {
        let p = &self.pts;
        let cl = &self.com_local;
        let fixed = |x: V2| PointKin {
            p: x,
            ..Default::default()
        };
        let lower = BodyKin::new(
            Rot::from_angle(alpha_rad),
            1.0,
            0.0,
            fixed(self.ground_j1),
            p.lower_arm_j1,
            cl[BodyId::LowerArm.index()],
        );
        let j3 = lower.at(p.lower_arm_j3);
        let j4 = lower.at(p.lower_arm_j4);

        // Lower loop: J2' on the upper arm's elbow lever (from J3) and on the coupling rod
        // (from J2 on the frame).
        let x = circle_intersection(j3.p, self.r_u, self.ground_j2, self.r_c, self.lower_sign)
            .ok_or(AssemblyError {
                alpha_rad,
                loop_name: "lower",
            })?;
        let rot_u = Rot::between(self.d_u, x - j3.p);
        let rot_c = Rot::between(self.d_c, x - self.ground_j2);
        let (w_u, w_c) = (rot_u.apply(self.d_u), rot_c.apply(self.d_c));
        // J3′ + θu′ k×w_u = θc′ k×w_c, and the same matrix for the second derivatives.
        let (a, b) = (w_u.perp(), -w_c.perp());
        let (u1, c1) = solve2(a, b, -j3.d1);
        let (u2, c2) = solve2(a, b, -j3.d2 + (u1 * u1) * w_u - (c1 * c1) * w_c);
        let upper = BodyKin::new(
            rot_u,
            u1,
            u2,
            j3,
            p.upper_arm_j3,
            cl[BodyId::UpperArm.index()],
        );
        let coupling = BodyKin::new(
            rot_c,
            c1,
            c2,
            fixed(self.ground_j2),
            p.coupling_rod_j2,
            cl[BodyId::CouplingRod.index()],
        );
        let j2p = upper.at(p.upper_arm_j2p);
        let j5 = upper.at(p.upper_arm_j5);

        // Upper loop: J7 on the shaft crank (from J5) and on the balance rod (from J4).
        let x = circle_intersection(j5.p, self.r_s, j4.p, self.r_b, self.upper_sign).ok_or(
            AssemblyError {
                alpha_rad,
                loop_name: "upper",
            },
        )?;
        let rot_s = Rot::between(self.d_s, x - j5.p);
        let rot_b = Rot::between(self.d_b, x - j4.p);
        let (w_s, w_b) = (rot_s.apply(self.d_s), rot_b.apply(self.d_b));
        // J4′ + θb′ k×w_b = J5′ + θs′ k×w_s.
        let (a, b) = (w_b.perp(), -w_s.perp());
        let (b1, s1) = solve2(a, b, j5.d1 - j4.d1);
        let (b2, s2) = solve2(a, b, j5.d2 - j4.d2 + (b1 * b1) * w_b - (s1 * s1) * w_s);
        let balance = BodyKin::new(
            rot_b,
            b1,
            b2,
            j4,
            p.balance_rod_j4,
            cl[BodyId::BalanceRod.index()],
        );
        let shaft = BodyKin::new(rot_s, s1, s2, j5, p.shaft_j5, cl[BodyId::Shaft.index()]);
        let j7 = shaft.at(p.shaft_j7);
        let j6 = shaft.at(p.shaft_j6);
        // J6 locked in the plane: the suspension turns with the shaft, frames aligned [assumed].
        let suspension = BodyKin::new(
            rot_s,
            s1,
            s2,
            j6,
            p.suspension_j6,
            cl[BodyId::Suspension.index()],
        );
        let j8 = suspension.at(p.suspension_j8);
        Ok(LinkagePose {
            alpha_rad,
            bodies: [lower, coupling, upper, balance, shaft, suspension],
            joints: [
                fixed(self.ground_j1),
                fixed(self.ground_j2),
                j2p,
                j3,
                j4,
                j5,
                j6,
                j7,
            ],
            j8,
        })
    }

    /// The head at travel `h_m` with rates `alpha_dot`, `h_dot`.
    #[inline]
    pub fn head(&self, pose: &LinkagePose, h_m: f64, alpha_dot: f64, h_dot: f64) -> HeadKin {
        let s = pose.body(BodyId::Suspension);
        let u = s.rot.apply(self.slide_axis);
        let w_s = u * (self.strip_offset_m + h_m);
        let w_c = w_s
            + s.rot
                .apply(self.com_local[BodyId::Head.index()] - self.pts.head_strip);
        let j8 = &pose.j8;
        let ad2 = alpha_dot * alpha_dot;
        HeadKin {
            u,
            strip: j8.p + w_s,
            strip_d_alpha: j8.d1 + s.w1 * w_s.perp(),
            com: j8.p + w_c,
            com_d_alpha: j8.d1 + s.w1 * w_c.perp(),
            com_acc0: (j8.d2 + s.w2 * w_c.perp() - (s.w1 * s.w1) * w_c) * ad2
                + (2.0 * s.w1 * alpha_dot * h_dot) * u.perp(),
        }
    }

    /// Contact-strip height H (y of the strip) at (α, h).
    pub fn strip_height_m(&self, alpha_rad: f64, h_m: f64) -> Result<f64, AssemblyError> {
        let pose = self.pose(alpha_rad)?;
        Ok(self.head(&pose, h_m, 0.0, 0.0).strip.y)
    }

    /// Loop-closure error of a pose: the largest distance between a joint placed from one body
    /// and from the other (J2′ from the upper arm and the coupling rod, J7 from the shaft and
    /// the balance rod, J5 from the upper arm and the shaft), m.
    pub fn closure_error_m(&self, pose: &LinkagePose) -> f64 {
        let p = &self.pts;
        let b = |id: BodyId| pose.body(id);
        let pairs = [
            (
                b(BodyId::UpperArm).at(p.upper_arm_j2p).p,
                b(BodyId::CouplingRod).at(p.coupling_rod_j2p).p,
            ),
            (
                b(BodyId::Shaft).at(p.shaft_j7).p,
                b(BodyId::BalanceRod).at(p.balance_rod_j7).p,
            ),
            (
                b(BodyId::UpperArm).at(p.upper_arm_j5).p,
                b(BodyId::Shaft).at(p.shaft_j5).p,
            ),
            (
                b(BodyId::LowerArm).at(p.lower_arm_j3).p,
                b(BodyId::UpperArm).at(p.upper_arm_j3).p,
            ),
            (
                b(BodyId::LowerArm).at(p.lower_arm_j4).p,
                b(BodyId::BalanceRod).at(p.balance_rod_j4).p,
            ),
            (
                b(BodyId::CouplingRod).at(p.coupling_rod_j2).p,
                self.ground_j2,
            ),
            (
                b(BodyId::Shaft).at(p.shaft_j6).p,
                b(BodyId::Suspension).at(p.suspension_j6).p,
            ),
        ];
        pairs
            .iter()
            .map(|(a, c)| (*a - *c).norm())
            .fold(0.0, f64::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lift::geometry::builtin_160ec;

    fn wrap(a: f64) -> f64 {
        (a + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI) - std::f64::consts::PI
    }

    #[test]
    fn assembly_matches_every_reference_pose() {
        let g = builtin_160ec();
        let lk = Linkage::new(g);
        let mut worst: f64 = 0.0;
        for rp in &g.reference_poses {
            let pose = lk.pose(rp.alpha_rad).unwrap();
            let head = lk.head(&pose, rp.h_m, 0.0, 0.0);
            for (name, want) in &rp.points_m {
                let got = match name.as_str() {
                    "strip" => head.strip,
                    "J1" => pose.joint(RevJoint::J1).p,
                    "J2" => pose.joint(RevJoint::J2).p,
                    "J2'" => pose.joint(RevJoint::J2p).p,
                    "J3" => pose.joint(RevJoint::J3).p,
                    "J4" => pose.joint(RevJoint::J4).p,
                    "J5" => pose.joint(RevJoint::J5).p,
                    "J6" => pose.joint(RevJoint::J6).p,
                    "J7" => pose.joint(RevJoint::J7).p,
                    other => panic!("unknown point {other}"),
                };
                let err = (got - V2::from_array(*want)).norm();
                worst = worst.max(err);
                assert!(err < 1e-9, "H {}: {name} off by {err:e} m", rp.h_strip_m);
            }
            for b in BodyId::ALL {
                let want = rp.theta_rad[b.key()];
                let got = match b {
                    BodyId::Head => pose.body(BodyId::Suspension).theta_rad(),
                    _ => pose.body(b).theta_rad(),
                };
                assert!(
                    wrap(got - want).abs() < 1e-9,
                    "{}: {got} vs {want}",
                    b.key()
                );
            }
            assert!((head.strip.y - rp.h_strip_m).abs() < 1e-9);
        }
        eprintln!("reference poses: worst joint error {worst:e} m");
    }

    #[test]
    fn closure_to_machine_precision_over_the_range() {
        let g = builtin_160ec();
        let lk = Linkage::new(g);
        let mut worst: f64 = 0.0;
        let n = 2000;
        for k in 0..=n {
            let a = g.alpha_min_rad + (g.alpha_max_rad - g.alpha_min_rad) * k as f64 / n as f64;
            worst = worst.max(lk.closure_error_m(&lk.pose(a).unwrap()));
        }
        eprintln!("closure error over the range: {worst:e} m");
        assert!(worst <= 1e-12, "{worst:e}");
    }

    #[test]
    fn alpha_derivatives_match_finite_differences() {
        let g = builtin_160ec();
        let lk = Linkage::new(g);
        let (a, e) = (0.3, 1e-4);
        let (p0, pm, pp) = (
            lk.pose(a).unwrap(),
            lk.pose(a - e).unwrap(),
            lk.pose(a + e).unwrap(),
        );
        for b in 0..6 {
            let th = |p: &LinkagePose| p.bodies[b].theta_rad();
            let d1 = wrap(th(&pp) - th(&pm)) / (2.0 * e);
            let d2 = wrap(th(&pp) - 2.0 * th(&p0) + th(&pm)) / (e * e);
            assert!(
                (d1 - p0.bodies[b].w1).abs() < 1e-8,
                "body {b}: {d1} vs {}",
                p0.bodies[b].w1
            );
            assert!(
                (d2 - p0.bodies[b].w2).abs() < 1e-4,
                "body {b}: {d2} vs {}",
                p0.bodies[b].w2
            );
            let c = |p: &LinkagePose| p.bodies[b].com.p;
            let fd1 = (c(&pp) - c(&pm)) * (0.5 / e);
            let fd2 = (c(&pp) - c(&p0) * 2.0 + c(&pm)) * (1.0 / (e * e));
            assert!((fd1 - p0.bodies[b].com.d1).norm() < 1e-8);
            assert!(
                (fd2 - p0.bodies[b].com.d2).norm() < 1e-4,
                "body {b}: {fd2:?} vs {:?}",
                p0.bodies[b].com.d2
            );
        }
        // Head: ∂strip/∂α and the velocity-product acceleration at ḣ = 0.
        let h = -0.004;
        let hk = |p: &LinkagePose| lk.head(p, h, 0.0, 0.0);
        let fd = (hk(&pp).strip - hk(&pm).strip) * (0.5 / e);
        assert!((fd - hk(&p0).strip_d_alpha).norm() < 1e-8);
        let fd2 = (hk(&pp).com - hk(&p0).com * 2.0 + hk(&pm).com) * (1.0 / (e * e));
        assert!((fd2 - lk.head(&p0, h, 1.0, 0.0).com_acc0).norm() < 1e-4);
    }
}

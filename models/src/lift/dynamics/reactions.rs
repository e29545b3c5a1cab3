//! The joint reactions from the bodies' Newton–Euler equations ([`LiftModel::reactions`]): the
//! moment balances body by body, from the head down to the lower arm.

use super::super::kinematics::{HeadKin, LinkagePose};
use super::super::topology::{BodyId, N_REV, RevJoint};
use super::super::vec2::V2;
use super::{LiftModel, Loads, Reactions};

impl LiftModel {
    /// Reaction forces from the bodies' Newton–Euler equations at given accelerations and
    /// friction torques: head and suspension together → J6; shaft and balance rod (moments
    /// about J5 and J4) → J7, then J5 and J4; upper arm and coupling rod (moments about J3 and
    /// J2) → J2′, then J3 and J2; lower arm → J1. The remaining two equations (lower-arm
    /// moment, head along the slide) are the equations of motion themselves.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub(in crate::lift) fn reactions(
        &self,
        pose: &LinkagePose,
        head: &HeadKin,
        ad2: f64,
        add: f64,
        hdd: f64,
        torque: &[f64; N_REV],
        loads: &Loads,
        f_axial: f64,
    ) -> Reactions {
        use RevJoint as J;
        let g = self.gravity;
        // m(a − g) and Iθ̈ of each body.
        let mut need = [V2::ZERO; 7];
        let mut iacc = [0.0; 7];
        for i in 0..6 {
            let bk = &pose.bodies[i];
            need[i] = self.mass_kg[i] * (bk.com.d1 * add + bk.com.d2 * ad2 - g);
            iacc[i] = self.inertia_kgm2[i] * (bk.w1 * add + bk.w2 * ad2);
        }
        let hi = BodyId::Head.index();
        let si = BodyId::Suspension.index();
        need[hi] = self.mass_kg[hi] * (head.com_d_alpha * add + head.u * hdd + head.com_acc0 - g);
        iacc[hi] = self.inertia_kgm2[hi] * (pose.bodies[si].w1 * add + pose.bodies[si].w2 * ad2);
        let t = |j: J| torque[j.index()];
        let p = |j: J| pose.joints[j.index()].p;
        let com = |b: BodyId| {
            if b == BodyId::Head {
                head.com
            } else {
                pose.bodies[b.index()].com.p
            }
        };
        let strip_force = V2::new(0.0, -loads.strip_load_n);

        // Head on the slide: the constraint force is what the head's own loads leave over.
        let j8_force = need[hi] - strip_force - f_axial * head.u;
        // Suspension + head on the shaft (J6): their internal forces cancel.
        let j6 = p(J::J6);
        let f6 = need[si] + need[hi] - strip_force;
        let m6 = iacc[si]
            + (com(BodyId::Suspension) - j6).cross(need[si])
            + iacc[hi]
            + (head.com - j6).cross(need[hi])
            - (head.strip - j6).cross(strip_force);
        // Shaft (moment about J5) and balance rod (moment about J4) → J7.
        let (sh, br) = (BodyId::Shaft.index(), BodyId::BalanceRod.index());
        let (j4, j5, j7) = (p(J::J4), p(J::J5), p(J::J7));
        let a1 = iacc[sh]
            + (com(BodyId::Shaft) - j5).cross(need[sh])
            + (j6 - j5).cross(f6)
            + m6
            + t(J::J5)
            + t(J::J7);
        let a2 = -(iacc[br] + (com(BodyId::BalanceRod) - j4).cross(need[br]) + t(J::J4) - t(J::J7));
        let f7 = solve_moments(j7 - j5, a1, j7 - j4, a2);
        let f5 = need[sh] - f7 + f6;
        let f4 = need[br] + f7;
        // Upper arm (moment about J3) and coupling rod (moment about J2) → J2′.
        let (ua, cr) = (BodyId::UpperArm.index(), BodyId::CouplingRod.index());
        let (j2, j2p, j3) = (p(J::J2), p(J::J2p), p(J::J3));
        let b1 = iacc[ua]
            + (com(BodyId::UpperArm) - j3).cross(need[ua])
            + (j5 - j3).cross(f5)
            + t(J::J3)
            + t(J::J2p)
            - t(J::J5);
        let b2 =
            -(iacc[cr] + (com(BodyId::CouplingRod) - j2).cross(need[cr]) + t(J::J2) - t(J::J2p));
        let f2p = solve_moments(j2p - j3, b1, j2p - j2, b2);
        let f3 = need[ua] - f2p + f5;
        let f2 = need[cr] + f2p;
        let f1 = need[BodyId::LowerArm.index()] + f3 + f4;
        Reactions {
            force_n: [f1, f2, f2p, f3, f4, f5, f6, f7],
            j6_couple_nm: m6,
            j8_force_n: j8_force,
        }
    }
}

/// The force f with r1 × f = m1 and r2 × f = m2.
#[inline]
fn solve_moments(r1: V2, m1: f64, r2: V2, m2: f64) -> V2 {
    (m1 * r2 - m2 * r1) * (1.0 / r1.cross(r2))
}

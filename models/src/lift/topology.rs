//! The 160EC's kinematic topology (paper, Section 2 and Fig 3): which bodies there are and
//! which joint connects which two. The topology is code; every number is in the geometry file.

/// A moving body of the planar model, in Table 2's order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum BodyId {
    LowerArm,
    CouplingRod,
    UpperArm,
    BalanceRod,
    /// Spring suspension shaft (Table 2 no. 5), carrying the crank J5 → J7.
    Shaft,
    /// The two spring suspension assemblies with half the springs, lumped; locked to the shaft
    /// in the plane of motion (J6).
    Suspension,
    /// Collector head with the other half of the springs, on the J8 slide.
    Head,
}

impl BodyId {
    pub const ALL: [BodyId; 7] = [
        BodyId::LowerArm,
        BodyId::CouplingRod,
        BodyId::UpperArm,
        BodyId::BalanceRod,
        BodyId::Shaft,
        BodyId::Suspension,
        BodyId::Head,
    ];

    /// Key of the body in the geometry file (`[bodies.<key>]`).
    pub fn key(self) -> &'static str {
        match self {
            BodyId::LowerArm => "lower_arm",
            BodyId::CouplingRod => "coupling_rod",
            BodyId::UpperArm => "upper_arm",
            BodyId::BalanceRod => "balance_rod",
            BodyId::Shaft => "shaft",
            BodyId::Suspension => "suspension",
            BodyId::Head => "head",
        }
    }

    pub fn index(self) -> usize {
        self as usize
    }
}

/// A revolute joint (Table 4). J6 is among them: locked in the plane, its relative rate is 0.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum RevJoint {
    J1,
    J2,
    J2p,
    J3,
    J4,
    J5,
    J6,
    J7,
}

/// Number of revolute joints.
pub const N_REV: usize = 8;

impl RevJoint {
    pub const ALL: [RevJoint; N_REV] = [
        RevJoint::J1,
        RevJoint::J2,
        RevJoint::J2p,
        RevJoint::J3,
        RevJoint::J4,
        RevJoint::J5,
        RevJoint::J6,
        RevJoint::J7,
    ];

    /// The paper's name, also the key in the geometry file (`[joints."J2'"]`).
    pub fn name(self) -> &'static str {
        match self {
            RevJoint::J1 => "J1",
            RevJoint::J2 => "J2",
            RevJoint::J2p => "J2'",
            RevJoint::J3 => "J3",
            RevJoint::J4 => "J4",
            RevJoint::J5 => "J5",
            RevJoint::J6 => "J6",
            RevJoint::J7 => "J7",
        }
    }

    /// (first, second) body; `None` is the ground (main frame). The joint's relative rate is
    /// ω_rel = θ̇(second) − θ̇(first), its reaction force is the one the first body exerts on the
    /// second, and its friction torque acts −T on the second body and +T on the first.
    pub fn bodies(self) -> (Option<BodyId>, BodyId) {
        use BodyId::*;
        match self {
            RevJoint::J1 => (None, LowerArm),
            RevJoint::J2 => (None, CouplingRod),
            RevJoint::J2p => (Some(CouplingRod), UpperArm),
            RevJoint::J3 => (Some(LowerArm), UpperArm),
            RevJoint::J4 => (Some(LowerArm), BalanceRod),
            RevJoint::J5 => (Some(UpperArm), Shaft),
            RevJoint::J6 => (Some(Shaft), Suspension),
            RevJoint::J7 => (Some(BalanceRod), Shaft),
        }
    }

    pub fn index(self) -> usize {
        self as usize
    }
}

/// The head joints: J8 (four cylindrical slides, lumped) and J9 (four springs, lumped), both
/// between the suspension assemblies (first) and the head (second).
pub const SLIDE_BODIES: (BodyId, BodyId) = (BodyId::Suspension, BodyId::Head);

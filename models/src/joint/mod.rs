//! One joint on its test rig (paper, Figs 5–11): the rig, the friction laws, the equation of
//! motion, stick–slip simulation, identification with intervals and the residual loop.

pub mod dynamics;
pub mod friction;
pub mod identify;
pub mod residual;
pub mod rig;
pub mod simulate;
pub mod synth;

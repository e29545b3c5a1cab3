//! The sensor side of the model: what the channel reads for a simulated motion —
//! `y(t) = scale·B_b(q(t − τ)) + o` with a sensor delay τ, a backlash (play) of half-width b
//! between the body and the sensor, and a sensor zero o — with the readings' sensitivities.

use crate::joint::dynamics::Dof;
use crate::joint::friction::FrictionLaw;
use crate::joint::simulate::{SimError, SimOptions, Trajectory, simulate};

/// Sensor-side effects. Defaults: none.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Readout {
    /// Sensor zero, channel units.
    pub offset: f64,
    /// The reading lags the motion by this time, s (`sensor_delay`).
    pub delay_s: f64,
    /// Half-width of the dead band between body and sensor, model units (`backlash`).
    pub backlash: f64,
}

/// Readings and their sensitivities.
#[derive(Debug, Clone)]
pub struct Reading {
    /// Channel units, one per sample.
    pub y: Vec<f64>,
    /// ∂y/∂p row-major `[k * m + j]`: the simulation's sensitivity parameters in order, then
    /// the delay (if asked), then the backlash (if asked). The offset's column is 1 (not stored).
    pub dy: Vec<f64>,
    pub m: usize,
    /// The motion (at the delayed times).
    pub traj: Trajectory,
}

/// Simulate from the release (q0, v0) at `times[0]` and read at every time in `times`.
#[allow(clippy::too_many_arguments)]
pub fn read(
    dof: &Dof,
    law: &FrictionLaw,
    q0: f64,
    v0: f64,
    ro: &Readout,
    times: &[f64],
    sim: &SimOptions,
    scale: f64,
    d_delay: bool,
    d_backlash: bool,
) -> Result<Reading, SimError> {
    let n = times.len();
    if ro.delay_s == 0.0 && ro.backlash == 0.0 && !d_delay && !d_backlash {
        // No sensor-side effect: the readings are the motion, scaled (no copies).
        let mut traj = simulate(dof, law, q0, v0, times, sim)?;
        let y = traj.q.iter().map(|x| scale * x + ro.offset).collect();
        let mut dy = std::mem::take(&mut traj.dq);
        for d in dy.iter_mut() {
            *d *= scale;
        }
        traj.dq = Vec::new();
        let m = traj.n_sens;
        return Ok(Reading { y, dy, m, traj });
    }
    let t0 = times[0];
    // Sample k reads the motion at t_k − τ; before the release it reads the release state.
    let shifted: Vec<f64> = times.iter().map(|t| t - ro.delay_s).collect();
    let k0 = shifted.iter().position(|&s| s > t0).unwrap_or(n);
    let mut sim_times = Vec::with_capacity(n - k0 + 1);
    sim_times.push(t0);
    sim_times.extend_from_slice(&shifted[k0..]);
    let traj = simulate(dof, law, q0, v0, &sim_times, sim)?;
    let ns = traj.n_sens;
    let m = ns + usize::from(d_delay) + usize::from(d_backlash);
    let idx = |k: usize| if k < k0 { 0 } else { k - k0 + 1 };
    let mut q = Vec::with_capacity(n);
    let mut dq = vec![0.0; n * m];
    for k in 0..n {
        let i = idx(k);
        q.push(traj.q[i]);
        dq[k * m..k * m + ns].copy_from_slice(&traj.dq[i * ns..(i + 1) * ns]);
        if d_delay && k >= k0 {
            dq[k * m + ns] = -traj.v[i];
        }
    }
    // Backlash: the play operator on the sampled motion.
    if ro.backlash > 0.0 || d_backlash {
        let b = ro.backlash;
        let jb = m.saturating_sub(1);
        let s0 = q
            .iter()
            .find(|&&x| x != q[0])
            .map_or(1.0, |x| (x - q[0]).signum());
        let mut z = q[0] + b * s0;
        let mut dz: Vec<f64> = dq[0..m].to_vec();
        if d_backlash {
            dz[jb] = s0;
        }
        for k in 0..n {
            let row = &mut dq[k * m..(k + 1) * m];
            if q[k] - z > b {
                z = q[k] - b;
                dz.copy_from_slice(row);
                if d_backlash {
                    dz[jb] = -1.0;
                }
            } else if q[k] - z < -b {
                z = q[k] + b;
                dz.copy_from_slice(row);
                if d_backlash {
                    dz[jb] = 1.0;
                }
            }
            q[k] = z;
            row.copy_from_slice(&dz);
        }
    }
    let y = q.iter().map(|x| scale * x + ro.offset).collect();
    for d in dq.iter_mut() {
        *d *= scale;
    }
    Ok(Reading { y, dy: dq, m, traj })
}

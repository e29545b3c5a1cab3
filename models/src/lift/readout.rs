//! The strip-height read-out tabulated over α: what of H depends only on the geometry, built
//! once per model and read at every recorded sample of every fit evaluation (issue 8).
//!
//! H(α, h) = A(α) + B(α)·(s₀ + h), with A the height of the J8 slide line's base point, B the
//! vertical component of the slide direction and s₀ the strip offset at h = 0 (the head slides
//! along the suspension). So ∂H/∂α = A′ + B′·(s₀ + h) and ∂H/∂h = B. A, A′, B, B′ are functions
//! of α alone; each is interpolated by a cubic Hermite polynomial from its value and exact
//! derivative at the nodes (A″ and B″ from the pose's second derivatives), so A′ and B′ come
//! from their own Hermite data rather than by differentiating A's.
//!
//! Assumption, checked where the table is built: on every interval it keeps, the interpolant at
//! the interval's midpoint agrees with the closed-form pose to [`TOL_H_M`] in H and [`TOL_DH`]
//! in ∂H/∂α (a cubic Hermite's error peaks near there; at 1,024 intervals over the 160EC range
//! the agreement is ~10⁻¹⁴ m). Intervals where the check fails (near a loop's toggle, or
//! outside the assembly range) are read from the closed-form pose, as is every α off the table.
//! The full pose (~160 scalars, what the right-hand side needs) is not tabulated: a table of it
//! costs as much to interpolate as the closed form costs to solve (docs/PROFILE.md).

use super::kinematics::{AssemblyError, Linkage};
use super::topology::BodyId;

/// Largest midpoint error in H kept in the table, m (the fit's integration error in H is
/// ~10⁻⁴ m and the stated H noise 10⁻³ m).
pub const TOL_H_M: f64 = 1e-9;
/// Largest midpoint error in ∂H/∂α kept in the table, m/rad (∂H/∂α is 2.5–3.5 m/rad).
pub const TOL_DH: f64 = 1e-8;
/// Intervals over the tabulated span.
const INTERVALS: usize = 1024;
/// The span is the model's α range widened by this on each side (simulations overshoot it).
const MARGIN_RAD: f64 = 0.1;

/// A, A′, A″, B, B′, B″ at one α.
type Node = [f64; 6];

/// The tabulated read-out: see the module doc.
#[derive(Debug, Clone)]
pub struct StripTable {
    lo_rad: f64,
    step_rad: f64,
    strip_offset_m: f64,
    nodes: Vec<Node>,
    /// Whether interval i (nodes i, i + 1) passed the midpoint check.
    usable: Vec<bool>,
}

fn node(lk: &Linkage, alpha_rad: f64) -> Result<Node, AssemblyError> {
    let pose = lk.pose(alpha_rad)?;
    let s = pose.body(BodyId::Suspension);
    let u = s.rot.apply(lk.slide_axis);
    // du/dα = θ′·perp(u); d²u/dα² = θ″·perp(u) − θ′²·u (perp(x, y) = (−y, x)).
    Ok([
        pose.j8.p.y,
        pose.j8.d1.y,
        pose.j8.d2.y,
        u.y,
        s.w1 * u.x,
        s.w2 * u.x - s.w1 * s.w1 * u.y,
    ])
}

/// Cubic Hermite on [0, 1] from values and derivatives (derivatives already scaled by the step).
#[inline]
fn hermite(t: f64, f0: f64, d0: f64, f1: f64, d1: f64) -> f64 {
    let t2 = t * t;
    let t3 = t2 * t;
    let h00 = 2.0 * t3 - 3.0 * t2 + 1.0;
    let h10 = t3 - 2.0 * t2 + t;
    let h01 = -2.0 * t3 + 3.0 * t2;
    let h11 = t3 - t2;
    h00 * f0 + h10 * d0 + h01 * f1 + h11 * d1
}

impl StripTable {
    /// Tabulate `lk` over `alpha_range_rad` widened by [`MARGIN_RAD`], checking every interval.
    pub fn new(lk: &Linkage, alpha_range_rad: (f64, f64)) -> Self {
        let lo = alpha_range_rad.0 - MARGIN_RAD;
        let hi = alpha_range_rad.1 + MARGIN_RAD;
        let step = (hi - lo) / INTERVALS as f64;
        let raw: Vec<Option<Node>> = (0..=INTERVALS)
            .map(|i| node(lk, lo + i as f64 * step).ok())
            .collect();
        let nodes: Vec<Node> = raw.iter().map(|n| n.unwrap_or([f64::NAN; 6])).collect();
        let mut table = Self {
            lo_rad: lo,
            step_rad: step,
            strip_offset_m: lk.strip_offset_m,
            nodes,
            usable: vec![false; INTERVALS],
        };
        for i in 0..INTERVALS {
            if raw[i].is_none() || raw[i + 1].is_none() {
                continue;
            }
            let mid = lo + (i as f64 + 0.5) * step;
            let Ok(exact) = node(lk, mid) else { continue };
            let (a, da, b, db) = table.interpolate(i, 0.5);
            // Checked at h = 0 and at a stroke of 0.2 m (B's error scales with s₀ + h).
            let ok = [0.0, 0.2].iter().all(|&h| {
                let arm = lk.strip_offset_m + h;
                let eh = (a + b * arm) - (exact[0] + exact[3] * arm);
                let ed = (da + db * arm) - (exact[1] + exact[4] * arm);
                eh.abs() <= TOL_H_M && ed.abs() <= TOL_DH
            });
            table.usable[i] = ok && (b - exact[3]).abs() <= TOL_DH;
        }
        table
    }

    /// A, A′, B, B′ at fraction `t` of interval `i`.
    #[inline]
    fn interpolate(&self, i: usize, t: f64) -> (f64, f64, f64, f64) {
        let (n0, n1, s) = (&self.nodes[i], &self.nodes[i + 1], self.step_rad);
        (
            hermite(t, n0[0], n0[1] * s, n1[0], n1[1] * s),
            hermite(t, n0[1], n0[2] * s, n1[1], n1[2] * s),
            hermite(t, n0[3], n0[4] * s, n1[3], n1[4] * s),
            hermite(t, n0[4], n0[5] * s, n1[4], n1[5] * s),
        )
    }

    /// H, ∂H/∂α and ∂H/∂h at (α, h) from the table, or `None` where it has no checked interval.
    #[inline]
    pub fn lookup(&self, alpha_rad: f64, h_m: f64) -> Option<(f64, f64, f64)> {
        let x = (alpha_rad - self.lo_rad) / self.step_rad;
        // NaN and out-of-span α fall through here.
        if !(x >= 0.0 && x < INTERVALS as f64) {
            return None;
        }
        let i = x as usize;
        if !self.usable[i] {
            return None;
        }
        let (a, da, b, db) = self.interpolate(i, x - i as f64);
        let arm = self.strip_offset_m + h_m;
        Some((a + b * arm, da + db * arm, b))
    }

    /// Fraction of the tabulated span whose intervals passed the check.
    pub fn coverage(&self) -> f64 {
        self.usable.iter().filter(|u| **u).count() as f64 / INTERVALS as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lift::geometry::builtin_160ec;

    fn exact(lk: &Linkage, a: f64, h: f64) -> (f64, f64, f64) {
        let pose = lk.pose(a).unwrap();
        let head = lk.head(&pose, h, 0.0, 0.0);
        (head.strip.y, head.strip_d_alpha.y, head.u.y)
    }

    /// Against the closed-form pose at 20,000 points between the nodes over the whole working
    /// range and a stroke of ±0.1 m: H within 10⁻⁹ m, ∂H/∂α within 10⁻⁸ m/rad, ∂H/∂h within
    /// 10⁻⁸; the working range wholly covered.
    #[test]
    fn the_table_agrees_with_the_closed_form_pose() {
        let g = builtin_160ec();
        let lk = Linkage::new(g);
        let t = StripTable::new(&lk, (g.alpha_min_rad, g.alpha_max_rad));
        let (mut eh, mut ed, mut eu) = (0.0f64, 0.0f64, 0.0f64);
        for k in 0..20_000 {
            // An irrational stride so the points fall anywhere inside the intervals.
            let f = (k as f64 * 0.618_033_988_75).fract();
            let a = g.alpha_min_rad + f * (g.alpha_max_rad - g.alpha_min_rad);
            let h = 0.1 * (k as f64 * 0.414_213_562).fract() * 2.0 - 0.1;
            let (h0, d0, u0) = exact(&lk, a, h);
            let (h1, d1, u1) = t.lookup(a, h).expect("the working range is tabulated");
            eh = eh.max((h1 - h0).abs());
            ed = ed.max((d1 - d0).abs());
            eu = eu.max((u1 - u0).abs());
        }
        eprintln!(
            "table vs closed form: H {eh:.1e} m, dH/dα {ed:.1e} m/rad, dH/dh {eu:.1e}; coverage {:.3}",
            t.coverage()
        );
        assert!(eh <= 1e-9 && ed <= 1e-8 && eu <= 1e-8, "{eh} {ed} {eu}");
        assert!(t.coverage() > 0.7);
    }

    /// Off the span, NaN, and intervals that fail the check give `None` (the caller reads the
    /// closed form), never a wrong value.
    #[test]
    fn off_the_table_is_none() {
        let g = builtin_160ec();
        let lk = Linkage::new(g);
        let t = StripTable::new(&lk, (g.alpha_min_rad, g.alpha_max_rad));
        assert!(t.lookup(g.alpha_min_rad - 0.2, 0.0).is_none());
        assert!(t.lookup(g.alpha_max_rad + 0.2, 0.0).is_none());
        assert!(t.lookup(f64::NAN, 0.0).is_none());
        assert!(t.lookup(f64::INFINITY, 0.0).is_none());
        // A table whose every interval failed its check answers nothing.
        let mut bad = t.clone();
        bad.usable.fill(false);
        assert!(bad.lookup(0.2, 0.0).is_none());
        assert!(t.lookup(0.2, 0.0).is_some());
    }
}

//! Local polynomial smoothing and differentiation of a sampled signal (Savitzky–Golay in
//! spirit, but on the actual sample times, so uneven spacing is handled).

/// Value, first and second derivative of a local cubic fitted by least squares to the samples
/// `i − half ..= i + half` (clipped at the ends), evaluated at sample `i`.
pub fn local_cubic(t: &[f64], y: &[f64], i: usize, half: usize) -> (f64, f64, f64) {
    let n = t.len();
    let lo = i.saturating_sub(half);
    let hi = (i + half).min(n - 1);
    let t0 = t[i];
    let span = (t[hi] - t[lo]).max(f64::MIN_POSITIVE);
    // Normal equations in the scaled variable u = (t − t0)/span, degree ≤ 3.
    let deg = (hi - lo).min(3);
    let m = deg + 1;
    let mut a = [[0.0f64; 4]; 4];
    let mut b = [0.0f64; 4];
    for k in lo..=hi {
        let u = (t[k] - t0) / span;
        let mut pw = [1.0, u, u * u, u * u * u];
        pw[m..].fill(0.0);
        for r in 0..m {
            b[r] += pw[r] * y[k];
            for c in 0..m {
                a[r][c] += pw[r] * pw[c];
            }
        }
    }
    let c = solve_small(&mut a, &mut b, m);
    let c1 = if m > 1 { c[1] } else { 0.0 };
    let c2 = if m > 2 { c[2] } else { 0.0 };
    (c[0], c1 / span, 2.0 * c2 / (span * span))
}

/// Gaussian elimination with partial pivoting on an m×m system (m ≤ 4).
fn solve_small(a: &mut [[f64; 4]; 4], b: &mut [f64; 4], m: usize) -> [f64; 4] {
    for col in 0..m {
        let piv = (col..m)
            .max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))
            .unwrap_or(col);
        a.swap(col, piv);
        b.swap(col, piv);
        let d = a[col][col];
        if d.abs() < 1e-300 {
            continue;
        }
        for r in col + 1..m {
            let f = a[r][col] / d;
            for c in col..m {
                a[r][c] -= f * a[col][c];
            }
            b[r] -= f * b[col];
        }
    }
    let mut x = [0.0; 4];
    for r in (0..m).rev() {
        let mut s = b[r];
        for c in r + 1..m {
            s -= a[r][c] * x[c];
        }
        x[r] = if a[r][r].abs() < 1e-300 {
            0.0
        } else {
            s / a[r][r]
        };
    }
    x
}

/// Half-window (in samples) that spans about `seconds`, from the median sample spacing.
pub fn half_window(t: &[f64], seconds: f64) -> usize {
    if t.len() < 3 {
        return 1;
    }
    let mut dt: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    let mid = dt.len() / 2;
    let med = *dt.select_nth_unstable_by(mid, f64::total_cmp).1;
    ((seconds / 2.0 / med).round() as usize).clamp(2, t.len() / 2)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cubic_derivatives_of_a_sine_on_uneven_samples() {
        let t: Vec<f64> = (0..400)
            .map(|i| i as f64 * 0.01 + 0.003 * ((i * 7) % 3) as f64)
            .collect();
        let y: Vec<f64> = t.iter().map(|x| x.sin()).collect();
        let (v, d1, d2) = local_cubic(&t, &y, 200, 6);
        let x = t[200];
        assert!(
            (v - x.sin()).abs() < 1e-7
                && (d1 - x.cos()).abs() < 1e-5
                && (d2 + x.sin()).abs() < 1e-3,
            "{v} {d1} {d2}"
        );
    }
}

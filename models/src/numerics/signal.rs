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

/// `local_cubic(tt, e_k, half, half)` for every unit impulse e_k, k < tt.len(), in O(window)
/// rather than O(window²) (issue 38: at 10 kHz a pendulum's window is ~1,800 samples). The
/// normal matrix does not depend on the data, and with a unit impulse the right-hand side is
/// the impulse's own powers: the same sums and the same elimination as [`local_cubic`], so the
/// same weights to the bit.
fn impulse_weights(tt: &[f64], half: usize) -> Vec<(f64, f64, f64)> {
    let n = tt.len();
    let (lo, hi) = (0, (half + half).min(n - 1));
    let t0 = tt[half];
    let span = (tt[hi] - tt[lo]).max(f64::MIN_POSITIVE);
    let deg = (hi - lo).min(3);
    let m = deg + 1;
    let powers = |k: usize| {
        let u = (tt[k] - t0) / span;
        let mut pw = [1.0, u, u * u, u * u * u];
        pw[m..].fill(0.0);
        pw
    };
    let mut a = [[0.0f64; 4]; 4];
    for k in lo..=hi {
        let pw = powers(k);
        for r in 0..m {
            for c in 0..m {
                a[r][c] += pw[r] * pw[c];
            }
        }
    }
    (0..n)
        .map(|k| {
            if k < lo || k > hi {
                return (0.0, 0.0, 0.0);
            }
            let mut b = powers(k);
            let c = solve_small(&mut a.clone(), &mut b, m);
            let c1 = if m > 1 { c[1] } else { 0.0 };
            let c2 = if m > 2 { c[2] } else { 0.0 };
            (c[0], c1 / span, 2.0 * c2 / (span * span))
        })
        .collect()
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

/// The logger's resolution, channel units: the step of the grid every reading lies on, or 0
/// when the readings are not on one (an unquantised channel). Assumption: the smallest
/// positive difference between distinct readings is one step, and at least 99 % of readings
/// lie within 1 % of a step from a multiple of it.
pub fn resolution(y: &[f64]) -> f64 {
    let mut v: Vec<f64> = y.iter().copied().filter(|x| x.is_finite()).collect();
    if v.len() < 10 {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    let scale = v
        .iter()
        .fold(0.0f64, |m, x| m.max(x.abs()))
        .max(f64::MIN_POSITIVE);
    let step = v
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|d| *d > 1e-12 * scale)
        .fold(f64::INFINITY, f64::min);
    if !step.is_finite() {
        return 0.0;
    }
    let on_grid = y
        .iter()
        .filter(|x| {
            let q = *x / step;
            (q - q.round()).abs() <= 0.01
        })
        .count();
    if on_grid as f64 >= 0.99 * y.len() as f64 {
        step
    } else {
        0.0
    }
}

/// Whether every spacing of `t` is within 1e-6·`dt` of `dt`: `t.windows(2).all(|w| ((w[1] −
/// w[0]) − dt).abs() ≤ 1e-6·dt)`, the same answer for every input (NaN included), judged 16
/// spacings at a time without a branch each (issue 38, session 23: four passes over the record
/// a pendulum fit, 12 instructions a sample each).
pub fn evenly_spaced(t: &[f64], dt: f64) -> bool {
    if t.len() < 2 {
        return true;
    }
    let tol = 1e-6 * dt;
    let (a, b) = (&t[..t.len() - 1], &t[1..]);
    a.chunks(16).zip(b.chunks(16)).all(|(a, b)| {
        a.iter()
            .zip(b)
            .fold(true, |ok, (&x, &y)| ok & (((y - x) - dt).abs() <= tol))
    })
}

/// Half-window (in samples) that spans about `seconds`, from the median sample spacing.
pub fn half_window(t: &[f64], seconds: f64) -> usize {
    if t.len() < 3 {
        return 1;
    }
    // Evenly spaced (every spacing within 1e-6 of the mean, the logger's case): the mean is
    // the median to that precision, without sorting a copy of the spacings (session 21: three
    // calls per fit were 3.5 % of a pendulum's identification).
    let n = t.len();
    let mean = (t[n - 1] - t[0]) / (n - 1) as f64;
    if mean > 0.0 && evenly_spaced(t, mean) {
        return ((seconds / 2.0 / mean).round() as usize).clamp(2, n / 2);
    }
    let mut dt: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    let mid = dt.len() / 2;
    let med = *dt.select_nth_unstable_by(mid, f64::total_cmp).1;
    ((seconds / 2.0 / med).round() as usize).clamp(2, t.len() / 2)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 38, session 23: the chunked evenness test answers as the pairwise one on even
    /// grids, grids with one spacing off (anywhere, by just over and just under the tolerance),
    /// NaN and infinite times, and every length 0 to 40.
    #[test]
    fn evenly_spaced_is_the_pairwise_test() {
        let pairwise = |t: &[f64], dt: f64| {
            t.windows(2)
                .all(|w| ((w[1] - w[0]) - dt).abs() <= 1e-6 * dt)
        };
        let mut rng = crate::numerics::noise::Noise::new(23);
        let mut cases = 0;
        for n in 0..=40usize {
            let fs = 100.0 + 900.0 * rng.uniform();
            let even: Vec<f64> = (0..n).map(|i| i as f64 / fs).collect();
            let dt = 1.0 / fs;
            let mut grids = vec![even.clone()];
            for k in 1..n {
                for (off, bad) in [(1.5e-6, f64::NAN), (0.5e-6, f64::INFINITY)] {
                    let mut g = even.clone();
                    for x in &mut g[k..] {
                        *x += off * dt;
                    }
                    grids.push(g);
                    let mut g = even.clone();
                    g[k] = bad;
                    grids.push(g);
                }
            }
            for g in &grids {
                for d in [dt, dt * (1.0 + 1e-5), f64::NAN] {
                    assert_eq!(evenly_spaced(g, d), pairwise(g, d), "n {n}, {g:?}, {d}");
                    cases += 1;
                }
            }
        }
        assert!(cases > 4000);
    }

    #[test]
    fn a_logger_step_is_read_off_the_data_and_continuous_readings_have_none() {
        let mut rng = crate::numerics::noise::Noise::new(3);
        let raw: Vec<f64> = (0..2000)
            .map(|k| 40.0 * (k as f64 * 0.01).cos() + 0.05 * rng.normal())
            .collect();
        assert_eq!(resolution(&raw), 0.0);
        let stepped: Vec<f64> = raw.iter().map(|x| (x / 0.01).round() * 0.01).collect();
        assert!(
            (resolution(&stepped) - 0.01).abs() < 1e-9,
            "{}",
            resolution(&stepped)
        );
        let mm: Vec<f64> = raw.iter().map(|x| (x / 0.025).round() * 0.025).collect();
        assert!((resolution(&mm) - 0.025).abs() < 1e-9);
    }

    /// Issue 38: the impulse weights in O(window) are the per-impulse fits' to the bit.
    #[test]
    fn impulse_weights_are_the_per_impulse_fits() {
        for half in [1usize, 2, 5, 40] {
            let tt: Vec<f64> = (0..2 * half + 1)
                .map(|k| (k as f64 - half as f64) * 1e-3)
                .collect();
            let fast = impulse_weights(&tt, half);
            let mut e = vec![0.0; tt.len()];
            for k in 0..tt.len() {
                e[k] = 1.0;
                let slow = local_cubic(&tt, &e, half, half);
                e[k] = 0.0;
                assert_eq!(fast[k], slow, "half {half}, k {k}");
            }
        }
    }

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

/// Local-cubic value, rate and acceleration at the samples `idx`, half-window `half`.
///
/// On evenly spaced samples (spacing equal to 1e-6 relative, the usual logger case) the
/// interior points use Savitzky–Golay weights computed once — the same local cubic, at
/// O(window) per point; the ends and uneven traces fall back to [`local_cubic`].
pub fn local_cubic_at(t: &[f64], y: &[f64], idx: &[usize], half: usize) -> Vec<(f64, f64, f64)> {
    let n = t.len();
    if n < 2 * half + 2 {
        return idx.iter().map(|&i| local_cubic(t, y, i, half)).collect();
    }
    let dt = (t[n - 1] - t[0]) / (n - 1) as f64;
    if !evenly_spaced(t, dt) {
        return idx.iter().map(|&i| local_cubic(t, y, i, half)).collect();
    }
    // Weights: the local cubic's coefficients are linear in y; apply it to unit impulses once.
    let m = 2 * half + 1;
    let tt: Vec<f64> = (0..m).map(|k| (k as f64 - half as f64) * dt).collect();
    let w = impulse_weights(&tt, half);
    idx.iter()
        .map(|&i| {
            if i < half || i + half >= n {
                return local_cubic(t, y, i, half);
            }
            let ys = &y[i - half..=i + half];
            let (mut a, mut b, mut c) = (0.0, 0.0, 0.0);
            for (yk, wk) in ys.iter().zip(&w) {
                a += wk.0 * yk;
                b += wk.1 * yk;
                c += wk.2 * yk;
            }
            (a, b, c)
        })
        .collect()
}

/// The rate alone of [`local_cubic_at`], the same number to the bit: a third of its work, for
/// a caller that only asks where the motion lasts (`identify::initial::energy_balance`).
pub fn local_cubic_rate_at(t: &[f64], y: &[f64], idx: &[usize], half: usize) -> Vec<f64> {
    let n = t.len();
    if n < 2 * half + 2 {
        return idx.iter().map(|&i| local_cubic(t, y, i, half).1).collect();
    }
    let dt = (t[n - 1] - t[0]) / (n - 1) as f64;
    if !evenly_spaced(t, dt) {
        return idx.iter().map(|&i| local_cubic(t, y, i, half).1).collect();
    }
    let m = 2 * half + 1;
    let tt: Vec<f64> = (0..m).map(|k| (k as f64 - half as f64) * dt).collect();
    let w: Vec<f64> = impulse_weights(&tt, half).iter().map(|w| w.1).collect();
    idx.iter()
        .map(|&i| {
            if i < half || i + half >= n {
                return local_cubic(t, y, i, half).1;
            }
            let mut b = 0.0;
            for (yk, wk) in y[i - half..=i + half].iter().zip(&w) {
                b += wk * yk;
            }
            b
        })
        .collect()
}

#[cfg(test)]
mod even_tests {
    use super::*;

    #[test]
    fn weights_agree_with_the_direct_fit() {
        let t: Vec<f64> = (0..500).map(|i| i as f64 * 0.002).collect();
        let y: Vec<f64> = t
            .iter()
            .map(|x| (3.0 * x).sin() + 0.1 * (17.0 * x).cos())
            .collect();
        let idx: Vec<usize> = (0..500).step_by(7).collect();
        let fast = local_cubic_at(&t, &y, &idx, 12);
        let rates = local_cubic_rate_at(&t, &y, &idx, 12);
        for (f, r) in fast.iter().zip(&rates) {
            assert_eq!(
                f.1.to_bits(),
                r.to_bits(),
                "the rate alone is the same number"
            );
        }
        for (k, &i) in idx.iter().enumerate() {
            let d = local_cubic(&t, &y, i, 12);
            assert!(
                (fast[k].0 - d.0).abs() < 1e-9
                    && (fast[k].1 - d.1).abs() < 1e-6
                    && (fast[k].2 - d.2).abs() < 1e-3,
                "{i}: {:?} vs {d:?}",
                fast[k]
            );
        }
    }
}

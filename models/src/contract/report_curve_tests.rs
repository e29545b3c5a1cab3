//! The fit curve's thinning for plots (`FitCurve::thinned`).

use super::FitCurve;

#[test]
fn a_long_record_is_thinned_to_the_plot_width_with_its_ends_kept() {
    let n = 5_000;
    let t: Vec<f64> = (0..n).map(|k| k as f64 * 0.002).collect();
    let y: Vec<f64> = t.iter().map(|t| t.sin()).collect();
    let m: Vec<f64> = y.iter().map(|v| v + 0.01).collect();
    let c = FitCurve::thinned("alpha_deg", "deg", &t, &y, &m).unwrap();
    assert_eq!(c.t_s.len(), FitCurve::MAX_POINTS);
    assert_eq!(c.t_s[0], 0.0);
    assert_eq!(*c.t_s.last().unwrap(), t[n - 1]);
    assert!((c.rmse() - 0.01).abs() < 1e-12);
    // A short record is kept whole; mismatched or empty series give nothing to draw.
    let s = FitCurve::thinned("H_m", "m", &t[..10], &y[..10], &m[..10]).unwrap();
    assert_eq!(s.t_s, t[..10].to_vec());
    assert!(FitCurve::thinned("H_m", "m", &t[..1], &y[..1], &m[..1]).is_none());
    let nan = vec![f64::NAN; 10];
    assert!(FitCurve::thinned("H_m", "m", &t[..10], &nan, &m[..10]).is_none());
}

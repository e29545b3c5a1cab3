//! Inline SVG charts for the web pages, drawn by hand (no JavaScript, no fonts to load): every
//! chart has `role="img"`, a `<title>` and a `<desc>` that says in words what it shows.

use std::fmt::Write;

use super::esc;

const W: f64 = 720.0;
const H: f64 = 240.0;
const L: f64 = 70.0;
const R: f64 = 20.0;
const T: f64 = 20.0;
const B: f64 = 30.0;

/// A plot area mapping data to pixels.
pub struct Frame {
    x: (f64, f64),
    y: (f64, f64),
    body: String,
}

fn nice_range(lo: f64, hi: f64) -> (f64, f64) {
    if !(lo.is_finite() && hi.is_finite()) {
        return (0.0, 1.0);
    }
    let span = (hi - lo).abs().max(hi.abs() * 1e-3).max(1e-12);
    (lo - 0.05 * span, hi + 0.05 * span)
}

impl Frame {
    /// A frame over x ∈ `x`, y ∈ `y` (padded by 5 %).
    pub fn new(x: (f64, f64), y: (f64, f64)) -> Frame {
        let x = if x.1 > x.0 { x } else { (x.0 - 1.0, x.0 + 1.0) };
        Frame {
            x,
            y: nice_range(y.0, y.1),
            body: String::new(),
        }
    }

    pub fn sx(&self, x: f64) -> f64 {
        L + (x - self.x.0) / (self.x.1 - self.x.0) * (W - L - R)
    }

    pub fn sy(&self, y: f64) -> f64 {
        let y = y.clamp(self.y.0, self.y.1);
        T + (self.y.1 - y) / (self.y.1 - self.y.0) * (H - T - B)
    }

    /// A horizontal band between `lo` and `hi`.
    pub fn hband(&mut self, lo: f64, hi: f64, fill: &str, label: &str) {
        let (y1, y2) = (self.sy(hi), self.sy(lo));
        let _ = write!(
            self.body,
            r#"<rect x="{L}" y="{y1:.1}" width="{:.1}" height="{:.1}" fill="{fill}"><title>{}</title></rect>"#,
            W - L - R,
            (y2 - y1).max(0.0),
            esc(label)
        );
    }

    /// A horizontal line at `y`.
    pub fn hline(&mut self, y: f64, stroke: &str, dash: bool) {
        let sy = self.sy(y);
        let d = if dash {
            r#" stroke-dasharray="4 3""#
        } else {
            ""
        };
        let _ = write!(
            self.body,
            r#"<line x1="{L}" x2="{:.1}" y1="{sy:.1}" y2="{sy:.1}" stroke="{stroke}"{d}/>"#,
            W - R
        );
    }

    /// A line through the points.
    pub fn polyline(&mut self, pts: &[(f64, f64)], stroke: &str, width: f64, dash: bool) {
        let mut p = String::new();
        for (x, y) in pts.iter().filter(|(x, y)| x.is_finite() && y.is_finite()) {
            let _ = write!(p, "{:.1},{:.1} ", self.sx(*x), self.sy(*y));
        }
        let d = if dash {
            r#" stroke-dasharray="6 4""#
        } else {
            ""
        };
        let _ = write!(
            self.body,
            r#"<polyline points="{p}" fill="none" stroke="{stroke}" stroke-width="{width}"{d}/>"#
        );
    }

    /// A point with its interval as a vertical bar; `label` is its tooltip.
    pub fn point_with_interval(
        &mut self,
        x: f64,
        y: f64,
        lo: f64,
        hi: f64,
        fill: &str,
        label: &str,
    ) {
        let (sx, sy) = (self.sx(x), self.sy(y));
        let _ = write!(
            self.body,
            r#"<g><title>{}</title><line x1="{sx:.1}" x2="{sx:.1}" y1="{:.1}" y2="{:.1}" stroke="{fill}" stroke-width="2"/><circle cx="{sx:.1}" cy="{sy:.1}" r="3.5" fill="{fill}"/></g>"#,
            esc(label),
            self.sy(hi),
            self.sy(lo)
        );
    }

    /// A vertical marker at `x` with a label.
    pub fn vline(&mut self, x: f64, stroke: &str, label: &str) {
        let sx = self.sx(x);
        let _ = write!(
            self.body,
            r#"<line x1="{sx:.1}" x2="{sx:.1}" y1="{T}" y2="{:.1}" stroke="{stroke}" stroke-dasharray="2 2"/><text x="{:.1}" y="{:.1}" font-size="11" fill="{stroke}">{}</text>"#,
            H - B,
            sx + 3.0,
            T + 11.0,
            esc(label)
        );
    }

    /// The finished `<svg>` with axes: `x_labels` are (x, text) ticks; `y_unit` names the axis.
    pub fn finish(
        self,
        title: &str,
        desc: &str,
        x_labels: &[(f64, String)],
        y_unit: &str,
    ) -> String {
        let mut s = String::new();
        let _ = write!(
            s,
            r#"<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {W} {H}" width="{W}" height="{H}" role="img" aria-labelledby="t d"><title>{}</title><desc>{}</desc>"#,
            esc(title),
            esc(desc)
        );
        let _ = write!(
            s,
            r##"<rect x="{L}" y="{T}" width="{:.1}" height="{:.1}" fill="#fff" stroke="#999"/>"##,
            W - L - R,
            H - T - B
        );
        s.push_str(&self.body);
        for k in 0..=4 {
            let y = self.y.0 + (self.y.1 - self.y.0) * f64::from(k) / 4.0;
            let _ = write!(
                s,
                r##"<text x="{:.1}" y="{:.1}" font-size="11" text-anchor="end" fill="#333">{}</text>"##,
                L - 4.0,
                self.sy(y) + 4.0,
                fmt_num(y)
            );
        }
        for (x, label) in x_labels {
            let sx = self.sx(*x);
            let anchor = if sx < L + 40.0 {
                "start"
            } else if sx > W - R - 40.0 {
                "end"
            } else {
                "middle"
            };
            let _ = write!(
                s,
                r##"<text x="{:.1}" y="{:.1}" font-size="11" text-anchor="{anchor}" fill="#333">{}</text>"##,
                sx,
                H - 10.0,
                esc(label)
            );
        }
        let _ = write!(
            s,
            r##"<text x="12" y="{:.1}" font-size="11" fill="#333" transform="rotate(-90 12 {:.1})">{}</text></svg>"##,
            H / 2.0,
            H / 2.0,
            esc(y_unit)
        );
        s
    }
}

/// Four significant digits, no exponent for everyday values.
pub fn fmt_num(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let mag = v.abs().log10().floor() as i32;
    if (-4..5).contains(&mag) {
        let decimals = usize::try_from((3 - mag).max(0)).unwrap_or(0);
        format!("{v:.decimals$}")
    } else {
        format!("{v:.3e}")
    }
}

/// At most `n` evenly spaced indices of `len` samples (the first and last kept).
pub fn thin(len: usize, n: usize) -> Vec<usize> {
    if len <= n || n < 2 {
        return (0..len).collect();
    }
    (0..n).map(|k| k * (len - 1) / (n - 1)).collect()
}

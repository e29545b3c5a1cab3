//! Inline SVG charts for the web pages, drawn with `maud` (no JavaScript, no fonts to load;
//! every value escaped): every chart has `role="img"`, a `<title>` and a `<desc>` that says in
//! words what it shows. Elements are written with explicit end tags: inside `<svg>` the HTML
//! parser closes no element by itself.

use maud::{Markup, html};

use crate::store::Status;

const W: f64 = 720.0;
const H: f64 = 240.0;
const L: f64 = 70.0;
const R: f64 = 20.0;
const T: f64 = 20.0;
const B: f64 = 30.0;

/// A pixel coordinate as written into the SVG.
fn px(v: f64) -> String {
    format!("{v:.1}")
}

/// A plot area mapping data to pixels.
pub struct Frame {
    x: (f64, f64),
    y: (f64, f64),
    body: Vec<Markup>,
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
            body: Vec::new(),
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
        self.body.push(html! {
            rect x=(L) y=(px(y1)) width=(px(W - L - R)) height=(px((y2 - y1).max(0.0))) fill=(fill) {
                title { (label) }
            }
        });
    }

    /// A horizontal line at `y`.
    pub fn hline(&mut self, y: f64, stroke: &str, dash: bool) {
        let sy = px(self.sy(y));
        self.body.push(html! {
            line x1=(L) x2=(px(W - R)) y1=(sy) y2=(sy) stroke=(stroke)
                stroke-dasharray=[dash.then_some("4 3")] {}
        });
    }

    /// A line through the points.
    pub fn polyline(&mut self, pts: &[(f64, f64)], stroke: &str, width: f64, dash: bool) {
        let points: Vec<String> = pts
            .iter()
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .map(|(x, y)| format!("{},{}", px(self.sx(*x)), px(self.sy(*y))))
            .collect();
        self.body.push(html! {
            polyline points=(points.join(" ")) fill="none" stroke=(stroke) stroke-width=(width)
                stroke-dasharray=[dash.then_some("6 4")] {}
        });
    }

    /// A band between two curves over the same x (`lower` and `upper` as (x, y) points), filled.
    pub fn band(&mut self, lower: &[(f64, f64)], upper: &[(f64, f64)], fill: &str, label: &str) {
        let points: Vec<String> = lower
            .iter()
            .chain(upper.iter().rev())
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .map(|(x, y)| format!("{},{}", px(self.sx(*x)), px(self.sy(*y))))
            .collect();
        self.body.push(html! {
            polygon points=(points.join(" ")) fill=(fill) stroke="none" {
                title { (label) }
            }
        });
    }

    /// One test's value with its interval as a vertical bar, coloured by `status` through the
    /// status's class (the badges' class); `trace_id` names the test, `label` is the tooltip.
    pub fn point(
        &mut self,
        (x, y, lo, hi): (f64, f64, f64, f64),
        status: Status,
        trace_id: &str,
        label: &str,
    ) {
        let (sx, sy) = (px(self.sx(x)), px(self.sy(y)));
        self.body.push(html! {
            g.pt.(status.as_str()) data-trace=(trace_id) {
                title { (label) }
                line x1=(sx) x2=(sx) y1=(px(self.sy(hi))) y2=(px(self.sy(lo))) stroke-width="2" {}
                circle cx=(sx) cy=(sy) r="3.5" {}
            }
        });
    }

    /// One measured reading at (`x`, `y`) in the group class `class` (a page tells the series
    /// apart by it): a filled circle, or with `open` a hollow square, so the series differ in
    /// shape as well as colour; `label` is its tooltip.
    pub fn marker(
        &mut self,
        (x, y): (f64, f64),
        class: &str,
        color: &str,
        open: bool,
        label: &str,
    ) {
        if !(x.is_finite() && y.is_finite()) {
            return;
        }
        let (sx, sy) = (self.sx(x), self.sy(y));
        self.body.push(html! {
            g class=(class) {
                title { (label) }
                @if open {
                    rect x=(px(sx - 3.5)) y=(px(sy - 3.5)) width="7" height="7" fill="#fff"
                        stroke=(color) stroke-width="1.5" {}
                } @else {
                    circle cx=(px(sx)) cy=(px(sy)) r="3.5" fill=(color) {}
                }
            }
        });
    }

    /// A vertical marker at `x` with a label.
    pub fn vline(&mut self, x: f64, stroke: &str, label: &str) {
        let sx = self.sx(x);
        self.body.push(html! {
            line x1=(px(sx)) x2=(px(sx)) y1=(T) y2=(px(H - B)) stroke=(stroke) stroke-dasharray="2 2" {}
            text x=(px(sx + 3.0)) y=(px(T + 11.0)) font-size="11" fill=(stroke) { (label) }
        });
    }

    /// The finished `<svg>` with axes: `x_labels` are (x, text) ticks; `y_unit` names the axis.
    pub fn finish(
        self,
        title: &str,
        desc: &str,
        x_labels: &[(f64, String)],
        y_unit: &str,
    ) -> Markup {
        let y_ticks: Vec<(f64, f64)> = (0..=4)
            .map(|k| {
                let y = self.y.0 + (self.y.1 - self.y.0) * f64::from(k) / 4.0;
                (self.sy(y) + 4.0, y)
            })
            .collect();
        let x_ticks: Vec<(f64, &str, &str)> = x_labels
            .iter()
            .map(|(x, label)| {
                let sx = self.sx(*x);
                let anchor = if sx < L + 40.0 {
                    "start"
                } else if sx > W - R - 40.0 {
                    "end"
                } else {
                    "middle"
                };
                (sx, anchor, label.as_str())
            })
            .collect();
        html! {
            svg xmlns="http://www.w3.org/2000/svg" viewBox={ "0 0 " (W) " " (H) } width=(W) height=(H)
                role="img" {
                title { (title) }
                desc { (desc) }
                rect x=(L) y=(T) width=(px(W - L - R)) height=(px(H - T - B)) fill="#fff" stroke="#999" {}
                @for m in &self.body { (m) }
                @for (sy, y) in &y_ticks {
                    text x=(px(L - 4.0)) y=(px(*sy)) font-size="11" text-anchor="end" fill="#333" { (fmt_num(*y)) }
                }
                @for (sx, anchor, label) in &x_ticks {
                    text x=(px(*sx)) y=(px(H - 10.0)) font-size="11" text-anchor=(anchor) fill="#333" { (label) }
                }
                text x="12" y=(px(H / 2.0)) font-size="11" fill="#333"
                    transform={ "rotate(-90 12 " (px(H / 2.0)) ")" } { (y_unit) }
            }
        }
    }
}

/// A legend entry outside the plot: a small swatch drawn as the chart draws the series, then
/// `text`. `swatch` is `line:<colour>`, `dash:<colour>`, `band:<colour>`, `dot:<colour>` (a
/// filled circle, as [`Frame::marker`]) or `square:<colour>` (its hollow square).
pub fn legend_entry(swatch: &str, text: &str) -> Markup {
    let (kind, color) = swatch.split_once(':').unwrap_or(("line", swatch));
    html! {
        span.legend-entry {
            svg xmlns="http://www.w3.org/2000/svg" width="18" height="10" viewBox="0 0 18 10"
                aria-hidden="true" {
                @match kind {
                    "dot" => { circle cx="9" cy="5" r="3.5" fill=(color) {} },
                    "square" => {
                        rect x="5.5" y="1.5" width="7" height="7" fill="#fff" stroke=(color)
                            stroke-width="1.5" {}
                    },
                    "band" => { rect x="0" y="1" width="18" height="8" fill=(color) {} },
                    _ => {
                        line x1="0" x2="18" y1="5" y2="5" stroke=(color) stroke-width="2"
                            stroke-dasharray=[(kind == "dash").then_some("6 4")] {}
                    },
                }
            }
            " " (text)
        }
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

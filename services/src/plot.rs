//! SVG plots for people: measured vs fitted motion and the residual, one file per fit.

use plotters::prelude::*;

/// A named series over time.
pub struct Series<'a> {
    pub name: &'a str,
    pub y: &'a [f64],
    pub color: RGBColor,
}

fn range(ys: &[&[f64]]) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for y in ys {
        for v in y.iter().filter(|v| v.is_finite()) {
            lo = lo.min(*v);
            hi = hi.max(*v);
        }
    }
    if !(lo.is_finite() && hi.is_finite()) {
        return (-1.0, 1.0);
    }
    let pad = ((hi - lo) * 0.05).max(1e-9);
    (lo - pad, hi + pad)
}

/// Upper panel: the series over `t`; lower panel: the residual series. Returns the SVG text.
pub fn fit_svg(
    title: &str,
    t: &[f64],
    unit: &str,
    top: &[Series],
    bottom: &[Series],
) -> Result<String, String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1100, 700)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let (up, down) = root.split_vertically(450);
        let (t0, t1) = (
            t.first().copied().unwrap_or(0.0),
            t.last().copied().unwrap_or(1.0),
        );
        for (area, series, caption, ylabel) in [
            (up, top, title.to_string(), unit.to_string()),
            (
                down,
                bottom,
                "residual (model − measured)".to_string(),
                unit.to_string(),
            ),
        ] {
            let ys: Vec<&[f64]> = series.iter().map(|s| s.y).collect();
            let (lo, hi) = range(&ys);
            let mut chart = ChartBuilder::on(&area)
                .caption(caption, ("sans-serif", 20))
                .margin(10)
                .x_label_area_size(35)
                .y_label_area_size(60)
                .build_cartesian_2d(t0..t1, lo..hi)
                .map_err(|e| e.to_string())?;
            chart
                .configure_mesh()
                .x_desc("t [s]")
                .y_desc(ylabel)
                .draw()
                .map_err(|e| e.to_string())?;
            for s in series {
                let color = s.color;
                chart
                    .draw_series(LineSeries::new(
                        t.iter().zip(s.y).map(|(a, b)| (*a, *b)),
                        color.stroke_width(1),
                    ))
                    .map_err(|e| e.to_string())?
                    .label(s.name)
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color));
            }
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()
                .map_err(|e| e.to_string())?;
        }
        root.present().map_err(|e| e.to_string())?;
    }
    Ok(svg)
}

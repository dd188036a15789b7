//! Learning curves from a run's metrics.csv as SVG: success rate against env steps and against training wall
//! time (rollout and learning, summed over resumes), and mean episode return against env steps.

use std::path::Path;

use crate::error::{Result, RlError};

/// One row of metrics.csv that the plot reads.
#[derive(Clone, Copy, Debug)]
pub struct CurvePoint {
    /// Env steps so far.
    pub env_steps: f64,
    /// Training wall time so far [s].
    pub wall_seconds: f64,
    /// Success rate of the episodes that ended in the update (NaN when none).
    pub success_rate: f64,
    /// Their mean return (NaN when none).
    pub mean_return: f64,
}

/// Reads the columns the plot needs from metrics.csv.
pub fn read_metrics(path: &Path) -> Result<Vec<CurvePoint>> {
    let text = std::fs::read_to_string(path).map_err(|e| RlError::io(path, e))?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap_or_default().split(',').collect();
    let col = |name: &str| {
        header.iter().position(|h| *h == name).ok_or_else(|| RlError::BadFile {
            path: path.into(),
            reason: format!("no `{name}` column (header: {})", header.join(",")),
        })
    };
    let (s, w, r, m) = (col("env_steps")?, col("wall_seconds")?, col("success_rate")?, col("mean_return")?);
    let mut out = Vec::new();
    for (i, line) in lines.enumerate() {
        let f: Vec<&str> = line.split(',').collect();
        let get = |k: usize| -> Result<f64> {
            f.get(k).and_then(|x| x.parse::<f64>().ok()).ok_or_else(|| RlError::BadFile {
                path: path.into(),
                reason: format!("row {}: column {k} is not a number", i + 2),
            })
        };
        out.push(CurvePoint { env_steps: get(s)?, wall_seconds: get(w)?, success_rate: get(r)?, mean_return: get(m)? });
    }
    Ok(out)
}

/// Means over windows of `k` updates, skipping NaN (updates in which no episode ended).
pub fn smooth(points: &[CurvePoint], k: usize) -> Vec<CurvePoint> {
    points
        .chunks(k.max(1))
        .filter_map(|c| {
            let mean = |f: &dyn Fn(&CurvePoint) -> f64| {
                let v: Vec<f64> = c.iter().map(f).filter(|x| x.is_finite()).collect();
                (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
            };
            let last = c.last()?;
            Some(CurvePoint {
                env_steps: last.env_steps,
                wall_seconds: last.wall_seconds,
                success_rate: mean(&|p| p.success_rate).unwrap_or(f64::NAN),
                mean_return: mean(&|p| p.mean_return).unwrap_or(f64::NAN),
            })
        })
        .collect()
}

fn plot_err<E: std::fmt::Display>(e: E) -> RlError {
    RlError::BadFile { path: "plot".into(), reason: e.to_string() }
}

/// Three panels: success rate against env steps and against training wall time (sample
/// efficiency and wall-clock cost), and the mean episode return against env steps.
pub fn plot_svg(points: &[CurvePoint], title: &str) -> Result<String> {
    use plotters::prelude::*;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1500, 480)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        let root = root.titled(title, ("sans-serif", 20)).map_err(plot_err)?;
        let panels = root.split_evenly((1, 3));
        let steps = |p: &CurvePoint| p.env_steps;
        let hours = |p: &CurvePoint| p.wall_seconds / 3600.0;
        let millions = |v: &f64| format!("{:.2}M", v / 1e6);
        let plain = |v: &f64| format!("{v:.1}");
        type Axis<'a> = (&'a str, &'a dyn Fn(&CurvePoint) -> f64, &'a dyn Fn(&f64) -> String);
        let by_steps: Axis = ("env steps", &steps, &millions);
        let by_hours: Axis = ("training wall time [h]", &hours, &plain);
        // A rate is drawn on [0, 1] so that runs compare at a glance; a return on the range of its data.
        let rate = Some((0.0, 1.0));
        let series: [(&str, &str, fn(&CurvePoint) -> f64, Option<(f64, f64)>, Axis); 3] = [
            ("success rate of the episodes ended per update", "success rate", |p| p.success_rate, rate, by_steps),
            ("the same against wall time", "success rate", |p| p.success_rate, rate, by_hours),
            ("mean episode return", "return", |p| p.mean_return, None, by_steps),
        ];
        for (area, (caption, y_desc, f, y_fixed, (x_desc, x_of, x_fmt))) in panels.iter().zip(series) {
            let x1 = points.iter().map(x_of).fold(f64::MIN_POSITIVE, f64::max);
            let ys: Vec<(f64, f64)> = points.iter().map(|p| (x_of(p), f(p))).filter(|(_, y)| y.is_finite()).collect();
            let (y0, y1) = y_fixed.unwrap_or_else(|| {
                let (lo, hi) = ys.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| (a.min(p.1), b.max(p.1)));
                if lo.is_finite() && hi > lo {
                    (lo, hi)
                } else {
                    (lo.min(0.0) - 1.0, hi.max(0.0) + 1.0)
                }
            });
            let mut chart = ChartBuilder::on(area)
                .caption(caption, ("sans-serif", 15))
                .margin(12)
                .x_label_area_size(45)
                .y_label_area_size(60)
                .build_cartesian_2d(0.0..x1, y0..y1)
                .map_err(plot_err)?;
            chart
                .configure_mesh()
                .x_desc(x_desc)
                .y_desc(y_desc)
                .x_label_formatter(x_fmt)
                .label_style(("sans-serif", 12))
                .draw()
                .map_err(plot_err)?;
            chart.draw_series(LineSeries::new(ys, RGBColor(31, 119, 180).stroke_width(2))).map_err(plot_err)?;
        }
        root.present().map_err(plot_err)?;
    }
    Ok(svg)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn smooth_skips_updates_without_episodes() {
        let p = |s: f64, r: f64| CurvePoint { env_steps: s, wall_seconds: s, success_rate: r, mean_return: -r };
        let out = smooth(&[p(1.0, f64::NAN), p(2.0, 0.5), p(3.0, 1.0), p(4.0, f64::NAN)], 2);
        assert_eq!(out.len(), 2);
        assert_eq!(out[0].success_rate, 0.5);
        assert_eq!(out[1].success_rate, 1.0);
        assert_eq!(out[1].env_steps, 4.0);
        let svg = plot_svg(&out, "t").unwrap();
        assert!(svg.contains("<svg") && svg.contains("success rate"));
        assert!(svg.contains("training wall time [h]"), "the success curve against wall time is drawn");
    }
}

//! `factory-bench pareto --scene nut-bolt`: the speed-against-error report (docs/ARCHITECTURE.md section 10).
//!
//! Each point runs the M16 nut-bolt scene ([`crate::scene::run_nut_bolt`]: contacts + GPU solver per
//! frame) frictionless (mu 0) for a fixed simulated time, and compares the nut's descent with the analytic
//! frictionless descent g m / (m + I (2 pi / p)^2) t^2 / 2. The sweep varies one axis at a time around the
//! paper's baseline (dt 1/60 s, 1 substep, 20 position and 1 velocity iteration, 64 patches, analytic bolt
//! SDF): bolt SDF (analytic or grid resolutions), patch budget, substeps, position iterations. It is not
//! the Cartesian product.
//!
//! Figures per point (all in the CSV):
//! - descent error: |descent - analytic| / analytic (plotted by default; the CSV also has it signed);
//! - lead error: |descent / |turns| - pitch| / pitch (does the nut follow its thread);
//! - max penetration [mm]: the deepest contact seen at any frame start (plotted by default);
//! - wall time per simulated second: wall_s / simulated s (all worlds of the run together), and per
//!   pair-second (divided by the worlds as well).
//!
//! Points a software adapter refuses (`GpuSolver::new` and llvmpipe's per-invocation loop budget) are
//! recorded as `refused` instead of failing the sweep; runs that blow up are `unstable`; both are left out
//! of the Pareto front and the plot.

use crate::scene::{run_nut_bolt, NutBoltReport, NutBoltRun};
use anyhow::{ensure, Result};
use factory_assets::{Fit, IsoSize, ThreadOptions};
use factory_engine::contact::ContactConfig;
use factory_engine::gpu::GpuContext;
use factory_engine::solver::SolverConfig;
use factory_engine::EngineError;
use std::borrow::Cow;
use std::path::PathBuf;

/// The swept axis a point belongs to (the baseline belongs to all of them).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Axis {
    Baseline,
    Sdf,
    Patches,
    Substeps,
    PosIters,
}

impl Axis {
    pub fn name(self) -> &'static str {
        match self {
            Axis::Baseline => "baseline",
            Axis::Sdf => "sdf",
            Axis::Patches => "patches",
            Axis::Substeps => "substeps",
            Axis::PosIters => "pos_iters",
        }
    }

    /// Legend text of the axis.
    fn legend(self) -> &'static str {
        match self {
            Axis::Baseline => "baseline (paper: analytic SDF, 64 patches, 1 substep, 20 iters)",
            Axis::Sdf => "bolt SDF (grid resolution)",
            Axis::Patches => "patch budget",
            Axis::Substeps => "substeps",
            Axis::PosIters => "position iterations",
        }
    }

    const ALL: [Axis; 5] = [Axis::Baseline, Axis::Sdf, Axis::Patches, Axis::Substeps, Axis::PosIters];
}

/// One point of the sweep.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Setting {
    pub axis: Axis,
    /// `None`: analytic bolt SDF; `Some(r)`: grid of resolution r.
    pub sdf: Option<u32>,
    pub patches: u32,
    pub substeps: u32,
    pub pos_iters: u32,
}

impl Setting {
    /// Short text for the CSV and the plot's point labels.
    pub fn sdf_name(&self) -> String {
        self.sdf.map_or("analytic".into(), |r| format!("grid {r}"))
    }

    fn label(&self) -> String {
        match self.axis {
            Axis::Baseline => "baseline".into(),
            Axis::Sdf => self.sdf_name(),
            Axis::Patches => format!("{} patches", self.patches),
            Axis::Substeps => format!("{} substeps", self.substeps),
            Axis::PosIters => format!("{} iters", self.pos_iters),
        }
    }
}

/// The baseline first, then each axis's values other than the baseline's (one axis varied at a time);
/// repeated values are dropped.
pub fn sweep_settings(
    base: Setting,
    sdfs: &[Option<u32>],
    patches: &[u32],
    substeps: &[u32],
    pos_iters: &[u32],
) -> Vec<Setting> {
    let base = Setting { axis: Axis::Baseline, ..base };
    let mut out = vec![base];
    let mut push = |s: Setting| {
        let same =
            |o: &Setting| (o.sdf, o.patches, o.substeps, o.pos_iters) == (s.sdf, s.patches, s.substeps, s.pos_iters);
        if !out.iter().any(same) {
            out.push(s);
        }
    };
    for &sdf in sdfs {
        push(Setting { axis: Axis::Sdf, sdf, ..base });
    }
    for &patches in patches {
        push(Setting { axis: Axis::Patches, patches, ..base });
    }
    for &substeps in substeps {
        push(Setting { axis: Axis::Substeps, substeps, ..base });
    }
    for &pos_iters in pos_iters {
        push(Setting { axis: Axis::PosIters, pos_iters, ..base });
    }
    out
}

/// Parses `analytic` or a grid resolution.
pub fn parse_sdf(s: &str) -> Result<Option<u32>> {
    match s.trim() {
        "analytic" => Ok(None),
        r => Ok(Some(r.parse::<u32>().map_err(|_| {
            anyhow::anyhow!("SDF {r:?}: valid values are `analytic` or a grid resolution such as 256")
        })?)),
    }
}

/// How a point ended.
#[derive(Clone, Debug, PartialEq)]
pub enum Status {
    Ok,
    /// The adapter cannot run these settings (the message says why).
    Refused(String),
    /// The run did not stay finite / below the solver's speed bound.
    Unstable,
    /// Any other failure (the message).
    Error(String),
}

impl Status {
    fn name(&self) -> &'static str {
        match self {
            Status::Ok => "ok",
            Status::Refused(_) => "refused",
            Status::Unstable => "unstable",
            Status::Error(_) => "error",
        }
    }

    fn note(&self) -> &str {
        match self {
            Status::Refused(m) | Status::Error(m) => m,
            _ => "",
        }
    }
}

/// Which error the plot (and `on_front`) uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ErrorMetric {
    /// Relative descent error against the analytic frictionless descent.
    Descent,
    /// Relative error of the descent per turn against the pitch.
    Lead,
    /// Max penetration [mm].
    Penetration,
}

impl ErrorMetric {
    pub fn parse(s: &str) -> Result<Self> {
        match s {
            "descent" => Ok(Self::Descent),
            "lead" => Ok(Self::Lead),
            "penetration" => Ok(Self::Penetration),
            _ => anyhow::bail!("error metric {s:?}: valid values are descent, lead, penetration"),
        }
    }

    fn title(self) -> &'static str {
        match self {
            ErrorMetric::Descent => "descent vs the analytic frictionless descent",
            ErrorMetric::Lead => "descent per turn vs the thread pitch",
            ErrorMetric::Penetration => "deepest penetration seen",
        }
    }

    fn axis_desc(self) -> &'static str {
        match self {
            ErrorMetric::Descent => "descent error |d - d_analytic| / d_analytic (frictionless)",
            ErrorMetric::Lead => "lead error |d / turns - pitch| / pitch",
            ErrorMetric::Penetration => "max penetration [mm]",
        }
    }
}

/// One measured point.
#[derive(Clone, Debug)]
pub struct PointResult {
    pub setting: Setting,
    pub status: Status,
    /// The run's report (absent when refused or failed); `wall_s` is the minimum over the repeats.
    pub report: Option<NutBoltReport>,
    pub repeats: u32,
}

impl PointResult {
    /// Wall seconds per simulated second (all worlds together).
    pub fn wall_per_sim_s(&self) -> Option<f64> {
        self.report.as_ref().map(|r| r.wall_s / r.seconds as f64)
    }

    pub fn descent_err(&self) -> Option<f64> {
        self.report.as_ref().map(|r| (r.nut_descent_mm - r.analytic_descent_mm).abs() / r.analytic_descent_mm)
    }

    pub fn lead_mm(&self) -> Option<f64> {
        self.report.as_ref().map(|r| r.nut_descent_mm / r.nut_turns.abs())
    }

    pub fn lead_err(&self) -> Option<f64> {
        let r = self.report.as_ref()?;
        Some((self.lead_mm()? - r.pitch_mm as f64).abs() / r.pitch_mm as f64)
    }

    pub fn error(&self, m: ErrorMetric) -> Option<f64> {
        match m {
            ErrorMetric::Descent => self.descent_err(),
            ErrorMetric::Lead => self.lead_err(),
            ErrorMetric::Penetration => self.report.as_ref().map(|r| r.max_penetration_mm),
        }
    }

    /// Point usable for the front and the plot: ok, with finite time and error.
    fn xy(&self, m: ErrorMetric) -> Option<(f64, f64)> {
        if self.status != Status::Ok {
            return None;
        }
        let (x, y) = (self.wall_per_sim_s()?, self.error(m)?);
        (x.is_finite() && y.is_finite()).then_some((x, y))
    }
}

/// Pareto front of points to minimise in both coordinates: `true` where no other point is at least as
/// good in both and strictly better in one. `None` (and NaN) points are never on the front and dominate
/// nothing; equal points are both on the front.
pub fn pareto_front(points: &[Option<(f64, f64)>]) -> Vec<bool> {
    let valid = |p: &Option<(f64, f64)>| p.filter(|(x, y)| !x.is_nan() && !y.is_nan());
    points
        .iter()
        .map(|p| {
            let Some((x, y)) = valid(p) else { return false };
            !points.iter().filter_map(valid).any(|(ox, oy)| ox <= x && oy <= y && (ox < x || oy < y))
        })
        .collect()
}

/// One CSV field (RFC 4180): quoted when it holds a comma, a quote, CR or LF, or leading/trailing
/// spaces; quotes inside are doubled.
pub fn csv_field(s: &str) -> Cow<'_, str> {
    if s.contains([',', '"', '\n', '\r']) || s.trim() != s {
        Cow::Owned(format!("\"{}\"", s.replace('"', "\"\"")))
    } else {
        Cow::Borrowed(s)
    }
}

/// One CSV record ending in `\n`.
pub fn csv_record<S: AsRef<str>>(fields: &[S]) -> String {
    let mut line = fields.iter().map(|f| csv_field(f.as_ref())).collect::<Vec<_>>().join(",");
    line.push('\n');
    line
}

/// CSV header: names with units.
pub const CSV_HEADER: [&str; 28] = [
    "point",
    "axis",
    "label",
    "status",
    "sdf",
    "max_patches",
    "substeps",
    "pos_iters",
    "vel_iters",
    "dt_s",
    "worlds",
    "mu",
    "sim_s",
    "frames",
    "repeats",
    "wall_s_min",
    "wall_s_per_sim_s",
    "wall_s_per_pair_s",
    "ms_per_frame",
    "descent_mm",
    "analytic_descent_mm",
    "descent_rel_err",
    "descent_signed_rel_err",
    "nut_turns",
    "lead_mm_per_turn",
    "lead_rel_err",
    "max_penetration_mm",
    "front",
];

/// The sweep as CSV: the header, then one record per point. `status` is `ok`, `unstable`, or
/// `refused: <why>` / `error: <why>`; `front` lists the error metrics on whose Pareto front (against
/// `wall_s_per_sim_s`) the point lies: `descent`, `lead`, `penetration`, joined by `+`.
pub fn to_csv(results: &[PointResult], solver: &SolverConfig, worlds: u32) -> String {
    let metrics = [ErrorMetric::Descent, ErrorMetric::Lead, ErrorMetric::Penetration];
    let fronts: Vec<Vec<bool>> =
        metrics.iter().map(|&m| pareto_front(&results.iter().map(|p| p.xy(m)).collect::<Vec<_>>())).collect();
    let mut out = csv_record(&CSV_HEADER);
    let f = |v: Option<f64>, prec: usize| v.filter(|v| v.is_finite()).map_or(String::new(), |v| format!("{v:.prec$}"));
    for (i, p) in results.iter().enumerate() {
        let s = &p.setting;
        let r = p.report.as_ref();
        let front: Vec<&str> =
            ["descent", "lead", "penetration"].iter().zip(&fronts).filter(|(_, fr)| fr[i]).map(|(n, _)| *n).collect();
        let status = match p.status.note() {
            "" => p.status.name().to_string(),
            note => format!("{}: {note}", p.status.name()),
        };
        let rec = [
            i.to_string(),
            s.axis.name().into(),
            s.label(),
            status,
            s.sdf_name(),
            s.patches.to_string(),
            s.substeps.to_string(),
            s.pos_iters.to_string(),
            solver.vel_iters.to_string(),
            format!("{:.6}", solver.dt),
            worlds.to_string(),
            "0".into(),
            f(r.map(|r| r.seconds as f64), 4),
            r.map_or(String::new(), |r| r.frames.to_string()),
            p.repeats.to_string(),
            f(r.map(|r| r.wall_s), 4),
            f(p.wall_per_sim_s(), 4),
            f(p.wall_per_sim_s().map(|w| w / worlds as f64), 4),
            f(r.map(|r| r.ms_per_frame), 2),
            f(r.map(|r| r.nut_descent_mm), 5),
            f(r.map(|r| r.analytic_descent_mm), 5),
            f(p.descent_err(), 5),
            f(r.map(|r| (r.nut_descent_mm - r.analytic_descent_mm) / r.analytic_descent_mm), 5),
            f(r.map(|r| r.nut_turns), 4),
            f(p.lead_mm(), 5),
            f(p.lead_err(), 5),
            f(r.map(|r| r.max_penetration_mm), 5),
            front.join("+"),
        ];
        out.push_str(&csv_record(&rec));
    }
    out
}

fn axis_color(a: Axis) -> plotters::style::RGBColor {
    use plotters::style::RGBColor;
    match a {
        Axis::Baseline => RGBColor(0, 0, 0),
        Axis::Sdf => RGBColor(214, 39, 40),
        Axis::Patches => RGBColor(31, 119, 180),
        Axis::Substeps => RGBColor(44, 160, 44),
        Axis::PosIters => RGBColor(148, 103, 189),
    }
}

/// The plot as an SVG document: one panel per error metric, error against wall time per simulated second,
/// log-log, points coloured by swept axis and labelled with their value, the Pareto front of each panel as
/// a staircase with rings.
pub fn plot_svg(results: &[PointResult], metrics: &[ErrorMetric], title: &str, footnote: &str) -> Result<String> {
    use plotters::prelude::*;
    ensure!(!metrics.is_empty(), "no error metric to plot");
    let (panel_w, h) = (760u32, 720u32);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (panel_w * metrics.len() as u32, h + 40)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        let (top, foot_area) = root.split_vertically(h);
        let top = top.titled(title, ("sans-serif", 22)).map_err(plot_err)?;
        let panels = top.split_evenly((1, metrics.len()));
        for (n, (&metric, area)) in metrics.iter().zip(&panels).enumerate() {
            draw_panel(area, results, metric, n == 0)?;
        }
        foot_area
            .draw(&Text::new(
                footnote.to_string(),
                (20, 12),
                ("sans-serif", 13).into_font().color(&RGBColor(80, 80, 80)),
            ))
            .map_err(plot_err)?;
        root.present().map_err(plot_err)?;
    }
    Ok(svg)
}

fn draw_panel<DB: plotters::prelude::DrawingBackend>(
    area: &plotters::prelude::DrawingArea<DB, plotters::coord::Shift>,
    results: &[PointResult],
    metric: ErrorMetric,
    legend: bool,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    use plotters::prelude::*;
    let pts: Vec<Option<(f64, f64)>> = results.iter().map(|p| p.xy(metric)).collect();
    let front = pareto_front(&pts);
    // Log axes: errors of exactly 0 are drawn at the floor.
    let floor = 1e-6;
    let xy: Vec<(usize, (f64, f64))> =
        pts.iter().enumerate().filter_map(|(i, p)| p.map(|(x, y)| (i, (x, y.max(floor))))).collect();
    ensure!(!xy.is_empty(), "no point of the sweep finished: nothing to plot");
    let (mut x0, mut x1, mut y0, mut y1) = (f64::INFINITY, 0.0f64, f64::INFINITY, 0.0f64);
    for &(_, (x, y)) in &xy {
        (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
    }
    // Room on the right for the point labels and above for the legend.
    let (x0, x1, xb) = log_axis(x0 / 1.1, x1 * 1.5);
    let (y0, y1, yb) = log_axis(y0 / 1.4, y1 * if legend { 6.0 } else { 1.6 });
    let mut chart = ChartBuilder::on(area)
        .caption(metric.title(), ("sans-serif", 17))
        .margin(14)
        .x_label_area_size(50)
        .y_label_area_size(75)
        .build_cartesian_2d((x0..x1).log_scale().base(xb), (y0..y1).log_scale().base(yb))
        .map_err(plot_err)?;
    chart
        .configure_mesh()
        .x_desc("wall time per simulated second [s/s] (lower = faster)")
        .y_desc(metric.axis_desc())
        .x_label_formatter(&|v| format!("{}", (v * 1e3).round() / 1e3))
        .y_label_formatter(&|v| format!("{v:.1e}"))
        .x_labels(5)
        .y_labels(6)
        .max_light_lines(4)
        .label_style(("sans-serif", 13))
        .axis_desc_style(("sans-serif", 14))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()
        .map_err(plot_err)?;
    // Front: staircase through the front points sorted by time.
    let mut fr: Vec<(f64, f64)> = xy.iter().filter(|(i, _)| front[*i]).map(|&(_, p)| p).collect();
    fr.sort_by(|a, b| a.0.total_cmp(&b.0).then(b.1.total_cmp(&a.1)));
    let mut stair = Vec::new();
    for (k, &(x, y)) in fr.iter().enumerate() {
        if k > 0 {
            stair.push((x, fr[k - 1].1));
        }
        stair.push((x, y));
    }
    let front_style = RGBColor(255, 127, 14);
    chart
        .draw_series(LineSeries::new(stair, front_style.stroke_width(2)))
        .map_err(plot_err)?
        .label("Pareto front (ringed)")
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], front_style.stroke_width(2)));
    chart.draw_series(fr.iter().map(|&p| Circle::new(p, 10, front_style.stroke_width(2)))).map_err(plot_err)?;
    let labels = place_labels(
        &xy.iter().map(|&(i, p)| (chart.backend_coord(&p), results[i].setting.label())).collect::<Vec<_>>(),
        chart.plotting_area().get_pixel_range(),
        legend,
    );
    for axis in Axis::ALL {
        let c = axis_color(axis);
        let mine: Vec<_> = xy
            .iter()
            .zip(&labels)
            .filter(|((i, _), _)| results[*i].setting.axis == axis)
            .map(|(&(i, p), &off)| (i, p, off))
            .collect();
        if mine.is_empty() {
            continue;
        }
        chart
            .draw_series(mine.iter().map(|&(i, p, off)| {
                EmptyElement::at(p)
                    + Circle::new((0, 0), 5, c.filled())
                    + Text::new(results[i].setting.label(), off, ("sans-serif", 13).into_font().color(&c))
            }))
            .map_err(plot_err)?
            .label(axis.legend())
            .legend(move |(x, y)| Circle::new((x + 10, y), 5, c.filled()));
    }
    if legend {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .label_font(("sans-serif", 12))
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(180, 180, 180))
            .draw()
            .map_err(plot_err)?;
    }
    Ok(())
}

/// Offsets (pixels, text top-left relative to its point) for point labels: the first of a few spots
/// around each point that overlaps no label placed before, no other point and not the legend (upper
/// left), else the first spot. Text size is estimated for a 13 px sans-serif font.
fn place_labels(
    points: &[((i32, i32), String)],
    area: (std::ops::Range<i32>, std::ops::Range<i32>),
    legend: bool,
) -> Vec<(i32, i32)> {
    type Box2 = (i32, i32, i32, i32);
    let overlaps = |a: &Box2, b: &Box2| a.0 < b.2 && b.0 < a.2 && a.1 < b.3 && b.1 < a.3;
    let (xr, yr) = area;
    let mut taken: Vec<Box2> = points.iter().map(|&((x, y), _)| (x - 6, y - 6, x + 6, y + 6)).collect();
    if legend {
        taken.push((xr.start, yr.start, xr.start + 450, yr.start + 120));
    }
    points
        .iter()
        .map(|&((x, y), ref text)| {
            let (w, h) = (7 * text.chars().count() as i32, 14);
            let spots = [(9, -16), (9, 3), (-9 - w, -16), (-9 - w, 3), (9, -30), (9, 17), (-9 - w, -30), (-9 - w, 17)];
            let inside = |b: &Box2| b.0 >= xr.start && b.2 <= xr.end && b.1 >= yr.start && b.3 <= yr.end;
            let own = (x - 6, y - 6, x + 6, y + 6);
            let pick = spots
                .iter()
                .copied()
                .find(|&(dx, dy)| {
                    let b = (x + dx, y + dy, x + dx + w, y + dy + h);
                    inside(&b) && !taken.iter().any(|t| *t != own && overlaps(t, &b))
                })
                .unwrap_or(spots[0]);
            taken.push((x + pick.0, y + pick.1, x + pick.0 + w, y + pick.1 + h));
            pick
        })
        .collect()
}

/// A log axis covering `lo`..`hi` (both > 0): (start, end, base). Base 10 over two decades or more (then
/// at least two powers of 10 lie inside, which plotters labels), else base 2, widened to powers of 2.
fn log_axis(lo: f64, hi: f64) -> (f64, f64, f64) {
    if hi / lo >= 100.0 {
        return (lo, hi, 10.0);
    }
    (2f64.powf(lo.log2().floor()), 2f64.powf(hi.log2().ceil()), 2.0)
}

fn plot_err<E: std::fmt::Display>(e: E) -> anyhow::Error {
    anyhow::anyhow!("drawing the plot: {e}")
}

/// Whether `e` is the solver's refusal of settings beyond a software adapter's loop budget.
fn is_budget_refusal(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        matches!(c.downcast_ref::<EngineError>(),
            Some(EngineError::Config { expected, .. }) if expected.contains("loop limit"))
    })
}

/// Settings of a sweep.
#[derive(Clone, Debug)]
pub struct ParetoArgs {
    pub size: IsoSize,
    pub fit: Fit,
    pub worlds: u32,
    pub seconds: f32,
    pub dt: f32,
    pub vel_iters: u32,
    pub base: Setting,
    pub sdfs: Vec<Option<u32>>,
    pub patches: Vec<u32>,
    pub substeps: Vec<u32>,
    pub pos_iters: Vec<u32>,
    /// Runs per point; the minimum wall time is kept (the machine is shared).
    pub repeats: u32,
    /// Errors plotted, one panel each (all three are in the CSV).
    pub metrics: Vec<ErrorMetric>,
    pub out_csv: PathBuf,
    pub out_plot: PathBuf,
}

/// Runs one point once.
pub fn run_point(gpu: &GpuContext, a: &ParetoArgs, s: Setting) -> PointResult {
    let run = NutBoltRun {
        size: a.size,
        fit: a.fit,
        worlds: a.worlds,
        seconds: a.seconds,
        sdf_resolution: s.sdf,
        contact: ContactConfig { max_patches: s.patches, ..Default::default() },
        solver: SolverConfig {
            dt: a.dt,
            substeps: s.substeps,
            pos_iters: s.pos_iters,
            vel_iters: a.vel_iters,
            ..Default::default()
        },
        mu: 0.0,
        contact_offset: 1e-3,
        segments_per_turn: ThreadOptions::default().segments_per_turn,
    };
    match run_nut_bolt(gpu, &run) {
        Ok(r) => {
            let status = if r.finite { Status::Ok } else { Status::Unstable };
            PointResult { setting: s, status, report: Some(r), repeats: 1 }
        }
        Err(e) if is_budget_refusal(&e) => {
            PointResult { setting: s, status: Status::Refused(format!("{e:#}")), report: None, repeats: 0 }
        }
        Err(e) => PointResult { setting: s, status: Status::Error(format!("{e:#}")), report: None, repeats: 0 },
    }
}

/// Folds a repeat into a point: the first run's figures, the minimum wall time (and the timings derived
/// from it); a failed repeat marks the point failed.
pub fn merge_repeat(p: &mut PointResult, next: PointResult) {
    match (&mut p.report, next.report) {
        (Some(r), Some(n)) => {
            r.wall_s = r.wall_s.min(n.wall_s);
            r.ms_per_frame = r.wall_s * 1e3 / r.frames as f64;
            r.real_time_factor_per_world = r.seconds as f64 / r.wall_s;
            r.pair_seconds_per_wall_second = r.worlds as f64 * r.real_time_factor_per_world;
            r.finite &= n.finite;
            p.repeats += 1;
            if !n.finite {
                p.status = Status::Unstable;
            }
        }
        _ => {
            p.status = next.status;
            p.report = None;
        }
    }
}

fn log_point(p: &PointResult) {
    match (&p.status, p.report.as_ref()) {
        (Status::Ok | Status::Unstable, Some(r)) => eprintln!(
            "    {}: {:.3} wall s per sim s (min of {}), descent {:.4} mm (analytic {:.4}; err {:.2e}), lead err \
             {:.2e}, penetration {:.4} mm",
            p.status.name(),
            p.wall_per_sim_s().unwrap_or(f64::NAN),
            p.repeats,
            r.nut_descent_mm,
            r.analytic_descent_mm,
            p.descent_err().unwrap_or(f64::NAN),
            p.lead_err().unwrap_or(f64::NAN),
            r.max_penetration_mm
        ),
        (st, _) => eprintln!("    {}: {}", st.name(), st.note()),
    }
}

/// The whole sweep: `repeats` passes over every point (round robin, so a burst of load on the shared
/// machine hits one run of several points rather than every run of one point; each point keeps its
/// minimum wall time). The CSV is rewritten after each run (a cut-off sweep leaves what it measured),
/// the plot after each pass.
pub fn run_sweep(gpu: &GpuContext, a: &ParetoArgs) -> Result<Vec<PointResult>> {
    ensure!(a.seconds > 0.0 && a.seconds.is_finite(), "--seconds must be > 0");
    ensure!(a.worlds > 0, "--worlds must be at least 1");
    let settings = sweep_settings(a.base, &a.sdfs, &a.patches, &a.substeps, &a.pos_iters);
    let solver = SolverConfig { dt: a.dt, vel_iters: a.vel_iters, ..Default::default() };
    let repeats = a.repeats.max(1);
    let mut results: Vec<PointResult> = Vec::new();
    for pass in 0..repeats {
        for (k, &s) in settings.iter().enumerate() {
            if results.get(k).is_some_and(|p| matches!(p.status, Status::Refused(_) | Status::Error(_))) {
                continue;
            }
            eprintln!(
                "[pass {}/{repeats}, {}/{}] {} ({}) ...",
                pass + 1,
                k + 1,
                settings.len(),
                s.label(),
                s.axis.name()
            );
            let p = run_point(gpu, a, s);
            if pass == 0 {
                results.push(p);
            } else {
                merge_repeat(&mut results[k], p);
            }
            log_point(&results[k]);
            factory_engine::fsutil::write_atomic(&a.out_csv, to_csv(&results, &solver, a.worlds).as_bytes())?;
        }
        let title = format!(
            "{} {} nut-bolt, frictionless, {} s simulated, {} world{}: error vs speed",
            a.size.name(),
            a.fit.name(),
            a.seconds,
            a.worlds,
            if a.worlds == 1 { "" } else { "s" }
        );
        let left_out: Vec<String> = results
            .iter()
            .filter(|p| p.status != Status::Ok)
            .map(|p| format!("{} ({})", p.setting.label(), p.status.name()))
            .collect();
        let foot = format!(
            "dt {:.4} s, {} velocity iteration(s); one axis varied at a time around the baseline; wall time: frames \
             only, min of {} run(s); adapter {}.{}",
            a.dt,
            a.vel_iters,
            pass + 1,
            gpu.info.name,
            if left_out.is_empty() { String::new() } else { format!(" Not plotted: {}.", left_out.join(", ")) }
        );
        let svg = plot_svg(&results, &a.metrics, &title, &foot)?;
        factory_engine::fsutil::write_atomic(&a.out_plot, svg.as_bytes())?;
    }
    Ok(results)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn front_minimises_both() {
        let pts = [
            Some((1.0, 0.10)), // front: fastest
            Some((2.0, 0.05)), // front
            Some((2.5, 0.05)), // dominated by (2.0, 0.05): equal error, slower
            Some((3.0, 0.20)), // dominated
            Some((4.0, 0.01)), // front: most accurate
            None,              // refused
            Some((0.5, f64::NAN)),
            Some((1.0, 0.10)), // equal to the first: both stay
        ];
        assert_eq!(pareto_front(&pts), vec![true, true, false, false, true, false, false, true]);
        assert_eq!(pareto_front(&[]), Vec::<bool>::new());
        assert_eq!(pareto_front(&[None, Some((1.0, 1.0))]), vec![false, true]);
    }

    #[test]
    fn csv_quotes_only_what_needs_it() {
        assert_eq!(csv_field("grid 256"), "grid 256");
        assert_eq!(csv_field("0.0123"), "0.0123");
        assert_eq!(csv_field(""), "");
        assert_eq!(csv_field("a,b"), "\"a,b\"");
        assert_eq!(csv_field("say \"x\""), "\"say \"\"x\"\"\"");
        assert_eq!(csv_field("two\nlines"), "\"two\nlines\"");
        assert_eq!(csv_field(" padded"), "\" padded\"");
        assert_eq!(csv_record(&["a", "b,c", "d\"e"]), "a,\"b,c\",\"d\"\"e\"\n");
        // A refusal message (commas, parentheses, quotes) survives a round trip through a minimal parser.
        let msg = r#"refused: invalid substeps x (pos_iters + vel_iters) x contacts = 4 x (40 + 1) x 1024 = 1, "x""#;
        let line = csv_record(&["7", msg, "z"]);
        assert_eq!(parse_record(line.trim_end_matches('\n')), vec!["7", msg, "z"]);
    }

    /// Minimal RFC 4180 record parser for the test.
    fn parse_record(s: &str) -> Vec<String> {
        let (mut out, mut cur, mut quoted, mut chars) = (Vec::new(), String::new(), false, s.chars().peekable());
        while let Some(c) = chars.next() {
            match (quoted, c) {
                (true, '"') if chars.peek() == Some(&'"') => {
                    chars.next();
                    cur.push('"');
                }
                (true, '"') => quoted = false,
                (false, '"') if cur.is_empty() => quoted = true,
                (false, ',') => out.push(std::mem::take(&mut cur)),
                (_, c) => cur.push(c),
            }
        }
        out.push(cur);
        out
    }

    #[test]
    fn log_axes_snap_to_powers_of_their_base() {
        assert_eq!(log_axis(1.3, 1.9), (1.0, 2.0, 2.0));
        assert_eq!(log_axis(1.3, 6.0), (1.0, 8.0, 2.0));
        assert_eq!(log_axis(0.0011, 0.19), (0.0011, 0.19, 10.0));
        assert_eq!(log_axis(0.0011, 1.9), (0.0011, 1.9, 10.0));
    }

    #[test]
    fn sweep_varies_one_axis_at_a_time() {
        let base = Setting { axis: Axis::Baseline, sdf: None, patches: 64, substeps: 1, pos_iters: 20 };
        let s = sweep_settings(base, &[None, Some(128), Some(256)], &[16, 64, 128], &[1, 2], &[5, 20, 40]);
        let labels: Vec<String> = s.iter().map(|s| s.label()).collect();
        assert_eq!(
            labels,
            ["baseline", "grid 128", "grid 256", "16 patches", "128 patches", "2 substeps", "5 iters", "40 iters"]
        );
        for p in &s[1..] {
            let diffs = [
                p.sdf != base.sdf,
                p.patches != base.patches,
                p.substeps != base.substeps,
                p.pos_iters != base.pos_iters,
            ];
            assert_eq!(diffs.iter().filter(|&&d| d).count(), 1, "{p:?}");
        }
    }

    #[test]
    fn csv_has_a_record_per_point_and_marks_refusals() {
        let base = Setting { axis: Axis::Baseline, sdf: None, patches: 64, substeps: 1, pos_iters: 20 };
        let results = vec![PointResult {
            setting: base,
            status: Status::Refused("too many loop passes, use fewer".into()),
            report: None,
            repeats: 0,
        }];
        let csv = to_csv(&results, &SolverConfig::default(), 1);
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines.len(), 2);
        assert_eq!(lines[0].split(',').count(), CSV_HEADER.len());
        assert!(lines[1].contains("\"refused: too many loop passes, use fewer\""), "{}", lines[1]);
        assert_eq!(parse_record(lines[1]).len(), CSV_HEADER.len());
    }

    fn fake(axis: Axis, patches: u32, wall_s: f64, descent_mm: f64, pen_mm: f64) -> PointResult {
        let report = NutBoltReport {
            scene: "nut-bolt",
            size: "M16".into(),
            fit: "tight".into(),
            worlds: 1,
            seconds: 1.0,
            frames: 60,
            solver: (&SolverConfig::default()).into(),
            sdf: "analytic".into(),
            max_patches: patches,
            descent_iters: 12,
            candidates_per_invocation: 1,
            workgroup_size: 64,
            interleaved_descent: true,
            segments_per_turn: 192,
            query_triangles: 11512,
            mu: 0.0,
            wall_s,
            ms_per_frame: wall_s * 1e3 / 60.0,
            handling_ms_per_frame: 0.8 * wall_s * 1e3 / 60.0,
            solve_ms_per_frame: 0.2 * wall_s * 1e3 / 60.0,
            pair_seconds_per_wall_second: 1.0 / wall_s,
            real_time_factor_per_world: 1.0 / wall_s,
            nut_descent_mm: descent_mm,
            nut_turns: -descent_mm / 2.0,
            analytic_descent_mm: 4.6,
            max_penetration_mm: pen_mm,
            nut_mass_kg: 0.03,
            nut_inertia_axis_kgm2: 3e-6,
            pitch_mm: 2.0,
            finite: true,
            adapter: "test".into(),
        };
        let setting = Setting { axis, sdf: None, patches, substeps: 1, pos_iters: 20 };
        PointResult { setting, status: Status::Ok, report: Some(report), repeats: 1 }
    }

    #[test]
    fn plot_has_a_panel_per_metric_and_the_labels() {
        let mut results = vec![
            fake(Axis::Baseline, 64, 1.2, 4.62, 0.02),
            fake(Axis::Patches, 16, 1.0, 4.7, 0.3),
            fake(Axis::Patches, 128, 1.5, 4.6, 0.0),
        ];
        results.push(PointResult {
            setting: Setting { axis: Axis::Substeps, substeps: 64, ..results[0].setting },
            status: Status::Refused("loop limit".into()),
            report: None,
            repeats: 0,
        });
        let svg = plot_svg(&results, &[ErrorMetric::Descent, ErrorMetric::Penetration], "t", "foot").unwrap();
        assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
        for text in ["baseline", "16 patches", "128 patches", "Pareto front", "deepest penetration seen"] {
            assert!(svg.contains(text), "{text} missing");
        }
        assert!(!svg.contains("64 substeps"), "refused points are not drawn");
        // Zero errors (128 patches) are on the fronts; equal lead errors leave only the fastest on that one.
        let csv = to_csv(&results, &SolverConfig::default(), 1);
        assert!(csv.lines().nth(3).unwrap().ends_with(",descent+penetration"), "{csv}");
        assert!(csv.lines().nth(2).unwrap().ends_with(",descent+lead+penetration"), "{csv}");
    }
}

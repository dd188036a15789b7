//! `factory-plot --metrics RUN_DIR/metrics.csv --out curve.svg`: the learning curve (success rate against
//! env steps and against training wall time, mean return against env steps) as SVG. The flags are
//! `factory-plot --help` (docs/CLI.md).

use anyhow::Result;
use clap::Parser;
use factory_rl::cli::PlotArgs;
use factory_rl::plot::{plot_svg, read_metrics, smooth};

fn main() -> Result<()> {
    let a = PlotArgs::parse();
    let points = read_metrics(&a.metrics)?;
    let last = points.last().copied();
    let title = a.title.unwrap_or_else(|| a.metrics.parent().map(|p| p.display().to_string()).unwrap_or_default());
    let title = match last {
        Some(p) => format!("{title}: {:.2}M env steps in {:.2} h", p.env_steps / 1e6, p.wall_seconds / 3600.0),
        None => title,
    };
    let svg = plot_svg(&smooth(&points, a.smooth), &title)?;
    factory_rl::checkpoint::write_atomic(&a.out, svg.as_bytes())?;
    println!("wrote {} ({} updates, smoothed over {}): {title}", a.out.display(), points.len(), a.smooth);
    Ok(())
}

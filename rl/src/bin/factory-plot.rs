//! `factory-plot --metrics RUN_DIR/metrics.csv --out curve.svg [--smooth 8] [--title T]`: the learning curve
//! (success rate against env steps and against training wall time, mean return against env steps) as SVG.

use std::path::PathBuf;

use anyhow::Result;
use clap::Parser;
use factory_rl::plot::{plot_svg, read_metrics, smooth};

#[derive(Parser, Debug)]
#[command(name = "factory-plot", about = "Plot a factory-rs run's learning curve")]
struct Args {
    /// The run's metrics.csv.
    #[arg(long)]
    metrics: PathBuf,
    /// The SVG to write.
    #[arg(long)]
    out: PathBuf,
    /// Average over windows of this many updates.
    #[arg(long, default_value_t = 8)]
    smooth: usize,
    /// Title (default: the metrics file's folder).
    #[arg(long)]
    title: Option<String>,
}

fn main() -> Result<()> {
    let a = Args::parse();
    let points = read_metrics(&a.metrics)?;
    let last = points.last().copied();
    let title = a.title.unwrap_or_else(|| a.metrics.parent().map(|p| p.display().to_string()).unwrap_or_default());
    let title = match last {
        Some(p) => format!("{title}: {:.2}M env steps in {:.2} h", p.env_steps / 1e6, p.wall_seconds / 3600.0),
        None => title,
    };
    let svg = plot_svg(&smooth(&points, a.smooth), &title)?;
    factory_rl::checkpoint::write_atomic(&a.out, svg.as_bytes())?;
    Ok(())
}

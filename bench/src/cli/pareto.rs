//! `factory-bench pareto`: the nut-bolt scene's speed against its error over one setting at a time
//! (`crate::pareto`), written as CSV and SVG.

use super::scene::SceneName;
use crate::pareto::{parse_sdf, run_sweep, Axis, ErrorMetric, ParetoArgs, Setting, Status};
use anyhow::{anyhow, bail, Result};
use clap::ValueEnum;
use factory_engine::gpu::GpuContext;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct ParetoCmdArgs {
    #[arg(long, value_enum, default_value = "nut-bolt")]
    scene: SceneName,
    /// Parallel worlds per run.
    #[arg(long, default_value_t = 1)]
    worlds: u32,
    /// Simulated time per point [s].
    #[arg(long, default_value_t = 1.0)]
    seconds: f32,
    /// Runs per point (round robin over the points); the minimum wall time is kept (the machine is
    /// shared).
    #[arg(long, default_value_t = 5)]
    repeats: u32,
    /// Frame time step [s].
    #[arg(long, default_value_t = 1.0 / 60.0)]
    dt: f32,
    #[arg(long, default_value_t = 1)]
    vel_iters: u32,
    /// Baseline bolt SDF: `analytic` or a grid resolution.
    #[arg(long, default_value = "analytic")]
    base_sdf: String,
    #[arg(long, default_value_t = 64)]
    base_patches: u32,
    #[arg(long, default_value_t = 1)]
    base_substeps: u32,
    #[arg(long, default_value_t = 20)]
    base_pos_iters: u32,
    /// Bolt SDFs to sweep (`analytic` or grid resolutions; 512 bakes for about a minute once, then
    /// comes from the cache).
    #[arg(long, value_delimiter = ',', default_value = "analytic,128,256,512")]
    sdf_res: Vec<String>,
    /// Patch budgets to sweep.
    #[arg(long, value_delimiter = ',', default_value = "16,32,64,128")]
    patches: Vec<u32>,
    /// Substeps to sweep.
    #[arg(long, value_delimiter = ',', default_value = "1,2,4")]
    substeps: Vec<u32>,
    /// Position iterations to sweep.
    #[arg(long, value_delimiter = ',', default_value = "5,10,20,40")]
    pos_iters: Vec<u32>,
    /// Errors plotted, one panel each with its Pareto front: descent, lead, penetration (all three and
    /// their fronts are in the CSV).
    #[arg(long, value_delimiter = ',', default_value = "descent,penetration")]
    error: Vec<String>,
    /// ISO size (M4, M8, M12, M16, M20).
    #[arg(long, default_value = "M16")]
    size: String,
    /// Tolerance end: tight or loose.
    #[arg(long, default_value = "tight")]
    fit: String,
    #[arg(long, default_value = "docs/data/pareto_nut_bolt.csv")]
    out_csv: PathBuf,
    #[arg(long, default_value = "docs/data/pareto_nut_bolt.svg")]
    out_plot: PathBuf,
}

/// Runs the sweep, writes its CSV and plot and prints how many points were measured.
pub fn run(a: &ParetoCmdArgs) -> Result<()> {
    if a.scene != SceneName::NutBolt {
        let name = a.scene.to_possible_value().map(|v| v.get_name().to_owned()).unwrap_or_default();
        bail!("pareto --scene {name}: only nut-bolt is swept (valid: nut-bolt)")
    }
    let args = ParetoArgs {
        size: a.size.parse().map_err(|e| anyhow!("--size: {e}"))?,
        fit: a.fit.parse().map_err(|e| anyhow!("--fit: {e}"))?,
        worlds: a.worlds,
        seconds: a.seconds,
        dt: a.dt,
        vel_iters: a.vel_iters,
        base: Setting {
            axis: Axis::Baseline,
            sdf: parse_sdf(&a.base_sdf)?,
            patches: a.base_patches,
            substeps: a.base_substeps,
            pos_iters: a.base_pos_iters,
        },
        sdfs: a.sdf_res.iter().map(|s| parse_sdf(s)).collect::<Result<_>>()?,
        patches: a.patches.clone(),
        substeps: a.substeps.clone(),
        pos_iters: a.pos_iters.clone(),
        repeats: a.repeats,
        metrics: a.error.iter().map(|e| ErrorMetric::parse(e)).collect::<Result<_>>()?,
        out_csv: a.out_csv.clone(),
        out_plot: a.out_plot.clone(),
    };
    let results = run_sweep(GpuContext::global()?, &args)?;
    let ok = results.iter().filter(|p| p.status == Status::Ok).count();
    println!(
        "{ok} of {} points measured; wrote {} and {}",
        results.len(),
        args.out_csv.display(),
        args.out_plot.display()
    );
    Ok(())
}

//! `factory-bench`: measurements behind docs/BENCHMARKS.md (paper Tables I and II).
//!
//! `factory-bench contacts --pair nut-bolt --size M16 --fit tight --worlds 64 --json` times contact
//! handling (generation + reduction, one 1/60 s frame) for N parallel copies of a pair and reports the
//! candidates, contacts and patches per pair.

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand, ValueEnum};
use factory_assets::{nut_bolt, peg_hole, Fit, IsoSize, PegHoleOptions, PegSize, ThreadOptions};
use factory_bench::contact_scene::{min_depth, ContactScene, PartPair};
use factory_engine::contact::{ContactConfig, ContactPipeline};
use factory_engine::gpu::GpuContext;
use factory_engine::mesh::TriMesh;
use factory_engine::sdf::cache::SdfCache;
use std::path::PathBuf;
use std::time::Instant;

#[derive(Parser)]
#[command(name = "factory-bench", about = "Benchmarks of the factory-rs contact pipeline")]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum PairKind {
    /// Our generated ISO hex nut on its bolt.
    NutBolt,
    /// Our generated round peg in its hole.
    PegHole,
}

#[derive(Clone, Copy, Debug, PartialEq, ValueEnum)]
enum SdfKind {
    Grid,
    Analytic,
}

#[derive(Clone, Copy, Debug, PartialEq, ValueEnum)]
enum SceneName {
    /// M16 (or --size) nut released on its bolt, one pair per world.
    NutBolt,
    /// --bodies M16 nuts dropped into a pile in each world.
    PileNuts,
    /// --bodies bowls dropped into a pile in each world.
    PileBowls,
    /// --bodies toruses dropped into a pile in each world.
    PileToruses,
    /// The paper's eighth scene without the feeder: a Franka picks an M16 nut from the table, places it on
    /// its bolt and screws it down (scripted; the nut's position and yaw drawn per world from --seed).
    FrankaNutBolt,
}

#[derive(clap::Args)]
struct SceneArgs {
    #[arg(value_enum)]
    name: SceneName,
    /// Parallel worlds.
    #[arg(long, default_value_t = 1)]
    worlds: u32,
    /// Simulated time [s] [default: 1; franka-nut-bolt: 60, the limit of its episode].
    #[arg(long)]
    seconds: Option<f32>,
    /// Frame time step [s].
    #[arg(long, default_value_t = 1.0 / 60.0)]
    dt: f32,
    /// Substeps per frame [default: the scene's in the paper's Table II: 1; bowls 2].
    #[arg(long)]
    substeps: Option<u32>,
    /// Position iterations [default: Table II's: nut-bolt 20, nuts and toruses 16, bowls 50].
    #[arg(long)]
    pos_iters: Option<u32>,
    /// Velocity iterations [default: 1; franka-nut-bolt: 0, as Factory's tasks].
    #[arg(long)]
    vel_iters: Option<u32>,
    /// Gauss-Seidel passes over each contact patch per sweep (SolverConfig::patch_iters).
    #[arg(long, default_value_t = factory_engine::solver::SolverConfig::default().patch_iters)]
    patch_iters: u32,
    /// Passes over each patch that touches an articulation link (SolverConfig::link_patch_iters;
    /// franka-nut-bolt) [default: 1; franka-nut-bolt: its scene default].
    #[arg(long)]
    link_patch_iters: Option<u32>,
    /// Coulomb friction per patch instead of per contact (SolverConfig::friction_per_patch).
    #[arg(long)]
    friction_per_patch: bool,
    /// Bolt SDF (nut-bolt): `analytic` or a grid resolution (e.g. 256).
    #[arg(long, default_value = "analytic")]
    sdf_res: String,
    /// Patch budget per pair (16..=256) [default: nut-bolt 64, piles 16].
    #[arg(long)]
    patches: Option<u32>,
    /// Friction coefficient [default: nut-bolt 0.05 as the paper; piles 0.5].
    #[arg(long)]
    mu: Option<f32>,
    /// Bodies per world of a pile scene (the paper's: 1024).
    #[arg(long, default_value_t = 16)]
    bodies: u32,
    /// Pile solver: `coloured` (near pairs found every frame, graph-coloured Gauss-Seidel; any size) or
    /// `serial` (all pairs fixed, one invocation per world; a few dozen bodies on lavapipe).
    #[arg(long, value_enum, default_value = "coloured")]
    pile_solver: PileSolverArg,
    /// Pile scenes: print the fastest bodies of world 0 for each of the last N frames on stderr;
    /// franka-nut-bolt: print world 0's stage, fingertip and nut every N frames.
    #[arg(long, default_value_t = 0)]
    trace_frames: u32,
    /// franka-nut-bolt: the world --trace-frames prints.
    #[arg(long, default_value_t = 0)]
    trace_world: usize,
    /// Pile scenes (coloured solver): a body that stays within --sleep-distance-mm and --sleep-angle of one
    /// pose for this many frames falls asleep until a moving body touches it (0: never; PhysX's wake
    /// counter of 0.4 s is 24 frames at 60 Hz).
    #[arg(long, default_value_t = 0)]
    sleep_frames: u32,
    /// Sleeping: largest displacement of a body's centre of mass from its reference pose [mm].
    #[arg(long, default_value_t = 1.0)]
    sleep_distance_mm: f32,
    /// Sleeping: largest rotation from the reference pose [rad].
    #[arg(long, default_value_t = 0.1)]
    sleep_angle: f32,
    /// Seed of a pile's starting orientations.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Contact offset [mm]: contacts are generated this far apart, so it must cover a frame's approach
    /// [default: nut-bolt 1; piles 10].
    #[arg(long)]
    offset_mm: Option<f32>,
    /// Projected-gradient iterations per query triangle.
    #[arg(long, default_value_t = 12)]
    descent_iters: u32,
    /// Candidates per invocation of the contact kernels (1, 2 or 4; ContactConfig::candidates_per_invocation:
    /// 4 is faster on lavapipe and keeps other contacts, see docs/BENCHMARKS.md).
    #[arg(long, default_value_t = 1)]
    per: u32,
    /// Invocations per contact workgroup (32, 64, 128, 256; at most 256 candidates per workgroup).
    #[arg(long, default_value_t = 64)]
    workgroup: u32,
    /// Run an invocation's four query triangles one after another instead of side by side
    /// (ContactConfig::interleaved_descent; the same results, for comparing speed).
    #[arg(long)]
    sequential_descent: bool,
    /// Thread columns per turn of the generated nut and bolt meshes (multiple of 12, >= 24).
    #[arg(long, default_value_t = 192)]
    segments_per_turn: usize,
    /// ISO size (M4, M8, M12, M16, M20).
    #[arg(long, default_value = "M16")]
    size: String,
    /// Tolerance end: tight or loose.
    #[arg(long, default_value = "tight")]
    fit: String,
    /// franka-nut-bolt: stiffness of the fingers' drive [N/m] (default 2000; Factory's gym_default 500).
    #[arg(long)]
    finger_kp: Option<f32>,
    /// franka-nut-bolt: damping of the fingers' drive [N s/m] (default 50; Factory's gym_default 20).
    #[arg(long)]
    finger_kd: Option<f32>,
    /// franka-nut-bolt: chamfer the bolt's tip (ISO 4753, as Factory's bolt); false: a flat-cut tip.
    #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
    bolt_tip_chamfer: bool,
    /// franka-nut-bolt: where the arm, fingers and parts are solved together: the device kernel
    /// (solver::articulated; lavapipe without a GPU), the host reference (solver::step_cpu_articulated), or
    /// auto: the device on a hardware GPU, the host on a software adapter.
    #[arg(long, default_value = "auto", value_parser = parse_solve)]
    solve: factory_bench::franka::CoupledSolve,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
}

/// `--solve auto|host|device`: the engine's enum by its config names.
fn parse_solve(s: &str) -> std::result::Result<factory_bench::franka::CoupledSolve, String> {
    serde_json::from_value(serde_json::Value::String(s.into()))
        .map_err(|_| format!("'{s}' is not one of auto, host, device"))
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum PileSolverArg {
    Coloured,
    Serial,
}

impl SceneArgs {
    /// The solver settings, the scene's Table II defaults filling what was not given.
    fn solver(&self, paper: &factory_engine::solver::SolverConfig) -> factory_engine::solver::SolverConfig {
        factory_engine::solver::SolverConfig {
            dt: self.dt,
            substeps: self.substeps.unwrap_or(paper.substeps),
            pos_iters: self.pos_iters.unwrap_or(paper.pos_iters),
            vel_iters: self.vel_iters.unwrap_or(1),
            patch_iters: self.patch_iters,
            friction_per_patch: self.friction_per_patch,
            ..Default::default()
        }
    }
}

#[derive(Subcommand)]
enum Cmd {
    /// Whole frames (contacts + solver on the GPU) of a paper scene (Table II) with its accuracy figures.
    Scene(SceneArgs),
    /// Speed against error: sweeps the bolt SDF, patch budget, substeps and position iterations one at a
    /// time around the paper's baseline (frictionless nut, analytic descent as reference) and writes a
    /// CSV and an SVG plot with the Pareto front (docs/BENCHMARKS.md).
    Pareto {
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
        #[arg(long, default_value = "docs/pareto_nut_bolt.csv")]
        out_csv: PathBuf,
        #[arg(long, default_value = "docs/pareto_nut_bolt.svg")]
        out_plot: PathBuf,
    },
    /// Cost of a control step for the Franka at N worlds: the articulation quantities the controllers read
    /// (fingertip pose, Jacobian, mass matrix, gravity; `ArmBatch::from_articulation`) and each of the
    /// seven controllers' torques, on the host; then the same on the device (the articulation kernel's
    /// dynamics and the task-space controllers' kernel).
    Controllers {
        /// Parallel worlds.
        #[arg(long, default_value_t = 128)]
        worlds: u32,
        /// Timed repetitions (the median is reported).
        #[arg(long, default_value_t = 50)]
        repeats: u32,
        /// Print one JSON object instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Contact generation + reduction for N parallel copies of a shape pair (paper Table I).
    Contacts {
        /// Which generated pair (ignored with --mesh-a/--mesh-b).
        #[arg(long, value_enum, default_value = "nut-bolt")]
        pair: PairKind,
        /// Nut-bolt size (M4, M8, M12, M16, M20) or peg diameter in mm (4, 8, 12, 16).
        #[arg(long, default_value = "M16")]
        size: String,
        /// Tolerance end: tight or loose.
        #[arg(long, default_value = "tight")]
        fit: String,
        /// Parallel worlds, one pair each.
        #[arg(long, default_value_t = 1)]
        worlds: u32,
        /// Moving part (e.g. Factory's nut) as OBJ, in the assembled pose; needs --mesh-b.
        #[arg(long, requires = "mesh_b")]
        mesh_a: Option<PathBuf>,
        /// Fixed part (e.g. Factory's bolt) as OBJ, in the assembled pose; needs --mesh-a.
        #[arg(long, requires = "mesh_a")]
        mesh_b: Option<PathBuf>,
        /// Thread pitch of the mesh pair [mm] (0 for unthreaded pairs).
        #[arg(long, default_value_t = 2.0)]
        pitch_mm: f32,
        /// SDF resolution: samples along the SDF part's longest axis (grid SDFs).
        #[arg(long, default_value_t = 256)]
        sdf_res: u32,
        /// SDF of the bolt: `grid` (baked from the mesh, as Factory) or `analytic` (exact thread field;
        /// generated nut-bolt pairs only).
        #[arg(long, value_enum, default_value = "grid")]
        sdf: SdfKind,
        /// Patch budget per pair (16..=256).
        #[arg(long, default_value_t = 64)]
        patches: u32,
        /// Candidates whose normals are within this angle of a patch's normal join it [deg].
        #[arg(long, default_value_t = 10.0)]
        normal_deg: f32,
        /// Invocations per contact workgroup (32, 64, 128, 256).
        #[arg(long, default_value_t = 64)]
        workgroup: u32,
        /// Candidates per invocation (1, 2 or 4; at most 256 per workgroup; ContactConfig::candidates_per_invocation).
        #[arg(long, default_value_t = 1)]
        per: u32,
        /// Run an invocation's four query triangles one after another instead of side by side
        /// (ContactConfig::interleaved_descent; the same results, for comparing speed).
        #[arg(long)]
        sequential_descent: bool,
        /// Projected-gradient iterations per query triangle.
        #[arg(long, default_value_t = 12)]
        descent_iters: u32,
        /// Thread columns per turn of the generated nut and bolt meshes (multiple of 12, >= 24).
        #[arg(long, default_value_t = 192)]
        segments_per_turn: usize,
        /// Contact offset [mm]: candidates farther than this are dropped.
        #[arg(long, default_value_t = 1.0)]
        offset_mm: f32,
        /// Frames to time (after one warm-up frame).
        #[arg(long, default_value_t = 30)]
        frames: u32,
        /// Also time the plain-Rust twin (all cores) on the same input.
        #[arg(long)]
        cpu: bool,
        /// Print one JSON object instead of text.
        #[arg(long)]
        json: bool,
    },
}

/// Prints a report as one JSON line (`--json`, for scripts) or indented.
fn print_report(report: &impl serde::Serialize, json: bool) -> Result<()> {
    let text = if json { serde_json::to_string(report)? } else { serde_json::to_string_pretty(report)? };
    println!("{text}");
    Ok(())
}

fn main() -> Result<()> {
    match Cli::parse().cmd {
        Cmd::Scene(args) if args.name == SceneName::FrankaNutBolt => {
            use factory_bench::franka::{run_franka_nut_bolt, FrankaNutBoltRun};
            let base = FrankaNutBoltRun::default();
            let run = FrankaNutBoltRun {
                worlds: args.worlds,
                seconds: args.seconds.unwrap_or(base.seconds),
                seed: args.seed,
                // 4 substeps as the paper's Table II row, 32 position iterations (the paper: 16; see
                // FrankaNutBoltRun::default), 0 velocity iterations as Factory's tasks; --substeps /
                // --pos-iters / --vel-iters override.
                solver: factory_engine::solver::SolverConfig {
                    vel_iters: args.vel_iters.unwrap_or(0),
                    link_patch_iters: args.link_patch_iters.unwrap_or(base.solver.link_patch_iters),
                    ..args.solver(&base.solver)
                },
                contact: ContactConfig {
                    candidates_per_invocation: args.per,
                    workgroup_size: args.workgroup,
                    interleaved_descent: !args.sequential_descent,
                    ..Default::default()
                },
                thread_mu: args.mu.unwrap_or(base.thread_mu),
                finger_drive: [
                    args.finger_kp.unwrap_or(base.finger_drive[0]),
                    args.finger_kd.unwrap_or(base.finger_drive[1]),
                ],
                bolt_tip_chamfer: args.bolt_tip_chamfer,
                solve: args.solve,
                trace_every: args.trace_frames,
                trace_world: args.trace_world,
                ..base
            };
            print_report(&run_franka_nut_bolt(GpuContext::global()?, &run)?, args.json)?;
        }
        Cmd::Scene(args) if args.name != SceneName::NutBolt => {
            use factory_bench::pile::{run_pile, PileKind, PileRun};
            let kind = match args.name {
                SceneName::PileNuts => PileKind::Nuts,
                SceneName::PileBowls => PileKind::Bowls,
                _ => PileKind::Toruses,
            };
            let run = PileRun {
                kind,
                bodies: args.bodies,
                worlds: args.worlds,
                seconds: args.seconds.unwrap_or(1.0),
                contact: ContactConfig {
                    max_patches: args.patches.unwrap_or(16),
                    iterations: args.descent_iters,
                    candidates_per_invocation: args.per,
                    workgroup_size: args.workgroup,
                    interleaved_descent: !args.sequential_descent,
                    ..Default::default()
                },
                solver: args.solver(&kind.paper_solver()),
                mu: args.mu.unwrap_or(0.5),
                contact_offset: args.offset_mm.unwrap_or(10.0) * 1e-3,
                seed: args.seed,
                trace_frames: args.trace_frames,
                sleep: factory_engine::crowd::SleepConfig {
                    frames: args.sleep_frames,
                    distance: args.sleep_distance_mm * 1e-3,
                    angle: args.sleep_angle,
                },
                pile_solver: match args.pile_solver {
                    PileSolverArg::Coloured => factory_bench::pile::PileSolver::Coloured,
                    PileSolverArg::Serial => factory_bench::pile::PileSolver::Serial,
                },
            };
            print_report(&run_pile(GpuContext::global()?, &run)?, args.json)?;
        }
        Cmd::Scene(args) => {
            // The paper's nut-bolt row of Table II: 1 substep, 20 position iterations; mu 0.05.
            let paper = factory_engine::solver::SolverConfig { substeps: 1, pos_iters: 20, ..Default::default() };
            let mu = args.mu.unwrap_or(0.05);
            let sdf_resolution = match args.sdf_res.as_str() {
                "analytic" => None,
                r => Some(r.parse::<u32>().map_err(|_| {
                    anyhow::anyhow!("--sdf-res {r:?}: valid values are `analytic` or a grid resolution such as 256")
                })?),
            };
            let run = factory_bench::scene::NutBoltRun {
                size: args.size.parse().map_err(|e| anyhow::anyhow!("--size: {e}"))?,
                fit: args.fit.parse().map_err(|e| anyhow::anyhow!("--fit: {e}"))?,
                worlds: args.worlds,
                seconds: args.seconds.unwrap_or(1.0),
                sdf_resolution,
                contact: ContactConfig {
                    max_patches: args.patches.unwrap_or(64),
                    iterations: args.descent_iters,
                    candidates_per_invocation: args.per,
                    workgroup_size: args.workgroup,
                    interleaved_descent: !args.sequential_descent,
                    ..Default::default()
                },
                solver: args.solver(&paper),
                mu,
                contact_offset: args.offset_mm.unwrap_or(1.0) * 1e-3,
                segments_per_turn: args.segments_per_turn,
            };
            if !(mu.is_finite() && mu >= 0.0) {
                bail!("--mu {mu}: the friction coefficient must be finite and >= 0");
            }
            print_report(&factory_bench::scene::run_nut_bolt(GpuContext::global()?, &run)?, args.json)?;
        }
        Cmd::Pareto {
            scene:
                other @ (SceneName::PileNuts | SceneName::PileBowls | SceneName::PileToruses | SceneName::FrankaNutBolt),
            ..
        } => {
            let name = other.to_possible_value().map(|v| v.get_name().to_owned()).unwrap_or_default();
            bail!("pareto --scene {name}: only nut-bolt is swept (valid: nut-bolt)")
        }
        Cmd::Pareto {
            scene: SceneName::NutBolt,
            worlds,
            seconds,
            repeats,
            dt,
            vel_iters,
            base_sdf,
            base_patches,
            base_substeps,
            base_pos_iters,
            sdf_res,
            patches,
            substeps,
            pos_iters,
            error,
            size,
            fit,
            out_csv,
            out_plot,
        } => {
            use factory_bench::pareto::{self, Axis, ErrorMetric, ParetoArgs, Setting};
            let args = ParetoArgs {
                size: size.parse().map_err(|e| anyhow::anyhow!("--size: {e}"))?,
                fit: fit.parse().map_err(|e| anyhow::anyhow!("--fit: {e}"))?,
                worlds,
                seconds,
                dt,
                vel_iters,
                base: Setting {
                    axis: Axis::Baseline,
                    sdf: pareto::parse_sdf(&base_sdf)?,
                    patches: base_patches,
                    substeps: base_substeps,
                    pos_iters: base_pos_iters,
                },
                sdfs: sdf_res.iter().map(|s| pareto::parse_sdf(s)).collect::<Result<_>>()?,
                patches,
                substeps,
                pos_iters,
                repeats,
                metrics: error.iter().map(|e| ErrorMetric::parse(e)).collect::<Result<_>>()?,
                out_csv,
                out_plot,
            };
            let results = pareto::run_sweep(GpuContext::global()?, &args)?;
            let ok = results.iter().filter(|p| p.status == pareto::Status::Ok).count();
            println!(
                "{ok} of {} points measured; wrote {} and {}",
                results.len(),
                args.out_csv.display(),
                args.out_plot.display()
            );
        }
        Cmd::Controllers { worlds, repeats, json } => {
            print_report(&factory_bench::franka::bench_controllers(worlds, repeats)?, json)?;
        }
        Cmd::Contacts {
            pair,
            size,
            fit,
            worlds,
            mesh_a,
            mesh_b,
            pitch_mm,
            sdf_res,
            sdf,
            patches,
            normal_deg,
            workgroup,
            per,
            sequential_descent,
            descent_iters,
            segments_per_turn,
            offset_mm,
            frames,
            cpu,
            json,
        } => {
            let fit_v: Fit = fit.parse().map_err(|e| anyhow::anyhow!("--fit: {e}"))?;
            let mut thread_sdf = None;
            let parts = match (mesh_a, mesh_b) {
                (Some(a), Some(b)) => PartPair {
                    name: format!("{} / {}", a.display(), b.display()),
                    a: TriMesh::load_obj(&a)?,
                    b: TriMesh::load_obj(&b)?,
                    pitch: pitch_mm * 1e-3,
                    side_shift: 0.0,
                },
                _ => match pair {
                    PairKind::NutBolt => {
                        let s: IsoSize = size.parse().map_err(|e| anyhow::anyhow!("--size: {e}"))?;
                        let opts = ThreadOptions { segments_per_turn, ..Default::default() };
                        let nb = nut_bolt(s, fit_v, &opts)?;
                        thread_sdf = Some(nb.bolt_sdf());
                        PartPair::nut_bolt(&nb)
                    }
                    PairKind::PegHole => {
                        let s: PegSize = size.parse().map_err(|e| anyhow::anyhow!("--size: {e}"))?;
                        let ph = peg_hole(s, fit_v, &PegHoleOptions::default())?;
                        PartPair {
                            name: format!("peg-hole {}mm {}", s.nominal_mm(), fit_v.name()),
                            a: ph.peg.mesh,
                            b: ph.hole.mesh,
                            pitch: 0.0,
                            side_shift: 0.5 * ph.clearance,
                        }
                    }
                },
            };
            let cache = SdfCache::new(SdfCache::default_dir());
            let t_bake = Instant::now();
            let scene = match (sdf, thread_sdf) {
                (SdfKind::Grid, _) => {
                    ContactScene::new(parts, sdf_res, offset_mm * 1e-3, &cache).context("building the contact scene")?
                }
                (SdfKind::Analytic, Some(t)) => ContactScene::with_thread_sdf(parts, t, offset_mm * 1e-3),
                (SdfKind::Analytic, None) => {
                    bail!("--sdf analytic needs a generated nut-bolt pair (--pair nut-bolt without --mesh-a/--mesh-b)")
                }
            };
            let bake_s = t_bake.elapsed().as_secs_f64();
            let gpu = GpuContext::global()?;
            // Threaded pairs: the nut raised by 5 whole pitches (threads in phase, centred in their axial
            // play, as the peers' scene); other pairs: the assembled pose, the peg against one side.
            let lift = 5.0 * scene.pair.pitch;
            // Each world gets its own turn of the nut (threads kept in phase), so worlds differ.
            let phases: Vec<f32> = (0..worlds).map(|w| (w as f32 * 2.399963) % std::f32::consts::TAU).collect();
            let poses = scene.poses(lift, &phases);
            let cfg = ContactConfig {
                max_patches: patches,
                normal_cos: normal_deg.to_radians().cos(),
                workgroup_size: workgroup,
                candidates_per_invocation: per,
                interleaved_descent: !sequential_descent,
                iterations: descent_iters,
                ..Default::default()
            };
            let pipe = ContactPipeline::new(gpu, &scene.model, worlds, &cfg)?;
            pipe.write_body_q(gpu, &poses);
            pipe.run(gpu);
            let out = pipe.read(gpu);
            let t = Instant::now();
            let cpu0 = process_cpu_ns();
            let mut enc = gpu.device.create_command_encoder(&Default::default());
            for _ in 0..frames {
                pipe.encode(&mut enc);
            }
            gpu.queue.submit([enc.finish()]);
            gpu.wait();
            let handling_ms = t.elapsed().as_secs_f64() * 1e3 / frames as f64;
            let handling_cpu_ms = cpu0.zip(process_cpu_ns()).map(|(a, b)| (b - a) as f64 * 1e-6 / frames as f64);
            let cpu_ms = if cpu {
                let t = Instant::now();
                let reps = 3;
                for _ in 0..reps {
                    std::hint::black_box(pipe.contacts_cpu(&poses));
                }
                Some(t.elapsed().as_secs_f64() * 1e3 / reps as f64)
            } else {
                None
            };
            let n = worlds as f64;
            let cand = out.candidates.iter().map(|&c| c as f64).sum::<f64>() / n;
            let contacts = (0..worlds as usize).map(|i| out.contact_count(i) as f64).sum::<f64>() / n;
            let npatch = out.patches.iter().map(|p| p.len() as f64).sum::<f64>() / n;
            let max_contacts = (0..worlds as usize).map(|i| out.contact_count(i)).max().unwrap_or(0);
            if !(cand > 0.0) {
                bail!("no contact candidates: the parts do not touch at lift {lift} m");
            }
            let report = serde_json::json!({
                "pair": scene.pair.name,
                "worlds": worlds,
                "adapter": gpu.info.name,
                "software_adapter": gpu.is_software(),
                "query_triangles": scene.query_triangles,
                "sdf_triangles": scene.sdf_triangles,
                "sdf": if scene.grid.is_some() { "grid" } else { "analytic" },
                "sdf_resolution": scene.grid.as_ref().map(|_| sdf_res),
                "sdf_dims": scene.grid.as_ref().map(|g| [g.dims.x, g.dims.y, g.dims.z]),
                "sdf_bake_or_load_s": bake_s,
                "max_patches": patches,
                "normal_bin_deg": normal_deg,
                "workgroup_size": workgroup,
                "candidates_per_invocation": per,
                "interleaved_descent": !sequential_descent,
                "descent_iters": descent_iters,
                "contact_offset_mm": offset_mm,
                "lift_mm": lift * 1e3,
                "deepest_contact_um": min_depth(&out).map(|d| d * 1e6),
                "candidates_per_pair": cand,
                "contacts_per_pair": contacts,
                "max_contacts_per_pair": max_contacts,
                "patches_per_pair": npatch,
                "handling_ms_per_frame": handling_ms,
                "handling_cpu_ms_per_frame": handling_cpu_ms,
                "cpu_twin_ms_per_frame": cpu_ms,
                "frames": frames,
            });
            if json {
                println!("{report}");
            } else {
                println!("{}", serde_json::to_string_pretty(&report)?);
            }
        }
    }
    Ok(())
}

/// CPU time of all this process's threads so far [ns] (Linux; None elsewhere). On a shared machine the wall
/// time of a software adapter (lavapipe) swings with the other processes' load, its CPU time much less:
/// compare CPU times when others share the cores.
fn process_cpu_ns() -> Option<u64> {
    let mut total = 0;
    for task in std::fs::read_dir("/proc/self/task").ok()? {
        let stat = std::fs::read_to_string(task.ok()?.path().join("schedstat")).ok()?;
        total += stat.split_whitespace().next()?.parse::<u64>().ok()?;
    }
    Some(total)
}

//! `factory-bench scene NAME`: whole frames of one of the paper's scenes (Table II) with its accuracy
//! figures; the nut-bolt scene (`crate::scene`), the piles (`crate::pile`) and the scripted Franka
//! (`crate::franka`).

use super::summary::{or_na, yes_no};
use super::{print_report, Summary};
use crate::franka::{run_franka_nut_bolt, CoupledSolve, FrankaNutBoltReport, FrankaNutBoltRun, STAGES};
use crate::pile::{run_pile, PileKind, PileReport, PileRun, PileSolver};
use crate::scene::{run_nut_bolt, NutBoltReport, NutBoltRun, SolverColumns};
use anyhow::{anyhow, bail, Result};
use clap::ValueEnum;
use factory_engine::contact::ContactConfig;
use factory_engine::gpu::GpuContext;
use factory_engine::many_body::SleepConfig;
use factory_engine::solver::SolverConfig;

/// The scenes `scene` runs (and `pareto --scene` names).
#[derive(Clone, Copy, Debug, PartialEq, ValueEnum)]
pub enum SceneName {
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

/// `--pile-solver`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum PileSolverArg {
    Coloured,
    Serial,
}

#[derive(clap::Args)]
pub struct SceneArgs {
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
    #[arg(long, default_value_t = SolverConfig::default().patch_iters)]
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
    /// Projected-gradient iterations per query triangle [default: 12, ContactConfig::default, as the Screw
    /// env].
    #[arg(long)]
    descent_iters: Option<u32>,
    /// Candidates per invocation of the contact kernels (1, 2 or 4; ContactConfig::candidates_per_invocation:
    /// 4 is faster on lavapipe and keeps other contacts, see docs/BENCHMARKS.md) [default: 1].
    #[arg(long)]
    per: Option<u32>,
    /// Invocations per contact workgroup (32, 64, 128, 256; at most 256 candidates per workgroup)
    /// [default: 64].
    #[arg(long)]
    workgroup: Option<u32>,
    /// Run an invocation's four query triangles one after another instead of side by side
    /// (ContactConfig::interleaved_descent; the same results, for comparing speed).
    #[arg(long)]
    sequential_descent: bool,
    /// Thread columns per turn of the generated nut and bolt meshes (multiple of 12, >= 24; 48 as the Screw
    /// env).
    #[arg(long, default_value_t = 48)]
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
    solve: CoupledSolve,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
}

/// `--solve auto|host|device`: the engine's enum by its config names.
fn parse_solve(s: &str) -> std::result::Result<CoupledSolve, String> {
    serde_json::from_value(serde_json::Value::String(s.into()))
        .map_err(|_| format!("'{s}' is not one of auto, host, device"))
}

impl SceneArgs {
    /// The solver settings, the scene's Table II defaults filling what was not given.
    fn solver(&self, paper: &SolverConfig) -> SolverConfig {
        SolverConfig {
            dt: self.dt,
            substeps: self.substeps.unwrap_or(paper.substeps),
            pos_iters: self.pos_iters.unwrap_or(paper.pos_iters),
            vel_iters: self.vel_iters.unwrap_or(1),
            patch_iters: self.patch_iters,
            friction_per_patch: self.friction_per_patch,
            ..Default::default()
        }
    }

    /// The contact settings given on the command line over the scene's own (`base`).
    fn contact(&self, base: ContactConfig) -> ContactConfig {
        ContactConfig {
            max_patches: self.patches.unwrap_or(base.max_patches),
            iterations: self.descent_iters.unwrap_or(base.iterations),
            candidates_per_invocation: self.per.unwrap_or(base.candidates_per_invocation),
            workgroup_size: self.workgroup.unwrap_or(base.workgroup_size),
            interleaved_descent: !self.sequential_descent,
            ..base
        }
    }
}

/// Runs the scene `args.name` and prints its report.
pub fn run(args: &SceneArgs) -> Result<()> {
    match args.name {
        SceneName::NutBolt => run_nut_bolt_scene(args),
        SceneName::FrankaNutBolt => run_franka_scene(args),
        SceneName::PileNuts | SceneName::PileBowls | SceneName::PileToruses => run_pile_scene(args),
    }
}

fn run_franka_scene(args: &SceneArgs) -> Result<()> {
    let base = FrankaNutBoltRun::default();
    let run = FrankaNutBoltRun {
        worlds: args.worlds,
        seconds: args.seconds.unwrap_or(base.seconds),
        seed: args.seed,
        // The Screw env's solver (FrankaNutBoltRun::default: 4 substeps, 32 position and 0 velocity
        // iterations); --substeps / --pos-iters / --vel-iters override.
        solver: SolverConfig {
            vel_iters: args.vel_iters.unwrap_or(0),
            link_patch_iters: args.link_patch_iters.unwrap_or(base.solver.link_patch_iters),
            ..args.solver(&base.solver)
        },
        contact: args.contact(base.contact.clone()),
        thread_mu: args.mu.or(base.thread_mu),
        finger_drive: [args.finger_kp.unwrap_or(base.finger_drive[0]), args.finger_kd.unwrap_or(base.finger_drive[1])],
        bolt_tip_chamfer: args.bolt_tip_chamfer,
        solve: args.solve,
        trace_every: args.trace_frames,
        trace_world: args.trace_world,
        ..base
    };
    print_report(&run_franka_nut_bolt(GpuContext::global()?, &run)?, args.json, franka_summary)
}

fn run_pile_scene(args: &SceneArgs) -> Result<()> {
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
        contact: args.contact(ContactConfig { max_patches: 16, ..Default::default() }),
        solver: args.solver(&kind.paper_solver()),
        mu: args.mu.unwrap_or(0.5),
        contact_offset: args.offset_mm.unwrap_or(10.0) * 1e-3,
        seed: args.seed,
        trace_frames: args.trace_frames,
        sleep: SleepConfig {
            frames: args.sleep_frames,
            distance: args.sleep_distance_mm * 1e-3,
            angle: args.sleep_angle,
        },
        pile_solver: match args.pile_solver {
            PileSolverArg::Coloured => PileSolver::Coloured,
            PileSolverArg::Serial => PileSolver::Serial,
        },
    };
    print_report(&run_pile(GpuContext::global()?, &run)?, args.json, pile_summary)
}

fn run_nut_bolt_scene(args: &SceneArgs) -> Result<()> {
    // The paper's nut-bolt row of Table II: 1 substep, 20 position iterations; mu 0.05.
    let paper = SolverConfig { substeps: 1, pos_iters: 20, ..Default::default() };
    let mu = args.mu.unwrap_or(0.05);
    let sdf_resolution =
        match args.sdf_res.as_str() {
            "analytic" => None,
            r => Some(r.parse::<u32>().map_err(|_| {
                anyhow!("--sdf-res {r:?}: valid values are `analytic` or a grid resolution such as 256")
            })?),
        };
    let run = NutBoltRun {
        size: args.size.parse().map_err(|e| anyhow!("--size: {e}"))?,
        fit: args.fit.parse().map_err(|e| anyhow!("--fit: {e}"))?,
        worlds: args.worlds,
        seconds: args.seconds.unwrap_or(1.0),
        sdf_resolution,
        contact: args.contact(ContactConfig::default()),
        solver: args.solver(&paper),
        mu,
        contact_offset: args.offset_mm.unwrap_or(1.0) * 1e-3,
        segments_per_turn: args.segments_per_turn,
    };
    if !(mu.is_finite() && mu >= 0.0) {
        bail!("--mu {mu}: the friction coefficient must be finite and >= 0");
    }
    print_report(&run_nut_bolt(GpuContext::global()?, &run)?, args.json, nut_bolt_summary)
}

/// `dt 16.667 ms, 1 substep, 20 position + 1 velocity iterations`.
fn solver_line(s: &SolverColumns) -> String {
    format!(
        "dt {:.3} ms, {} substeps, {} position + {} velocity iterations, {} passes per patch{}",
        s.dt * 1e3,
        s.substeps,
        s.pos_iters,
        s.vel_iters,
        s.patch_iters,
        if s.friction_per_patch { ", friction per patch" } else { "" }
    )
}

/// Wall time and its split per frame, as the scenes report it.
fn time_line(wall_s: f64, ms_per_frame: f64, handling_ms: f64, solve_ms: f64) -> String {
    format!(
        "{wall_s:.3} s wall, {ms_per_frame:.2} ms per frame (contact handling {handling_ms:.2}, solve {solve_ms:.2})"
    )
}

/// The nut-bolt scene's figures for a person.
pub fn nut_bolt_summary(r: &NutBoltReport) -> Summary {
    let mut s = Summary::new(format!(
        "scene {}: {} {}, {} worlds, {:.2} s simulated ({} frames)",
        r.scene, r.size, r.fit, r.worlds, r.seconds, r.frames
    ));
    s.row("adapter", &r.adapter)
        .row("solver", solver_line(&r.solver))
        .row("contacts", format!("{} SDF, {} patches per pair, mu {}", r.sdf, r.max_patches, r.mu))
        .row("time", time_line(r.wall_s, r.ms_per_frame, r.handling_ms_per_frame, r.solve_ms_per_frame))
        .row(
            "throughput",
            format!(
                "real-time factor {:.3} per world, {:.2} pair-seconds per wall second",
                r.real_time_factor_per_world, r.pair_seconds_per_wall_second
            ),
        )
        .row(
            "nut (world 0)",
            format!(
                "descended {:.3} mm (frictionless analytic {:.3} mm), {:+.3} turns",
                r.nut_descent_mm, r.analytic_descent_mm, r.nut_turns
            ),
        )
        .row("deepest contact", format!("{:.4} mm", r.max_penetration_mm))
        .row("stayed finite", yes_no(r.finite));
    s
}

/// A pile's figures for a person.
pub fn pile_summary(r: &PileReport) -> Summary {
    let mut s = Summary::new(format!(
        "scene {}: {} bodies x {} worlds, {:.2} s simulated ({} frames), {} solver",
        r.scene,
        r.bodies,
        r.worlds,
        r.seconds,
        r.frames,
        match r.pile_solver {
            PileSolver::Coloured => "coloured",
            PileSolver::Serial => "serial",
        }
    ));
    s.row("adapter", &r.adapter)
        .row("solver", format!("{}, mu {}", solver_line(&r.solver), r.mu))
        .row(
            "last frame",
            format!(
                "{} candidates -> {} contacts in {} patches, {} touching pairs (all worlds)",
                r.contacts_before, r.contacts_after, r.patches, r.touching_pairs
            ),
        )
        .row(
            "pile (world 0)",
            format!("{:.1} mm high, {} bodies resting on bodies", r.pile_height_mm, r.resting_body_pairs),
        )
        .row("time", time_line(r.wall_s, r.ms_per_frame, r.handling_ms_per_frame, r.solve_ms_per_frame))
        .row(
            "throughput",
            format!(
                "real-time factor {:.3} per world, {:.1} body-seconds per wall second",
                r.real_time_factor_per_world, r.body_seconds_per_wall_second
            ),
        )
        .row(
            "fastest body",
            format!(
                "{:.3} m/s (free fall {:.3}, energy bound {:.3}); at the end {:.4} m/s",
                r.max_speed_m_s, r.free_fall_speed_m_s, r.energy_bound_speed_m_s, r.final_max_speed_m_s
            ),
        )
        .row(
            "last second",
            format!("farthest drift {:.3} mm (body {})", r.last_second_max_drift_mm, r.last_second_max_drift_body),
        )
        .row("energy gain", format!("{:+.4} of the start's", r.max_energy_gain))
        .row("deepest contact", format!("{:.3} mm", r.max_penetration_mm))
        .row("stayed finite", yes_no(r.finite))
        .row("flagged frames", r.flagged_frames);
    if r.sleep_frames > 0 {
        s.row(
            "asleep (world 0)",
            format!("{} bodies at the end; woken, moved {:.3} mm at most", r.final_asleep_bodies, r.woken_max_drift_mm),
        );
    }
    s
}

/// The scripted Franka scene's figures for a person.
pub fn franka_summary(r: &FrankaNutBoltReport) -> Summary {
    let seated = (r.success_rate * r.worlds as f64).round() as u32;
    let mut s = Summary::new(format!(
        "scene {}: {} worlds, {:.2} s simulated at most ({} frames), {} solve",
        r.scene,
        r.worlds,
        r.seconds,
        r.frames,
        serde_json::to_value(r.solve).ok().and_then(|v| v.as_str().map(String::from)).unwrap_or_default()
    ));
    let stages: Vec<String> = STAGES
        .iter()
        .zip(&r.stage_reached)
        .map(|(st, n)| {
            format!(
                "{} {n}",
                serde_json::to_value(st).ok().and_then(|v| v.as_str().map(String::from)).unwrap_or_default()
            )
        })
        .collect();
    s.row("adapter", &r.adapter)
        .row(
            "solver",
            format!(
                "dt {:.3} ms, {} substeps, {} position + {} velocity iterations",
                r.dt * 1e3,
                r.substeps,
                r.pos_iters,
                r.vel_iters
            ),
        )
        .row(
            "seated",
            format!(
                "{seated} of {} worlds ({:.1}%), mean time to seat {} s",
                r.worlds,
                100.0 * r.success_rate,
                or_na(r.mean_success_s, 2)
            ),
        )
        .row("stages reached", stages.join(", "))
        .row("contacts", format!("{:.1} per world per frame", r.contacts_per_world))
        .row(
            "time",
            format!(
                "{:.1} s wall, {:.2} ms per frame (contact handling {:.2}, solve {:.2}, controller {:.3})",
                r.wall_s, r.ms_per_frame, r.handling_ms_per_frame, r.solve_ms_per_frame, r.controller_ms_per_frame
            ),
        )
        .row("throughput", format!("{:.3} world-seconds per wall second", r.world_seconds_per_wall_second))
        .row("deepest contact", format!("{:.3} mm", r.max_penetration_mm))
        .row("diverged worlds", r.diverged_worlds);
    s
}

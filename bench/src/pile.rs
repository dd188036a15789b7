//! The paper's pile scenes (section III-D, Tables I, II and VI): identical bodies (M16 nuts, bowls or
//! toruses) dropped from a loose lattice onto the ground, all in one world, every pair of bodies a
//! candidate pair. The paper drops 1024 of them; here the count is a parameter (see below).
//!
//! Representation (Table VI: the SDF body and the mesh body of each pair are the same part):
//! - toruses and bowls: the exact field of their revolved profile ([`factory_assets::pile`]) against the
//!   other's mesh, no grid at all;
//! - nuts: a grid baked from the nut's mesh (threads at `NUT_SEGMENTS_PER_TURN` columns per turn: a nut
//!   lying on a nut touches its flats and faces, not its threads, so the coarse thread is what the scene
//!   needs) against the other nut's mesh.
//!
//! Every body also meets the ground (the half-space z <= 0). Which pairs are near is the broad phase's
//! business (bounding spheres, `contact::generate::pair_far_cpu`), so far pairs cost a skipped workgroup.
//!
//! Limits, measured 2026-11-22 on lavapipe: the solver steps a world in one invocation (Gauss-Seidel is
//! serial within a world), and lavapipe allows an invocation 65535 loop passes, so a world's pairs x
//! sweeps must fit: a few dozen bodies per world. The paper's 1024-body piles need a solver that is
//! parallel within a world (graph colouring) and a compacted list of near pairs; neither is built.

use crate::scene::SolverColumns;
use anyhow::{ensure, Context, Result};
use factory_assets::pile::{bowl, torus, BowlOptions, TorusOptions};
use factory_assets::{nut_bolt, Fit, IsoSize, ThreadOptions};
use factory_engine::contact::{
    ContactConfig, ContactModel, ContactPipeline, PairSpec, QueryShape, SdfShape, TransformGpu, NO_BODY,
};
use factory_engine::gpu::GpuContext;
use factory_engine::mesh::{MassProperties, TriMesh};
use factory_engine::rng::SplitMix64;
use factory_engine::sdf::bake::BakeParams;
use factory_engine::sdf::cache::SdfCache;
use factory_engine::solver::gpu::GpuSolver;
use factory_engine::solver::{BodyModel, BodyState, SolverConfig};
use glam::{Quat, Vec3};
use std::sync::Arc;
use std::time::Instant;

/// Thread columns per turn of the pile's nuts (see the module doc).
pub const NUT_SEGMENTS_PER_TURN: usize = 48;
/// SDF resolution of the pile's nut grid (voxels along its longest axis): 0.5 mm voxels over the 27 mm
/// nut, against the 0.1 mm of Table VI's thread-resolving 284 x 132 x 327 grid.
pub const NUT_PILE_SDF_RESOLUTION: u32 = 64;
/// Gap between neighbouring bodies' bounding spheres in the starting lattice [m].
pub const LATTICE_GAP: f32 = 0.005;

/// Which part the pile is made of.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PileKind {
    Nuts,
    Bowls,
    Toruses,
}

impl PileKind {
    /// The scene's name on the command line and in reports.
    pub fn scene_name(self) -> &'static str {
        match self {
            PileKind::Nuts => "pile-nuts",
            PileKind::Bowls => "pile-bowls",
            PileKind::Toruses => "pile-toruses",
        }
    }

    /// The paper's solver settings for the scene (Table II: nuts and toruses 1 substep and 16 position
    /// iterations, bowls 2 substeps and 50; 1 velocity iteration each).
    pub fn paper_solver(self) -> SolverConfig {
        let (substeps, pos_iters) = if self == PileKind::Bowls { (2, 50) } else { (1, 16) };
        SolverConfig { substeps, pos_iters, vel_iters: 1, ..Default::default() }
    }
}

/// One pile world: the contact pairs, the bodies and their starting poses.
pub struct PileScene {
    pub contacts: ContactModel,
    pub bodies: BodyModel,
    /// Starting body poses of one world, shape [body_count].
    pub start: Vec<TransformGpu>,
    /// Mass properties of one part.
    pub part: MassProperties,
    /// Query triangles of one part.
    pub triangles: usize,
}

/// A uniformly random rotation (Shoemake 1992, "Uniform random rotations", Graphics Gems III).
fn random_rotation(rng: &mut SplitMix64) -> Quat {
    let (u1, u2, u3) = (rng.unit(), rng.unit(), rng.unit());
    let (a, b) = ((1.0 - u1).sqrt(), u1.sqrt());
    let t = std::f32::consts::TAU;
    Quat::from_xyzw(a * (t * u2).sin(), a * (t * u2).cos(), b * (t * u3).sin(), b * (t * u3).cos()).normalize()
}

/// Builds a pile of `bodies` parts: every pair of parts and every part with the ground, friction `mu`,
/// contact offset `contact_offset` [m]; parts start in a lattice of `ceil(sqrt(bodies / 4))` squared per
/// layer (a column about four layers tall), each turned at random (`seed`).
pub fn pile_scene(kind: PileKind, bodies: u32, contact_offset: f32, mu: f32, seed: u64) -> Result<PileScene> {
    ensure!(bodies >= 1, "--bodies must be at least 1");
    ensure!(mu.is_finite() && mu >= 0.0, "--mu must be a finite coefficient >= 0, got {mu}");
    let (mesh, part, sdf): (TriMesh, MassProperties, SdfShape) = match kind {
        PileKind::Toruses => {
            let t = torus(&TorusOptions::default())?;
            (t.part.mesh, t.part.mass_properties, SdfShape::Revolved(t.sdf))
        }
        PileKind::Bowls => {
            let b = bowl(&BowlOptions::default())?;
            (b.part.mesh, b.part.mass_properties, SdfShape::Revolved(b.sdf))
        }
        PileKind::Nuts => {
            let opts = ThreadOptions { segments_per_turn: NUT_SEGMENTS_PER_TURN, ..Default::default() };
            let nut = nut_bolt(IsoSize::M16, Fit::Tight, &opts)?.nut;
            let cache = SdfCache::new(SdfCache::default_dir());
            let params = BakeParams { resolution: NUT_PILE_SDF_RESOLUTION, ..Default::default() };
            let grid = cache.get_or_bake_shared(&nut.mesh, &params).context("baking the nut's SDF")?;
            (nut.mesh, nut.mass_properties, SdfShape::Grid(grid))
        }
    };
    let query = Arc::new(QueryShape::mesh(&mesh));
    let identity = (Vec3::ZERO, Quat::IDENTITY);
    let pair = |a: u32, b: u32, sdf: SdfShape| PairSpec {
        body_a: a,
        a_pose: identity,
        query: query.clone(),
        body_b: b,
        b_pose: identity,
        sdf,
        contact_offset,
        friction: mu,
    };
    let mut pairs = Vec::new();
    for i in 0..bodies {
        pairs.push(pair(i, NO_BODY, SdfShape::Plane));
    }
    for i in 0..bodies {
        for j in i + 1..bodies {
            pairs.push(pair(i, j, sdf.clone()));
        }
    }
    let contacts = ContactModel { body_count: bodies, pairs };
    let mut model = BodyModel { gravity: Vec3::new(0.0, 0.0, -9.81), ..Default::default() };
    for _ in 0..bodies {
        model.add_dynamic(part.mass, part.inertia, part.com);
    }
    // The lattice: bounding spheres (about the centre of mass) LATTICE_GAP apart, the lowest layer that far
    // above the ground.
    let reach = mesh.positions.iter().map(|v| v.distance(part.com)).fold(0.0f32, f32::max);
    let pitch = 2.0 * reach + LATTICE_GAP;
    let side = ((bodies as f32 / 4.0).sqrt().ceil() as u32).max(1);
    let mut rng = SplitMix64(seed);
    let start = (0..bodies)
        .map(|i| {
            let (layer, cell) = (i / (side * side), i % (side * side));
            let com = Vec3::new(
                (cell % side) as f32 - 0.5 * (side - 1) as f32,
                (cell / side) as f32 - 0.5 * (side - 1) as f32,
                0.0,
            ) * pitch
                + Vec3::new(0.0, 0.0, reach + LATTICE_GAP + layer as f32 * pitch);
            let q = random_rotation(&mut rng);
            TransformGpu::new(com - q * part.com, q)
        })
        .collect();
    Ok(PileScene { contacts, bodies: model, start, part, triangles: mesh.triangle_count() })
}

impl PileScene {
    /// Gravity's magnitude [m/s^2] (down, -z).
    pub fn g(&self) -> f64 {
        -self.bodies.gravity.z as f64
    }
}

/// Settings of one pile run.
#[derive(Clone, Debug)]
pub struct PileRun {
    pub kind: PileKind,
    pub bodies: u32,
    pub worlds: u32,
    /// Simulated time [s].
    pub seconds: f32,
    pub contact: ContactConfig,
    pub solver: SolverConfig,
    pub mu: f32,
    /// Contact offset [m].
    pub contact_offset: f32,
    pub seed: u64,
}

/// What a pile run measured (the columns of the paper's Tables I and II, and the physical checks).
#[derive(Clone, Debug, serde::Serialize)]
pub struct PileReport {
    pub scene: &'static str,
    pub bodies: u32,
    pub worlds: u32,
    /// Candidate pairs per world (every pair of bodies and every body with the ground).
    pub pairs: usize,
    pub query_triangles: usize,
    pub seconds: f32,
    pub frames: u32,
    /// The solver settings (Table II's columns).
    #[serde(flatten)]
    pub solver: SolverColumns,
    pub max_patches: u32,
    pub mu: f32,
    /// Last frame, summed over worlds: contact candidates before reduction, contacts after it, patches,
    /// and pairs with at least one patch.
    pub contacts_before: u64,
    pub contacts_after: u64,
    pub patches: u64,
    pub touching_pairs: u64,
    /// Last frame, world 0: pairs of two bodies (not body and ground) with a contact within 0.5 mm, i.e.
    /// bodies lying on bodies ...
    pub resting_body_pairs: u64,
    /// ... and the highest centre of mass [mm] (a single layer of toruses: 8 mm).
    pub pile_height_mm: f64,
    pub wall_s: f64,
    pub ms_per_frame: f64,
    /// Where the time goes (paper Table I), timed after the run on its last state: contact handling and
    /// the solver step [ms per frame].
    pub handling_ms_per_frame: f64,
    pub solve_ms_per_frame: f64,
    pub real_time_factor_per_world: f64,
    pub body_seconds_per_wall_second: f64,
    /// Fastest centre of mass of any body at any frame end [m/s] ...
    pub max_speed_m_s: f64,
    /// ... against free fall from the highest start to the ground [m/s] ...
    pub free_fall_speed_m_s: f64,
    /// ... and against the speed of one body carrying all the potential energy the pile can release
    /// (sum of m g z over the bodies' centres of mass; a hard bound: contacts only dissipate) [m/s].
    pub energy_bound_speed_m_s: f64,
    /// Largest total energy (kinetic + potential, world 0) over the start's, minus 1 [unitless].
    pub max_energy_gain: f64,
    /// Fastest body at the last frame [m/s] ...
    pub final_max_speed_m_s: f64,
    /// ... and the farthest any body's centre of mass moved over the last second (or the whole run if
    /// shorter) [mm]: a pile at rest jitters in place, it does not creep.
    pub last_second_max_drift_mm: f64,
    /// Deepest contact at any frame start [mm] (positive: penetration).
    pub max_penetration_mm: f64,
    pub finite: bool,
    /// Worlds whose step did not fit lavapipe's loop budget (flagged, not stepped) in any frame.
    pub over_loop_budget: bool,
    pub adapter: String,
}

/// Total energy of world 0 [J]: kinetic (translation and rotation) plus potential m g z of the centres of
/// mass.
pub fn total_energy(scene: &PileScene, s: &BodyState) -> f64 {
    let n = scene.bodies.body_count();
    let (m, i_body, g) = (scene.part.mass as f64, scene.part.inertia, scene.g());
    (0..n)
        .map(|b| {
            let t = s.body_q[b];
            let q = Quat::from_array(t.q);
            let com = Vec3::from_slice(&t.p[..3]) + q * scene.part.com;
            let [v, w] = s.body_qd[b];
            let w_body = q.inverse() * w;
            0.5 * m * v.length_squared() as f64 + 0.5 * w_body.dot(i_body * w_body) as f64 + m * g * com.z as f64
        })
        .sum()
}

/// Runs a pile; every world starts from the same lattice.
pub fn run_pile(gpu: &GpuContext, run: &PileRun) -> Result<PileReport> {
    ensure!(run.worlds > 0, "--worlds must be at least 1");
    ensure!(run.seconds > 0.0 && run.seconds.is_finite(), "--seconds must be > 0, got {}", run.seconds);
    run.solver.validate()?;
    let scene = pile_scene(run.kind, run.bodies, run.contact_offset, run.mu, run.seed)?;
    let pipe = ContactPipeline::new(gpu, &scene.contacts, run.worlds, &run.contact)?;
    let solver = GpuSolver::new(gpu, &pipe, &scene.bodies, &run.solver)?;
    let n = run.bodies as usize;
    let state = BodyState {
        body_q: (0..run.worlds).flat_map(|_| scene.start.iter().copied()).collect(),
        body_qd: vec![[Vec3::ZERO; 2]; n * run.worlds as usize],
    };
    let e0 = total_energy(&scene, &state);
    let coms = |s: &BodyState| -> Vec<Vec3> {
        s.body_q.iter().map(|t| Vec3::from_slice(&t.p[..3]) + Quat::from_array(t.q) * scene.part.com).collect()
    };
    let start_com = coms(&state);
    let top = start_com[..n].iter().map(|c| c.z).fold(0.0f32, f32::max) as f64;
    let released: f64 = start_com[..n].iter().map(|c| c.z as f64).sum::<f64>() * scene.g();
    crate::scene::warm_up(gpu, &pipe, &solver, &state);
    let frames = (run.seconds / run.solver.dt).round().max(1.0) as u32;
    let (mut wall, mut deepest, mut max_speed, mut max_energy) = (0.0f64, f32::INFINITY, 0.0f64, e0);
    let (mut finite, mut over) = (true, false);
    let mut last = state.clone();
    let second_before_end = frames.saturating_sub((1.0 / run.solver.dt).round() as u32);
    let mut mark = start_com.clone();
    for f in 0..frames {
        if f == second_before_end {
            mark = coms(&last);
        }
        let t = Instant::now();
        solver.submit_frame(gpu, &pipe);
        gpu.wait();
        wall += t.elapsed().as_secs_f64();
        let c = pipe.read(gpu);
        if let Some(d) = crate::scene::min_depth_all(&c) {
            deepest = deepest.min(d);
        }
        let (s, ok) = solver.read_state(gpu, &pipe);
        finite &= ok.iter().all(|&o| o);
        over |= solver.worlds_over_loop_budget(gpu).iter().any(|&o| o);
        max_speed = max_speed.max(s.body_qd.iter().map(|v| v[0].length()).fold(0.0f32, f32::max) as f64);
        max_energy = max_energy.max(total_energy(&scene, &s));
        last = s;
    }
    let c = pipe.read(gpu);
    let contacts_after: u64 = c.patches.iter().flat_map(|ps| ps.iter().map(|p| p.contacts.len() as u64)).sum();
    let patches: u64 = c.patches.iter().map(|ps| ps.len() as u64).sum();
    let touching_pairs = c.patches.iter().filter(|ps| !ps.is_empty()).count() as u64;
    let resting_body_pairs = (0..scene.contacts.pairs.len())
        .filter(|&i| scene.contacts.pairs[i].body_b != NO_BODY)
        .filter(|&i| c.patches[i].iter().any(|p| p.contacts.iter().any(|k| k.depth <= 0.5e-3)))
        .count() as u64;
    let pile_height = coms(&last)[..n].iter().map(|c| c.z).fold(0.0f32, f32::max);
    let (handling_ms, solve_ms) = crate::scene::time_split(gpu, &pipe, &solver, frames.min(10));
    let sim = frames as f64 * run.solver.dt as f64;
    Ok(PileReport {
        scene: run.kind.scene_name(),
        bodies: run.bodies,
        worlds: run.worlds,
        pairs: scene.contacts.pairs.len(),
        query_triangles: scene.triangles,
        seconds: sim as f32,
        frames,
        solver: (&run.solver).into(),
        max_patches: run.contact.max_patches,
        mu: run.mu,
        contacts_before: c.candidates.iter().map(|&k| k as u64).sum(),
        contacts_after,
        patches,
        touching_pairs,
        resting_body_pairs,
        pile_height_mm: pile_height as f64 * 1e3,
        wall_s: wall,
        ms_per_frame: wall * 1e3 / frames as f64,
        handling_ms_per_frame: handling_ms,
        solve_ms_per_frame: solve_ms,
        real_time_factor_per_world: sim / wall,
        body_seconds_per_wall_second: (run.bodies * run.worlds) as f64 * sim / wall,
        max_speed_m_s: max_speed,
        free_fall_speed_m_s: (2.0 * scene.g() * top).sqrt(),
        energy_bound_speed_m_s: (2.0 * released).sqrt(),
        max_energy_gain: max_energy / e0 - 1.0,
        last_second_max_drift_mm: coms(&last).iter().zip(&mark).map(|(a, b)| a.distance(*b)).fold(0.0f32, f32::max)
            as f64
            * 1e3,
        final_max_speed_m_s: last.body_qd.iter().map(|v| v[0].length()).fold(0.0f32, f32::max) as f64,
        max_penetration_mm: (-deepest as f64 * 1e3).max(0.0),
        finite,
        over_loop_budget: over,
        adapter: gpu.info.name.clone(),
    })
}

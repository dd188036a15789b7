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
//! Two solvers ([`PileSolver`]):
//! - `coloured` (default): the many-body world of `factory_engine::many_body`: each frame the near pairs are
//!   found on the GPU (bounding spheres), their contacts generated and reduced, and the Gauss-Seidel sweep
//!   cut into one dispatch per colour of a graph colouring of the pairs: any number of bodies (the
//!   paper's 1024).
//! - `serial`: every pair of bodies in a fixed list, the broad phase skipping the far ones, and the world
//!   stepped by one invocation (`GpuSolver`); lavapipe's 65535 loop passes per invocation limit this to a
//!   few dozen bodies per world (measured: 32 toruses fit).

use crate::scene::SolverColumns;
use anyhow::{ensure, Context, Result};
use factory_assets::pile::{bowl, torus, BowlOptions, TorusOptions};
use factory_assets::{nut_bolt, Fit, IsoSize, ThreadOptions};
use factory_engine::contact::{
    ContactConfig, ContactModel, ContactPipeline, PairSpec, QueryShape, SdfShape, TransformGpu, NO_BODY,
};
use factory_engine::gpu::GpuContext;
use factory_engine::many_body::gpu::ManyBodyPipeline;
use factory_engine::many_body::{ManyBodyConfig, ManyBodyFlat, ManyBodyModel, SleepConfig};
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

/// Which solver steps a pile (see the module doc).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum PileSolver {
    /// Near pairs found every frame, graph-coloured Gauss-Seidel (`factory_engine::many_body`).
    Coloured,
    /// All pairs in a fixed list, one invocation per world (`GpuSolver`).
    Serial,
}

/// One pile world: the contact pairs, the bodies and their starting poses.
pub struct PileScene {
    /// Every body with every body and with the ground, as templates (the near pairs are found per frame).
    pub many_body: ManyBodyModel,
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
    let many_body = ManyBodyModel::uniform(bodies, pair(0, 1, sdf), vec![pair(0, NO_BODY, SdfShape::Plane)]);
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
    Ok(PileScene { many_body, bodies: model, start, part, triangles: mesh.triangle_count() })
}

impl PileScene {
    /// The fixed pair list of the serial solver: each body with the ground (pairs 0..n), then every pair
    /// of bodies (i, j), i < j.
    pub fn fixed_pairs(&self) -> ContactModel {
        let n = self.many_body.body_count;
        let with = |a: u32, b: u32, t: &PairSpec| PairSpec { body_a: a, body_b: b, ..t.clone() };
        let mut pairs: Vec<PairSpec> = (0..n).map(|i| with(i, NO_BODY, &self.many_body.templates[1])).collect();
        for i in 0..n {
            for j in i + 1..n {
                pairs.push(with(i, j, &self.many_body.templates[0]));
            }
        }
        ContactModel { body_count: n, pairs }
    }

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
    pub pile_solver: PileSolver,
    /// Frames at the end of the run for which the fastest bodies of world 0 are printed on stderr, one
    /// line per frame (index, speed, velocity, spin, centre of mass): what shows a nut orbiting between two
    /// poses for good (docs/BENCHMARKS.md). 0: none.
    pub trace_frames: u32,
    /// Sleeping of bodies that stay put (coloured solver only; `factory_engine::many_body::SleepConfig`).
    pub sleep: SleepConfig,
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
    pub pile_solver: PileSolver,
    /// Near pairs (bodies within reach of each other or of the ground) at the last frame, world 0 ...
    pub near_pairs: u64,
    /// ... and the most colours the coloured solver needed in any frame (0: serial solver).
    pub colours: u32,
    /// The solver settings (Table II's columns).
    #[serde(flatten)]
    pub solver: SolverColumns,
    pub max_patches: u32,
    /// Candidates per invocation of the contact kernels (ContactConfig::candidates_per_invocation).
    pub candidates_per_invocation: u32,
    /// Invocations per contact workgroup (ContactConfig::workgroup_size).
    pub workgroup_size: u32,
    pub mu: f32,
    /// Last frame, summed over worlds: contact candidates before reduction, contacts after it, patches,
    /// and pairs with at least one patch.
    pub contacts_before: u64,
    pub contacts_after: u64,
    pub patches: u64,
    pub touching_pairs: u64,
    /// Last frame, world 0: pairs of two bodies (not body and ground) with a contact within 0.5 mm, i.e.
    /// bodies lying on bodies (with sleeping, whose pairs of sleepers get no contacts: at the end of the
    /// woken check below, every body awake) ...
    pub resting_body_pairs: u64,
    /// ... and the highest centre of mass [mm] (a single layer of toruses: 8 mm).
    pub pile_height_mm: f64,
    pub wall_s: f64,
    pub ms_per_frame: f64,
    /// ... and per simulated second in turn (a settling pile, sleepers that get no contacts) [ms].
    pub ms_per_frame_per_second: Vec<f64>,
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
    /// ... the median over the last second's frames of the fastest body's speed (a pile at rest may show a
    /// single frame's jitter; this is its typical speed) [m/s] ...
    pub last_second_median_max_speed_m_s: f64,
    /// ... and that median for each simulated second in turn (the last entry covers what is left) [m/s] ...
    pub median_max_speed_per_second_m_s: Vec<f64>,
    /// ... and the farthest any body's centre of mass moved over the last second (or the whole run if
    /// shorter) [mm]: a pile at rest jitters in place, it does not creep ...
    pub last_second_max_drift_mm: f64,
    /// ... which body that was, and where its centre of mass ended [m] (a body sliding off the pile's rim
    /// and one creeping inside it are different problems).
    pub last_second_max_drift_body: u32,
    pub last_second_max_drift_end_m: [f32; 3],
    /// Bodies of world 0 faster than [`MOVING_SPEED`] at the last frame.
    pub final_moving_bodies: u32,
    /// Deepest contact at any frame start [mm] (positive: penetration) ...
    pub max_penetration_mm: f64,
    /// ... and in each simulated second in turn [mm] (landing frames against a settled pile). With
    /// sleeping, pairs whose bodies all sleep have no contacts and do not count: a pile asleep reports 0.
    pub max_penetration_per_second_mm: Vec<f64>,
    /// Every pose and velocity stayed finite.
    pub finite: bool,
    /// Worlds whose step did not fit lavapipe's loop budget or (coloured solver) the near-pair, colour or
    /// patch capacities (flagged, not stepped) in any frame ...
    pub over_loop_budget: bool,
    /// ... in how many frames ...
    pub flagged_frames: u32,
    /// ... and why (coloured solver: factory_engine::many_body::FLAG_* bits seen).
    pub flags_seen: u32,
    /// Sleeping (0 frames: off): frames a body must stay within the distance [mm] and angle [rad] of one
    /// pose to fall asleep ...
    pub sleep_frames: u32,
    pub sleep_distance_mm: f64,
    pub sleep_angle_rad: f64,
    /// ... and the bodies of world 0 asleep at the last frame, and at the end of each simulated second. A
    /// sleeping body has zero velocity and does not move: the rest figures above count it as at rest.
    pub final_asleep_bodies: u32,
    pub asleep_bodies_per_second: Vec<u32>,
    /// Whether the sleepers rested where they slept: after the run every body is woken (the last state
    /// uploaded again, warm start forgotten) and stepped [`WAKE_FRAMES`] frames (0.25 s); the farthest any
    /// centre of mass of world 0 then moved [mm] (a sleeper left unsupported would fall g t^2 / 2 = 306 mm)
    /// and which body (-1: sleeping off).
    pub woken_max_drift_mm: f64,
    pub woken_max_drift_body: i64,
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
    ensure!(
        !(run.sleep.enabled() && run.pile_solver == PileSolver::Serial),
        "--sleep-frames {}: sleeping is a feature of the coloured pile solver; use --pile-solver coloured or \
         --sleep-frames 0",
        run.sleep.frames
    );
    let scene = pile_scene(run.kind, run.bodies, run.contact_offset, run.mu, run.seed)?;
    match run.pile_solver {
        PileSolver::Coloured => run_coloured(gpu, run, &scene),
        PileSolver::Serial => run_serial(gpu, run, &scene),
    }
}

/// The figures both solvers report, gathered frame by frame.
struct Tally {
    n: usize,
    e0: f64,
    top: f64,
    released: f64,
    /// Wall time of each frame [s].
    frame_walls: Vec<f64>,
    max_speed: f64,
    max_energy: f64,
    finite: bool,
    over: bool,
    flagged_frames: u32,
    flags_seen: u32,
    mark: Vec<Vec3>,
    last: BodyState,
    frames: u32,
    second_before_end: u32,
    /// PileRun::trace_frames.
    trace_frames: u32,
    /// The fastest body's speed at each frame end [m/s].
    speeds: Vec<f64>,
    /// The deepest contact at each frame start [m] (+inf: none).
    depths: Vec<f32>,
}

impl Tally {
    /// A frame's wall time [s].
    fn add_wall(&mut self, secs: f64) {
        self.frame_walls.push(secs);
    }

    /// Wall time of the frames so far [s].
    fn wall(&self) -> f64 {
        self.frame_walls.iter().sum()
    }

    fn new(scene: &PileScene, run: &PileRun, state: &BodyState) -> Self {
        let n = run.bodies as usize;
        let start_com = coms(scene, state);
        let e0 = total_energy(scene, state);
        let frames = (run.seconds / run.solver.dt).round().max(1.0) as u32;
        Tally {
            n,
            e0,
            top: start_com[..n].iter().map(|c| c.z).fold(0.0f32, f32::max) as f64,
            released: start_com[..n].iter().map(|c| c.z as f64).sum::<f64>() * scene.g(),
            frame_walls: Vec::new(),
            max_speed: 0.0,
            max_energy: e0,
            finite: true,
            over: false,
            flagged_frames: 0,
            flags_seen: 0,
            mark: start_com,
            last: state.clone(),
            frames,
            second_before_end: frames.saturating_sub((1.0 / run.solver.dt).round() as u32),
            trace_frames: run.trace_frames,
            speeds: Vec::new(),
            depths: Vec::new(),
        }
    }

    /// Before frame f.
    fn before(&mut self, scene: &PileScene, f: u32) {
        if f == self.second_before_end {
            self.mark = coms(scene, &self.last);
        }
    }

    /// After a frame: its state, whether some world was flagged and not stepped (and why: factory_engine::many_body FLAG_*
    /// bits), and the deepest contact it started from.
    fn after(&mut self, scene: &PileScene, s: BodyState, flagged: bool, flags: u32, deepest: Option<f32>) {
        self.depths.push(deepest.unwrap_or(f32::INFINITY));
        self.over |= flagged;
        self.flagged_frames += flagged as u32;
        self.flags_seen |= flags;
        let finite = |v: Vec3| v.is_finite();
        self.finite &= s.body_q.iter().all(|t| t.p.iter().chain(&t.q).all(|x| x.is_finite()))
            && s.body_qd.iter().all(|v| finite(v[0]) && finite(v[1]));
        let fastest = s.body_qd.iter().map(|v| v[0].length()).fold(0.0f32, f32::max) as f64;
        self.max_speed = self.max_speed.max(fastest);
        self.speeds.push(fastest);
        self.max_energy = self.max_energy.max(total_energy(scene, &s));
        if self.speeds.len() as u32 + self.trace_frames > self.frames {
            eprintln!("trace frame {}: {}", self.speeds.len(), fastest_bodies(scene, &s, self.n, 3));
        }
        self.last = s;
    }
}

/// The `count` fastest of world 0's `n` bodies: index, speed [m/s], velocity [m/s], spin [rad/s] and
/// centre of mass [m] each (PileRun::trace_frames).
fn fastest_bodies(scene: &PileScene, s: &BodyState, n: usize, count: usize) -> String {
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| s.body_qd[b][0].length().total_cmp(&s.body_qd[a][0].length()));
    let c = coms(scene, s);
    let body = |i: usize| {
        let [v, w] = s.body_qd[i];
        format!(
            "{i} {:.4} m/s ({:.4}, {:.4}, {:.4}) spin {:.2} rad/s at ({:.4}, {:.4}, {:.4}) m",
            v.length(),
            v.x,
            v.y,
            v.z,
            w.length(),
            c[i].x,
            c[i].y,
            c[i].z
        )
    };
    order.into_iter().take(count).map(body).collect::<Vec<_>>().join(" | ")
}

fn coms(scene: &PileScene, s: &BodyState) -> Vec<Vec3> {
    s.body_q.iter().map(|t| Vec3::from_slice(&t.p[..3]) + Quat::from_array(t.q) * scene.part.com).collect()
}

/// Contact figures of the last frame (summed over worlds; resting pairs of world 0).
struct LastContacts {
    candidates: u64,
    contacts: u64,
    patches: u64,
    touching: u64,
    resting_body_pairs: u64,
    near_pairs: u64,
    colours: u32,
    /// Bodies of world 0 asleep at the end of each second and at the last frame (empty: sleeping off).
    asleep_per_second: Vec<u32>,
    /// [`woken_drift`] (sleeping only): (body, distance [m]).
    woken: Option<(usize, f32)>,
}

/// Frames the pile is stepped after waking every body (`PileReport::woken_max_drift_mm`).
pub const WAKE_FRAMES: u32 = 15;

/// Whether the sleepers were resting where they slept: the last state uploaded again (which wakes every
/// body and forgets the warm start), stepped [`WAKE_FRAMES`] frames; the farthest any centre of mass of
/// world 0 moved: (body, distance [m]).
fn woken_drift(gpu: &GpuContext, pipe: &ManyBodyPipeline, scene: &PileScene, n: usize) -> (usize, f32) {
    let (end, _) = pipe.read_state(gpu);
    pipe.write_state(gpu, &end);
    for _ in 0..WAKE_FRAMES {
        pipe.submit_frame(gpu);
    }
    let (after, _) = pipe.read_state(gpu);
    let (a, b) = (coms(scene, &end), coms(scene, &after));
    arg_max(a[..n].iter().zip(&b[..n]).map(|(x, y)| x.distance(*y)))
}

fn report(
    scene: &PileScene,
    run: &PileRun,
    t: Tally,
    c: LastContacts,
    (handling_ms, solve_ms): (f64, f64),
    gpu: &GpuContext,
) -> PileReport {
    let n = t.n;
    let sim = t.frames as f64 * run.solver.dt as f64;
    let wall = t.wall();
    let end = coms(scene, &t.last);
    let pile_height = end[..n].iter().map(|c| c.z).fold(0.0f32, f32::max);
    // The farthest any centre of mass moved over the last second: (body, distance [m]).
    let drift = arg_max(end.iter().zip(&t.mark).map(|(a, b)| a.distance(*b)));
    let per_second = (1.0 / run.solver.dt).round().max(1.0) as usize;
    PileReport {
        scene: run.kind.scene_name(),
        bodies: run.bodies,
        worlds: run.worlds,
        pairs: n * (n - 1) / 2 + n,
        query_triangles: scene.triangles,
        seconds: sim as f32,
        frames: t.frames,
        pile_solver: run.pile_solver,
        near_pairs: c.near_pairs,
        colours: c.colours,
        solver: (&run.solver).into(),
        max_patches: run.contact.max_patches,
        candidates_per_invocation: run.contact.candidates_per_invocation,
        workgroup_size: run.contact.workgroup_size,
        mu: run.mu,
        contacts_before: c.candidates,
        contacts_after: c.contacts,
        patches: c.patches,
        touching_pairs: c.touching,
        resting_body_pairs: c.resting_body_pairs,
        pile_height_mm: pile_height as f64 * 1e3,
        wall_s: wall,
        ms_per_frame: wall * 1e3 / t.frames as f64,
        ms_per_frame_per_second: t
            .frame_walls
            .chunks(per_second)
            .map(|c| c.iter().sum::<f64>() * 1e3 / c.len() as f64)
            .collect(),
        handling_ms_per_frame: handling_ms,
        solve_ms_per_frame: solve_ms,
        real_time_factor_per_world: sim / wall,
        body_seconds_per_wall_second: (run.bodies * run.worlds) as f64 * sim / wall,
        max_speed_m_s: t.max_speed,
        free_fall_speed_m_s: (2.0 * scene.g() * t.top).sqrt(),
        energy_bound_speed_m_s: (2.0 * t.released).sqrt(),
        max_energy_gain: t.max_energy / t.e0 - 1.0,
        last_second_max_drift_mm: drift.1 as f64 * 1e3,
        last_second_max_drift_body: (drift.0 % n) as u32,
        last_second_max_drift_end_m: end[drift.0].to_array(),
        final_moving_bodies: moving_bodies(&t.last.body_qd[..n]) as u32,
        final_max_speed_m_s: t.speeds.last().copied().unwrap_or(0.0),
        last_second_median_max_speed_m_s: median(&t.speeds[(t.second_before_end as usize).min(t.speeds.len())..]),
        median_max_speed_per_second_m_s: t.speeds.chunks(per_second).map(median).collect(),
        max_penetration_mm: penetration_mm(&t.depths),
        max_penetration_per_second_mm: t.depths.chunks(per_second).map(penetration_mm).collect(),
        finite: t.finite,
        over_loop_budget: t.over,
        flagged_frames: t.flagged_frames,
        flags_seen: t.flags_seen,
        sleep_frames: run.sleep.frames,
        sleep_distance_mm: run.sleep.distance as f64 * 1e3,
        sleep_angle_rad: run.sleep.angle as f64,
        final_asleep_bodies: c.asleep_per_second.last().copied().unwrap_or(0),
        asleep_bodies_per_second: c.asleep_per_second,
        woken_max_drift_mm: c.woken.map_or(0.0, |w| w.1 as f64 * 1e3),
        woken_max_drift_body: c.woken.map_or(-1, |w| w.0 as i64),
        adapter: gpu.info.name.clone(),
    }
}

/// A body faster than this is moving [m/s] (the pile tests' bar for the fastest body at rest).
pub const MOVING_SPEED: f32 = 0.01;

/// How many of these bodies are faster than [`MOVING_SPEED`].
fn moving_bodies(body_qd: &[[Vec3; 2]]) -> usize {
    body_qd.iter().filter(|v| v[0].length() > MOVING_SPEED).count()
}

/// The index and value of the largest of `v` ((0, 0) when empty or all below 0).
fn arg_max(v: impl Iterator<Item = f32>) -> (usize, f32) {
    v.enumerate().fold((0, 0.0), |a, (i, x)| if x > a.1 { (i, x) } else { a })
}

/// The deepest of these contact depths as a penetration [mm] (0 when none penetrates).
fn penetration_mm(depths: &[f32]) -> f64 {
    (-depths.iter().copied().fold(f32::INFINITY, f32::min) as f64 * 1e3).max(0.0)
}

/// The median of `v` (the upper one of an even count; 0 when empty).
fn median(v: &[f64]) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(0.0)
}

fn start_state(scene: &PileScene, run: &PileRun) -> BodyState {
    BodyState {
        body_q: (0..run.worlds).flat_map(|_| scene.start.iter().copied()).collect(),
        body_qd: vec![[Vec3::ZERO; 2]; run.bodies as usize * run.worlds as usize],
    }
}

/// The coloured solver (`factory_engine::many_body`).
fn run_coloured(gpu: &GpuContext, run: &PileRun, scene: &PileScene) -> Result<PileReport> {
    let cfg = ManyBodyConfig { sleep: run.sleep, ..ManyBodyConfig::for_bodies(run.bodies) };
    let pipe =
        ManyBodyPipeline::new(gpu, &scene.many_body, &scene.bodies, run.worlds, &cfg, &run.contact, &run.solver)?;
    let state = start_state(scene, run);
    let mut t = Tally::new(scene, run, &state);
    // An untimed frame first: lavapipe compiles the shaders at their first dispatch.
    pipe.write_state(gpu, &state);
    pipe.submit_frame(gpu);
    gpu.wait();
    pipe.write_state(gpu, &state);
    let mut colours = 0;
    let per_second = (1.0 / run.solver.dt).round().max(1.0) as u32;
    let mut asleep_per_second = Vec::new();
    let asleep_now = || -> u32 {
        if !run.sleep.enabled() {
            return 0;
        }
        let rest = pipe.read_rest(gpu);
        rest[..run.bodies as usize].iter().filter(|r| r.asleep(&run.sleep)).count() as u32
    };
    for f in 0..t.frames {
        t.before(scene, f);
        let clock = Instant::now();
        pipe.submit_frame(gpu);
        gpu.wait();
        t.add_wall(clock.elapsed().as_secs_f64());
        let (frames, patches): (Vec<_>, Vec<_>) = pipe.read_patches(gpu).into_iter().unzip();
        let deepest = patches
            .iter()
            .flatten()
            .flat_map(|ps| ps.iter().flat_map(|p| p.contacts.iter().map(|c| c.depth)))
            .reduce(f32::min);
        colours = colours.max(frames.iter().map(|f| f.colour_count).max().unwrap_or(0));
        let near0 = frames[0].pairs.len();
        let flags = frames.iter().fold(0, |a, f| a | f.flags);
        let (s, _) = pipe.read_state(gpu);
        if run.bodies >= 256 && (f + 1) % 30 == 0 {
            // Long runs say how far they are and where the fastest body is (stderr: the report on stdout
            // stays one JSON object), so a pile that does not settle shows what keeps moving.
            let moving = moving_bodies(&s.body_qd[..t.n]);
            eprintln!(
                "frame {}/{}: {} near pairs, {:.0} ms per frame so far, fastest body {}, {moving} bodies over \
                 {MOVING_SPEED} m/s, {} asleep",
                f + 1,
                t.frames,
                near0,
                t.wall() * 1e3 / (f + 1) as f64,
                fastest_bodies(scene, &s, t.n, 1),
                asleep_now()
            );
        }
        if run.sleep.enabled() && ((f + 1) % per_second == 0 || f + 1 == t.frames) {
            asleep_per_second.push(asleep_now());
        }
        t.after(scene, s, flags != 0, flags, deepest);
    }
    let stats = pipe.read_stats(gpu);
    let resting = |pipe: &ManyBodyPipeline| {
        let (frame0, patches0) = &pipe.read_patches(gpu)[0];
        frame0
            .pairs
            .iter()
            .zip(patches0)
            .filter(|(np, ps)| np.b != NO_BODY && ps.iter().any(|p| p.contacts.iter().any(|k| k.depth <= 0.5e-3)))
            .count() as u64
    };
    // After the last frame's figures are read: it steps the pile on (and the resting pairs are counted
    // after it, every body awake).
    let woken = run.sleep.enabled().then(|| woken_drift(gpu, &pipe, scene, t.n));
    let resting_body_pairs = resting(&pipe);
    let c = LastContacts {
        candidates: stats.iter().map(|s| s.candidates).sum(),
        contacts: stats.iter().map(|s| s.contacts as u64).sum(),
        patches: stats.iter().map(|s| s.patches as u64).sum(),
        touching: stats.iter().map(|s| s.touching_pairs as u64).sum(),
        resting_body_pairs,
        near_pairs: stats[0].pairs as u64,
        colours,
        asleep_per_second,
        woken,
    };
    let split = crate::scene::time_parts(gpu, t.frames.min(10), &|enc| pipe.encode_handling(enc), &|enc| {
        pipe.encode_solve(enc)
    });
    Ok(report(scene, run, t, c, split, gpu))
}

/// The serial solver: all pairs fixed, one invocation per world.
fn run_serial(gpu: &GpuContext, run: &PileRun, scene: &PileScene) -> Result<PileReport> {
    let fixed = scene.fixed_pairs();
    let pipe = ContactPipeline::new(gpu, &fixed, run.worlds, &run.contact)?;
    let solver = GpuSolver::new(gpu, &pipe, &scene.bodies, &run.solver)?;
    let state = start_state(scene, run);
    let mut t = Tally::new(scene, run, &state);
    crate::scene::warm_up(gpu, &pipe, &solver, &state);
    for f in 0..t.frames {
        t.before(scene, f);
        let clock = Instant::now();
        solver.submit_frame(gpu, &pipe);
        gpu.wait();
        t.add_wall(clock.elapsed().as_secs_f64());
        let deepest = crate::scene::min_depth_all(&pipe.read(gpu));
        let (s, _) = solver.read_state(gpu, &pipe);
        let over = solver.worlds_over_loop_budget(gpu).iter().any(|&o| o);
        t.after(scene, s, over, 0, deepest);
    }
    let c = pipe.read(gpu);
    let last = LastContacts {
        candidates: c.candidates.iter().map(|&k| k as u64).sum(),
        contacts: c.patches.iter().flat_map(|ps| ps.iter().map(|p| p.contacts.len() as u64)).sum(),
        patches: c.patches.iter().map(|ps| ps.len() as u64).sum(),
        touching: c.patches.iter().filter(|ps| !ps.is_empty()).count() as u64,
        resting_body_pairs: (0..fixed.pairs.len())
            .filter(|&i| fixed.pairs[i].body_b != NO_BODY)
            .filter(|&i| c.patches[i].iter().any(|p| p.contacts.iter().any(|k| k.depth <= 0.5e-3)))
            .count() as u64,
        near_pairs: {
            let xf: Vec<_> = t.last.body_q.iter().map(|q| q.xf()).collect();
            ManyBodyFlat::new(&scene.many_body, &run.contact)?.near_pairs(&xf, 0, u32::MAX).0.len() as u64
        },
        colours: 0,
        asleep_per_second: Vec::new(),
        woken: None,
    };
    let split = crate::scene::time_split(gpu, &pipe, &solver, t.frames.min(10));
    Ok(report(scene, run, t, last, split, gpu))
}

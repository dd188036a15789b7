//! Stability of the Gauss-Seidel step (docs/ARCHITECTURE.md section 10: resting contact does not drift; energy
//! does not grow), on the GPU solver with the CPU reference `step_cpu` run on the same scenes (contacts from the GPU
//! pipeline every frame in both cases; the GPU path submits contacts + solver as one command buffer per frame
//! and keeps the state on the device, read back only to measure).
//!
//! Shapes are paired with Factory's rules (`contact::roles::pair_spec`): box vs table = the box's triangles and
//! corners queried against the exact half-space; box vs box = convex-convex, one box baked into an SDF grid
//! (`CONVEX_SDF_RESOLUTION`) and the other's triangles and corners queried.
//!
//! Settings: dt = 1/60 s, 1 substep, 20 position and 1 velocity iteration (the paper's nut-bolt row of
//! Table II, `SolverConfig::default()`), unless a test says otherwise.

use factory_engine::contact::roles::{pair_spec, ShapeDesc, ShapeGeometry};
use factory_engine::contact::{ContactConfig, ContactModel, ContactPipeline, PairSpec, TransformGpu};
use factory_engine::gpu::GpuContext;
use factory_engine::sdf::cache::SdfCache;
use factory_engine::solver::gpu::GpuSolver;
use factory_engine::solver::{step_cpu_with_pipeline, BodyModel, BodyState, Control, SolverConfig, WarmStart};
use glam::{Mat3, Quat, Vec3};

const G: f32 = 9.81;
/// Steel [kg/m^3].
const DENSITY: f32 = 7850.0;
/// Contact offset of every pair [m]: covers what a box moves in a frame in these scenes.
const OFFSET: f32 = 0.005;

/// A box resting on a table drifts less than 1e-3 mm/s, measured after settling.
const REST_DRIFT_MAX: f32 = 1e-6;
/// Settling time before the drift is measured [frames] (1 s).
const SETTLE_FRAMES: u32 = 60;
/// A stacked box's xy stays within this fraction of its edge length of where it was placed.
const STACK_XY_FRACTION: f32 = 0.01;
/// A stacked box's height stays within this fraction of its own height of the exact stacked height.
const STACK_Z_FRACTION: f32 = 0.01;
/// A closed frictionless system gains less than 1% energy over 10 s.
const ENERGY_GAIN_MAX: f64 = 0.01;
/// The frame-to-frame rise of a depenetrating box is the capped speed itself (the position sweeps drive the
/// normal velocity to exactly min(depth / h, cap)); this relative slack covers f32 rounding only.
const RATE_ROUNDING: f32 = 1e-3;
/// Initial overlap of the depenetration test [m].
const OVERLAP: f32 = 1e-3;
/// The overlap counts as resolved below this [m]: the resting penetration the solver leaves (see the
/// resting test in solver_gpu.rs: within 1e-5 m of the exact height).
const RESOLVED_DEPTH: f32 = 1e-5;

fn gpu() -> &'static GpuContext {
    GpuContext::global().unwrap()
}

fn cache() -> SdfCache {
    SdfCache::new(SdfCache::default_dir())
}

fn p3(t: &TransformGpu) -> Vec3 {
    Vec3::from_slice(&t.p[..3])
}

fn q4(t: &TransformGpu) -> Quat {
    Quat::from_array(t.q)
}

/// Adds a dynamic box of half extents `h` [m] (solid steel).
fn add_box(bodies: &mut BodyModel, h: Vec3) -> u32 {
    let mass = DENSITY * 8.0 * h.x * h.y * h.z;
    let inertia = Mat3::from_diagonal(
        Vec3::new(h.y * h.y + h.z * h.z, h.x * h.x + h.z * h.z, h.x * h.x + h.y * h.y) * mass / 3.0,
    );
    bodies.add_dynamic(mass, inertia, Vec3::ZERO)
}

fn box_shape(body: u32, h: Vec3) -> ShapeDesc {
    ShapeDesc::new(body, ShapeGeometry::Box { half_extents: h })
}

fn table() -> ShapeDesc {
    ShapeDesc::fixed((Vec3::ZERO, Quat::IDENTITY), ShapeGeometry::Plane)
}

fn pair(a: &ShapeDesc, b: &ShapeDesc, offset: f32, mu: f32) -> PairSpec {
    let mut p = pair_spec(a, b, offset, &cache()).unwrap();
    p.friction = mu;
    p
}

/// One world stepped frame by frame, on the GPU solver or on the CPU reference.
struct Sim {
    pipe: ContactPipeline,
    solver: GpuSolver,
    bodies: BodyModel,
    cfg: SolverConfig,
    state: BodyState,
    on_gpu: bool,
    warm: WarmStart,
}

impl Sim {
    fn new(contacts: &ContactModel, bodies: BodyModel, cfg: SolverConfig, state: BodyState, on_gpu: bool) -> Self {
        let g = gpu();
        let pipe = ContactPipeline::new(g, contacts, 1, &ContactConfig::default()).unwrap();
        let solver = GpuSolver::new(g, &pipe, &bodies, &cfg).unwrap();
        solver.write_state(g, &pipe, &state);
        Sim { pipe, solver, bodies, cfg, state, on_gpu, warm: WarmStart::default() }
    }

    fn who(&self) -> &'static str {
        if self.on_gpu {
            "GPU solver"
        } else {
            "CPU reference"
        }
    }

    /// One frame; returns the new state.
    fn step(&mut self) -> &BodyState {
        let g = gpu();
        if self.on_gpu {
            self.solver.submit_frame(g, &self.pipe);
            let (s, ok) = self.solver.read_state(g, &self.pipe);
            assert!(ok[0], "{}: world diverged", self.who());
            self.state = s;
        } else {
            let ok = step_cpu_with_pipeline(
                g,
                &self.pipe,
                &self.bodies,
                &mut self.state,
                &self.cfg,
                &Control::default(),
                &mut self.warm,
            );
            assert!(ok[0], "{}: world diverged", self.who());
        }
        &self.state
    }
}

fn at_rest(body_q: Vec<TransformGpu>) -> BodyState {
    let n = body_q.len();
    BodyState { body_q, body_qd: vec![[Vec3::ZERO; 2]; n] }
}

/// Largest displacement of the 8 corners of a box of half extents `h` between two poses [m]: the drift of
/// any material point, rotation included.
fn corner_displacement(h: Vec3, a: &TransformGpu, b: &TransformGpu) -> f32 {
    (0..8)
        .map(|i| {
            let c = Vec3::new(
                if i & 1 == 0 { -h.x } else { h.x },
                if i & 2 == 0 { -h.y } else { h.y },
                if i & 4 == 0 { -h.z } else { h.z },
            );
            ((p3(a) + q4(a) * c) - (p3(b) + q4(b) * c)).length()
        })
        .fold(0.0, f32::max)
}

#[test]
fn a_box_resting_on_the_table_drifts_less_than_1e_3_mm_per_s_over_10_s() {
    let h = Vec3::new(0.02, 0.015, 0.01);
    // Off the origin and turned, so that no symmetry of the set-up hides a lateral error. With friction 0
    // nothing but the contact normals' accuracy holds the box in place.
    let pose = TransformGpu::new(Vec3::new(0.13, -0.07, h.z), Quat::from_rotation_z(0.5));
    for mu in [0.5, 0.0] {
        for on_gpu in [true, false] {
            let mut bodies = BodyModel { gravity: Vec3::new(0.0, 0.0, -G), ..Default::default() };
            add_box(&mut bodies, h);
            let contacts = ContactModel { body_count: 1, pairs: vec![pair(&box_shape(0, h), &table(), OFFSET, mu)] };
            let mut sim = Sim::new(&contacts, bodies, SolverConfig::default(), at_rest(vec![pose]), on_gpu);
            for _ in 0..SETTLE_FRAMES {
                sim.step();
            }
            let settled = sim.state.body_q[0];
            let window = 600 - SETTLE_FRAMES;
            let mut worst = 0.0f32;
            for _ in 0..window {
                let s = sim.step();
                worst = worst.max(corner_displacement(h, &settled, &s.body_q[0]));
            }
            let t = window as f32 / 60.0;
            let end = sim.state.body_q[0];
            let drift = corner_displacement(h, &settled, &end) / t;
            eprintln!(
                "{} mu {mu}: drift {:.3e} mm/s over {t} s (largest corner excursion {:.3e} mm), z - h {:.3e} mm, \
                 settling moved it {:.3e} mm",
                sim.who(),
                drift * 1e3,
                worst * 1e3,
                (end.p[2] - h.z) * 1e3,
                corner_displacement(h, &pose, &settled) * 1e3
            );
            assert!(drift < REST_DRIFT_MAX, "{} mu {mu}: drift {drift} m/s", sim.who());
            // No slow wander that happens to come back: every excursion stays within the drift budget too.
            assert!(worst / t < REST_DRIFT_MAX, "{} mu {mu}: excursion {worst} m in {t} s", sim.who());
        }
    }
}

/// Three boxes of decreasing size (edges 50, 40 and 30 mm, 20 mm tall), each centred on the one below, on the
/// table; all six pairs collide (box vs table, box vs box). In each box pair the lower box is the SDF and the
/// upper box is queried (`pair_spec`'s tie rule: the first shape is the SDF), so that the upper box's four
/// bottom corners are queried inside the lower box's top face, where the baked box field is exactly linear.
/// (The other way round, the lower box's top face is queried: one candidate per triangle, two points for
/// the whole face, a line on which the upper box rocks.) Returns the largest sideways move [m] and height
/// error [m] of each box, after checking them against the bounds every frame.
fn run_stack(cfg: &SolverConfig, on_gpu: bool) -> ([f32; 3], [f32; 3]) {
    let hs = [Vec3::new(0.025, 0.025, 0.01), Vec3::new(0.02, 0.02, 0.01), Vec3::new(0.015, 0.015, 0.01)];
    let mut bodies = BodyModel { gravity: Vec3::new(0.0, 0.0, -G), ..Default::default() };
    let shapes: Vec<ShapeDesc> = hs.iter().map(|&h| box_shape(add_box(&mut bodies, h), h)).collect();
    let mu = 0.5;
    let mut pairs: Vec<PairSpec> = shapes.iter().map(|s| pair(s, &table(), OFFSET, mu)).collect();
    for (lower, upper) in [(0, 1), (1, 2), (0, 2)] {
        pairs.push(pair(&shapes[lower], &shapes[upper], OFFSET, mu));
    }
    let contacts = ContactModel { body_count: 3, pairs };
    let placed: Vec<TransformGpu> =
        (0..3).map(|i| TransformGpu::new(Vec3::new(0.0, 0.0, (2 * i + 1) as f32 * 0.01), Quat::IDENTITY)).collect();
    let mut sim = Sim::new(&contacts, bodies, cfg.clone(), at_rest(placed.clone()), on_gpu);
    let (mut worst_xy, mut worst_z) = ([0.0f32; 3], [0.0f32; 3]);
    for f in 0..300 {
        let s = sim.step().clone();
        for i in 0..3 {
            let (p, p0) = (p3(&s.body_q[i]), p3(&placed[i]));
            worst_xy[i] = worst_xy[i].max((p - p0).truncate().length());
            worst_z[i] = worst_z[i].max((p.z - p0.z).abs());
        }
        let z: Vec<f32> = s.body_q.iter().map(|t| t.p[2]).collect();
        assert!(z[0] < z[1] && z[1] < z[2], "{} frame {f}: order lost {z:?}", sim.who());
    }
    eprintln!(
        "{} ({} substeps, {} position, {} velocity iterations): stack after 5 s: largest sideways moves {:?} mm, \
         height errors {:?} mm",
        sim.who(),
        cfg.substeps,
        cfg.pos_iters,
        cfg.vel_iters,
        worst_xy.map(|v| v * 1e3),
        worst_z.map(|v| v * 1e3)
    );
    (worst_xy, worst_z)
}

/// Both runs first (so that a failure reports both), then the bounds.
fn check_stack(cfg: &SolverConfig) {
    let hs = [0.05f32, 0.04, 0.03];
    let runs = [run_stack(cfg, true), run_stack(cfg, false)];
    for (who, (xy, z)) in ["GPU solver", "CPU reference"].iter().zip(runs) {
        for i in 0..3 {
            assert!(xy[i] <= STACK_XY_FRACTION * hs[i], "{who}: box {i} moved {} m sideways (edge {} m)", xy[i], hs[i]);
            assert!(z[i] <= STACK_Z_FRACTION * 0.02, "{who}: box {i} height error {} m", z[i]);
        }
    }
}

/// The paper's 20 position iterations. Regression: before warm starting (impulses carried from frame to
/// frame by contact matching) the stack slid as a whole, 1.22 / 0.95 / 1.09 mm in 5 s on the GPU solver and
/// the CPU reference alike (40 iterations: 0.06-0.10 mm; 80: 0.2 um); with it, 0.021 / 0.083 / 0.163 mm.
#[test]
fn a_stack_of_three_boxes_stays_stacked_for_5_s() {
    check_stack(&SolverConfig::default());
}

/// The same stack with 80 sweeps (the same bounds).
#[test]
fn a_stack_of_three_boxes_stays_stacked_for_5_s_at_80_position_iterations() {
    check_stack(&SolverConfig { pos_iters: 80, ..Default::default() });
}

/// Kinetic plus potential energy of a box [J], the potential measured from the box resting flat
/// (centre at `rest_z`).
fn energy(bodies: &BodyModel, s: &BodyState, rest_z: f32) -> f64 {
    let m = 1.0 / bodies.body_inv_mass[0] as f64;
    let q = q4(&s.body_q[0]);
    let r = Mat3::from_quat(q);
    let inertia = r * bodies.body_inv_inertia[0].inverse() * r.transpose();
    let [v, w] = s.body_qd[0];
    0.5 * m * v.length_squared() as f64
        + 0.5 * w.dot(inertia * w) as f64
        + m * G as f64 * (s.body_q[0].p[2] - rest_z) as f64
}

fn slide_start(h: Vec3) -> BodyState {
    BodyState {
        body_q: vec![TransformGpu::new(Vec3::new(0.0, 0.0, h.z), Quat::IDENTITY)],
        body_qd: vec![[Vec3::new(0.3, -0.2, 0.0), Vec3::new(0.0, 0.0, 3.0)]],
    }
}

fn drop_start() -> BodyState {
    BodyState {
        body_q: vec![TransformGpu::new(
            Vec3::new(0.0, 0.0, 0.05),
            Quat::from_euler(glam::EulerRot::XYZ, 0.4, -0.25, 0.3),
        )],
        body_qd: vec![[Vec3::new(0.05, 0.0, 0.0), Vec3::new(1.0, 0.5, 2.0)]],
    }
}

/// Runs a frictionless box for 10 s; returns (E0, largest E, E after 10 s) [J] and the final state.
fn frictionless_run(h: Vec3, start: &BodyState, offset: f32, on_gpu: bool, name: &str) -> (f64, f64, f64, BodyState) {
    let mut bodies = BodyModel { gravity: Vec3::new(0.0, 0.0, -G), ..Default::default() };
    add_box(&mut bodies, h);
    let contacts = ContactModel { body_count: 1, pairs: vec![pair(&box_shape(0, h), &table(), offset, 0.0)] };
    let mut sim = Sim::new(&contacts, bodies.clone(), SolverConfig::default(), start.clone(), on_gpu);
    let e0 = energy(&bodies, start, h.z);
    let (mut e_max, mut e_min) = (e0, e0);
    for _ in 0..600 {
        let s = sim.step().clone();
        let e = energy(&bodies, &s, h.z);
        e_max = e_max.max(e);
        e_min = e_min.min(e);
    }
    let e_end = energy(&bodies, &sim.state, h.z);
    eprintln!(
        "{} {name} (offset {offset} m): E0 {:.4e} J, max {:+.4}%, min {:+.4}%, after 10 s {:+.4}% (centre z {:.4} mm)",
        sim.who(),
        e0,
        (e_max / e0 - 1.0) * 100.0,
        (e_min / e0 - 1.0) * 100.0,
        (e_end / e0 - 1.0) * 100.0,
        sim.state.body_q[0].p[2] * 1e3
    );
    (e0, e_max, e_end, sim.state)
}

/// The box lies flat on one of its faces: the centre height is one of the half extents.
fn lies_on_a_face(h: Vec3, s: &BodyState) -> bool {
    let z = s.body_q[0].p[2];
    [h.x, h.y, h.z].iter().any(|&e| (z - e).abs() <= RESOLVED_DEPTH)
}

#[test]
fn a_closed_frictionless_system_gains_less_than_1_percent_energy_over_10_s() {
    // Closed system: one box on a frictionless, static, infinite table under uniform gravity. Gravity is
    // conservative, the table does no work on tangential motion (mu = 0), and a normal contact without
    // restitution can only take energy out (an impact) or do none (a resting or sliding contact): the exact
    // energy never grows. Energy = translational + rotational kinetic + m g (z - z_flat), zero for the box
    // lying still on its largest face, so that the 1% is 1% of the motion's energy, not of a potential
    // offset. Two motions: (a) sliding and spinning flat (the exact energy is constant: any change is the
    // solver's); (b) dropped from 5 cm, tilted and spinning, landing on a corner at ~1 m/s (17 mm a frame:
    // more than the contact offset, so it penetrates and is pushed out, where solvers typically inject
    // energy), then rocking and sliding to rest.
    let h = Vec3::new(0.02, 0.015, 0.01);
    for on_gpu in [true, false] {
        let (e0, e_max, e_end, _) = frictionless_run(h, &slide_start(h), OFFSET, on_gpu, "slide");
        assert!(e_max <= e0 * (1.0 + ENERGY_GAIN_MAX), "slide: energy rose to {e_max} J from {e0} J");
        // (A slide has nothing to lose energy to either: report it, assert only that energy does not rise.)
        let _ = e_end;
        let (e0, e_max, _, end) = frictionless_run(h, &drop_start(), OFFSET, on_gpu, "drop");
        assert!(e_max <= e0 * (1.0 + ENERGY_GAIN_MAX), "drop: energy rose to {e_max} J from {e0} J");
        // Not a vacuous pass: the box did land and lies on the table (not sunk into it).
        assert!(lies_on_a_face(h, &end), "drop: final centre height {} m", end.body_q[0].p[2]);
    }
}

/// The same drop with a contact offset large enough to cover a frame's fall (30 mm, so contacts are
/// speculative before the impact). Regression test: the plane pair gives one patch (one normal) of at most 4
/// contacts, and a reduction that chooses slots 2-4 by distance from the deepest contact alone lets the
/// box's top corners, 21 mm above the table but within the offset, win over the other bottom corners: the
/// box settles 3.07 mm sunk (corner 7.1 mm into the table, energy -101%). Slots 2-4 therefore skip contacts
/// far above both the deepest one and the surface (DEPTH_BAND in common.wgsl).
#[test]
fn a_box_dropped_with_a_large_contact_offset_lands_on_the_table() {
    let h = Vec3::new(0.02, 0.015, 0.01);
    for on_gpu in [true, false] {
        let (e0, e_max, _, end) = frictionless_run(h, &drop_start(), 0.03, on_gpu, "drop");
        assert!(e_max <= e0 * (1.0 + ENERGY_GAIN_MAX), "drop: energy rose to {e_max} J from {e0} J");
        assert!(lies_on_a_face(h, &end), "drop: final centre height {} m", end.body_q[0].p[2]);
    }
}

#[test]
fn a_1_mm_overlap_resolves_no_faster_than_the_max_depenetration_velocity() {
    let h = Vec3::new(0.02, 0.015, 0.01);
    let dt = 1.0 / 60.0;
    let mut bodies = BodyModel { gravity: Vec3::new(0.0, 0.0, -G), ..Default::default() };
    add_box(&mut bodies, h);
    let contacts = ContactModel { body_count: 1, pairs: vec![pair(&box_shape(0, h), &table(), OFFSET, 0.5)] };
    let start = at_rest(vec![TransformGpu::new(Vec3::new(0.0, 0.0, h.z - OVERLAP), Quat::from_rotation_z(0.3))]);
    for mdv in [0.01f32, 0.05, 0.2] {
        let cfg = SolverConfig { max_depenetration_velocity: mdv, ..Default::default() };
        // Two measures of the upward speed: the rise from frame to frame (the speed the overlap actually
        // resolves at; bound: the cap) and the velocity left in the state after the frame (bound: the cap plus
        // the speed gravity adds in one frame, g dt, which the sweeps cancel along with the penetration).
        let bound = mdv + G * dt;
        // Frames the bound implies for the overlap (the per-step target is min(depth / h, cap)), plus one
        // for the last partial step.
        let frames_needed = (OVERLAP / (mdv * dt)).ceil() as u32 + 1;
        for on_gpu in [true, false] {
            let mut sim = Sim::new(&contacts, bodies.clone(), cfg.clone(), start.clone(), on_gpu);
            let mut z = start.body_q[0].p[2];
            let (mut top_rate, mut top_vz) = (0.0f32, 0.0f32);
            let mut resolved_at = None;
            for f in 1..=frames_needed + 30 {
                let s = sim.step();
                let (z1, vz) = (s.body_q[0].p[2], s.body_qd[0][0].z);
                let rate = (z1 - z) / dt;
                z = z1;
                top_rate = top_rate.max(rate);
                top_vz = top_vz.max(vz);
                assert!(
                    rate <= mdv * (1.0 + RATE_ROUNDING) && vz <= bound,
                    "{} mdv {mdv}: frame {f} rose at {rate} m/s, vz {vz}",
                    sim.who()
                );
                let depth = h.z - z1;
                if resolved_at.is_none() && depth <= RESOLVED_DEPTH {
                    resolved_at = Some(f);
                }
                if resolved_at.is_some() {
                    // Resolved means resolved: no bounce off the table afterwards.
                    assert!(depth.abs() <= RESOLVED_DEPTH, "{} mdv {mdv}: frame {f} depth {depth} m", sim.who());
                }
            }
            eprintln!(
                "{} mdv {mdv} m/s: fastest rise {:.5} m/s (frame-to-frame), largest vz {:.5} m/s, bound {bound:.4}; \
                 resolved after {resolved_at:?} frames (bound implies {frames_needed})",
                sim.who(),
                top_rate,
                top_vz
            );
            let at = resolved_at.unwrap_or_else(|| panic!("{} mdv {mdv}: overlap never resolved", sim.who()));
            assert!(at <= frames_needed, "{} mdv {mdv}: resolved after {at} frames", sim.who());
        }
    }
}

/// Coulomb friction against the analytic block on an incline (mu 0.5): at 20 deg (tan 0.36 < mu) a box set
/// on the slope stays put; at 35 deg (tan 0.70 > mu) it slides down with a = g (sin t - mu cos t) =
/// 1.61 m/s^2, so after 1 s its speed along the slope is a * 1 s (semi-implicit Euler is exact for the speed
/// under a constant force). GPU solver and CPU reference, the paper's nut-bolt settings, friction per contact
/// and per patch.
#[test]
fn a_box_on_an_incline_sticks_below_the_friction_angle_and_slides_at_g_sin_minus_mu_cos_above() {
    /// Sticking: the box moves less than this along the slope in 1 s [m] ...
    const STICK_DRIFT: f32 = 1e-5;
    /// ... sliding: its speed is within this fraction of the analytic one.
    const SLIDE_SPEED_TOL: f32 = 0.005;
    let mu = 0.5;
    let h = Vec3::new(0.02, 0.015, 0.01);
    for (deg, slides) in [(20.0f32, false), (35.0, true)] {
        let tilt = Quat::from_rotation_y(deg.to_radians());
        let slope = ShapeDesc::fixed((Vec3::ZERO, tilt), ShapeGeometry::Plane);
        let mut bodies = BodyModel { gravity: Vec3::new(0.0, 0.0, -G), ..Default::default() };
        let b = add_box(&mut bodies, h);
        let contacts = ContactModel { body_count: 1, pairs: vec![pair(&box_shape(b, h), &slope, OFFSET, mu)] };
        // On the slope, its bottom face on the plane (0.1 um above it), at rest.
        let start = BodyState {
            body_q: vec![TransformGpu::new(tilt * Vec3::new(0.0, 0.0, h.z + 1e-7), tilt)],
            body_qd: vec![[Vec3::ZERO; 2]],
        };
        // Down the slope: the plane's x axis tilted points down for a positive rotation about y.
        let down = tilt * Vec3::X;
        let down = if down.z < 0.0 { down } else { -down };
        let t = deg.to_radians();
        let a = G * (t.sin() - mu * t.cos());
        for (on_gpu, friction_per_patch) in [(true, false), (false, false), (true, true), (false, true)] {
            let cfg = SolverConfig { friction_per_patch, ..Default::default() };
            let mut sim = Sim::new(&contacts, bodies.clone(), cfg, start.clone(), on_gpu);
            for _ in 0..60 {
                sim.step();
            }
            let moved = (p3(&sim.state.body_q[0]) - p3(&start.body_q[0])).dot(down);
            let speed = sim.state.body_qd[0][0].dot(down);
            let per = if friction_per_patch { "per patch" } else { "per contact" };
            eprintln!(
                "{} (friction {per}) at {deg} deg: moved {:.4e} m down the slope in 1 s, speed {speed:.4} m/s (analytic {:.4})",
                sim.who(),
                moved,
                if slides { a } else { 0.0 }
            );
            if slides {
                assert!((speed - a).abs() <= SLIDE_SPEED_TOL * a, "{}: {speed} m/s, analytic {a}", sim.who());
            } else {
                assert!(moved.abs() <= STICK_DRIFT, "{}: crept {moved} m", sim.who());
            }
        }
    }
}

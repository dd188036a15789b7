//! The GPU rigid-body step (solver.wgsl) against its CPU reference, bitwise determinism, diverged-world
//! isolation, resting drift, and refusal of bad settings.

use factory_engine::contact::{
    ContactConfig, ContactModel, ContactPipeline, PairSpec, QueryShape, SdfShape, TransformGpu, NO_BODY,
};
use factory_engine::gpu::GpuContext;
use factory_engine::solver::gpu::GpuSolver;
use factory_engine::solver::{
    step_cpu, step_cpu_with_pipeline, BodyModel, BodyState, Control, SolverConfig, WarmStart,
};
use glam::{Mat3, Quat, Vec3};
use std::sync::Arc;

/// GPU and CPU differ only by float rounding order within one frame [m], [m/s].
const PARITY_POS_TOL: f32 = 2e-6;
const PARITY_VEL_TOL: f32 = 2e-4;
/// A box at rest on a table drifts less than 1e-3 mm/s (docs/ARCHITECTURE.md section 10).
const REST_DRIFT: f32 = 1e-6;

const H: Vec3 = Vec3::new(0.02, 0.015, 0.01);

/// One dynamic box (body 0) on a table plane (static world), per world.
fn scene(mu: f32) -> (ContactModel, BodyModel) {
    let pair = PairSpec {
        body_a: 0,
        a_pose: (Vec3::ZERO, Quat::IDENTITY),
        query: Arc::new(QueryShape::cuboid(H)),
        body_b: NO_BODY,
        b_pose: (Vec3::ZERO, Quat::IDENTITY),
        sdf: SdfShape::Plane,
        contact_offset: 0.005,
        friction: mu,
    };
    let mass = 0.2;
    let inertia = Mat3::from_diagonal(
        Vec3::new(H.y * H.y + H.z * H.z, H.x * H.x + H.z * H.z, H.x * H.x + H.y * H.y) * mass / 3.0,
    );
    let mut bodies = BodyModel { gravity: Vec3::new(0.0, 0.0, -9.81), ..Default::default() };
    bodies.add_dynamic(mass, inertia, Vec3::ZERO);
    (ContactModel { body_count: 1, pairs: vec![pair] }, bodies)
}

fn tumbling_state(worlds: u32) -> BodyState {
    let body_q = (0..worlds)
        .map(|w| {
            let a = w as f32 * 0.7;
            TransformGpu::new(
                Vec3::new(0.0, 0.0, 0.03 + 0.004 * w as f32),
                Quat::from_euler(glam::EulerRot::XYZ, 0.3 * a.sin(), 0.2 * a.cos(), a),
            )
        })
        .collect();
    let body_qd =
        (0..worlds).map(|w| [Vec3::new(0.1 * w as f32, -0.05, -0.2), Vec3::new(1.0, -2.0, 0.5 * w as f32)]).collect();
    BodyState { body_q, body_qd }
}

fn gpu() -> &'static GpuContext {
    GpuContext::global().unwrap()
}

fn frame(g: &GpuContext, pipe: &ContactPipeline, solver: &GpuSolver) {
    solver.submit_frame(g, &pipe);
}

#[test]
fn gpu_step_matches_the_cpu_reference() {
    gpu_step_matches_the_cpu_reference_with(false);
}

/// The same with Coulomb friction per patch (SolverConfig::friction_per_patch).
#[test]
fn gpu_step_with_friction_per_patch_matches_the_cpu_reference() {
    gpu_step_matches_the_cpu_reference_with(true);
}

fn gpu_step_matches_the_cpu_reference_with(friction_per_patch: bool) {
    let worlds = 8;
    let (contacts, bodies) = scene(0.4);
    let g = gpu();
    let pipe = ContactPipeline::new(g, &contacts, worlds, &ContactConfig::default()).unwrap();
    let cfg = SolverConfig { substeps: 2, pos_iters: 8, vel_iters: 2, friction_per_patch, ..Default::default() };
    let solver = GpuSolver::new(g, &pipe, &bodies, &cfg).unwrap();
    let mut state = tumbling_state(worlds);
    let mut touched = 0;
    let (mut worst_p, mut worst_v) = (0.0f32, 0.0f32);
    for f in 0..40 {
        solver.write_state(g, &pipe, &state);
        pipe.run(g);
        let c = pipe.read(g);
        touched += c.patches.iter().filter(|p| !p.is_empty()).count();
        let mut cpu = state.clone();
        // write_state starts the GPU cold each frame, so the CPU starts cold too.
        step_cpu(&bodies, &mut cpu, &c, &pipe.flat, &cfg, &Control::default(), &mut WarmStart::default());
        solver.write_state(g, &pipe, &state);
        frame(g, &pipe, &solver);
        let (gpu_state, ok) = solver.read_state(g, &pipe);
        assert!(ok.iter().all(|&o| o));
        for i in 0..worlds as usize {
            let (a, b) = (gpu_state.body_q[i], cpu.body_q[i]);
            let dp = (Vec3::from_slice(&a.p[..3]) - Vec3::from_slice(&b.p[..3])).length();
            let dq = (glam::Vec4::from_array(a.q) - glam::Vec4::from_array(b.q)).length();
            let dv = (gpu_state.body_qd[i][0] - cpu.body_qd[i][0]).length()
                + (gpu_state.body_qd[i][1] - cpu.body_qd[i][1]).length();
            worst_p = worst_p.max(dp);
            worst_v = worst_v.max(dv);
            assert!(
                dp <= PARITY_POS_TOL && dq <= PARITY_POS_TOL * 10.0 && dv <= PARITY_VEL_TOL,
                "frame {f} world {i}: dp {dp} dq {dq} dv {dv}"
            );
        }
        // Continue from the GPU's state so rounding does not accumulate across frames.
        state = gpu_state;
    }
    eprintln!("worst position difference {worst_p:.3e} m, velocity {worst_v:.3e} m/s");
    assert!(touched > 100, "the boxes must land and tumble on the table ({touched} world-frames with contacts)");
}

/// Warm starting carries impulses from frame to frame, so it is only exercised by runs that are never
/// re-synchronised: the GPU solver and the CPU reference each run 60 frames on their own (each with its own
/// contact pipeline) from the same start, a box landing and sliding to rest on the table (a smooth motion,
/// so rounding does not grow chaotically). Tolerances: 20 um and 2 mm/s over the whole run.
#[test]
fn warm_started_gpu_run_matches_the_cpu_reference() {
    let (contacts, bodies) = scene(0.3);
    let g = gpu();
    let cfg = SolverConfig::default();
    let gpu_pipe = ContactPipeline::new(g, &contacts, 1, &ContactConfig::default()).unwrap();
    let cpu_pipe = ContactPipeline::new(g, &contacts, 1, &ContactConfig::default()).unwrap();
    let solver = GpuSolver::new(g, &gpu_pipe, &bodies, &cfg).unwrap();
    let start = BodyState {
        body_q: vec![TransformGpu::new(Vec3::new(0.0, 0.0, H.z + 0.5e-3), Quat::from_rotation_z(0.3))],
        body_qd: vec![[Vec3::new(0.2, 0.1, 0.0), Vec3::new(0.0, 0.0, 1.0)]],
    };
    solver.write_state(g, &gpu_pipe, &start);
    let mut cpu = start.clone();
    let mut warm = WarmStart::default();
    let (mut worst_p, mut worst_v, mut moved) = (0.0f32, 0.0f32, 0.0f32);
    for f in 0..60 {
        frame(g, &gpu_pipe, &solver);
        assert!(step_cpu_with_pipeline(g, &cpu_pipe, &bodies, &mut cpu, &cfg, &Control::default(), &mut warm)[0]);
        let (gs, ok) = solver.read_state(g, &gpu_pipe);
        assert!(ok[0]);
        let dp = (Vec3::from_slice(&gs.body_q[0].p[..3]) - Vec3::from_slice(&cpu.body_q[0].p[..3])).length();
        let dv = (gs.body_qd[0][0] - cpu.body_qd[0][0]).length();
        worst_p = worst_p.max(dp);
        worst_v = worst_v.max(dv);
        moved =
            moved.max((Vec3::from_slice(&gs.body_q[0].p[..3]) - Vec3::from_slice(&start.body_q[0].p[..3])).length());
        assert!(dp <= 20e-6 && dv <= 2e-3, "frame {f}: dp {dp} m dv {dv} m/s");
    }
    eprintln!(
        "warm-started runs: worst position difference {worst_p:.3e} m, velocity {worst_v:.3e} m/s; moved {moved:.3e} m"
    );
    assert!(moved > 5e-3, "the box must slide (moved {moved} m)");
}

#[test]
fn same_input_gives_bitwise_identical_state() {
    let worlds = 4;
    let (contacts, bodies) = scene(0.5);
    let g = gpu();
    let pipe = ContactPipeline::new(g, &contacts, worlds, &ContactConfig::default()).unwrap();
    let solver = GpuSolver::new(g, &pipe, &bodies, &SolverConfig::default()).unwrap();
    let mut runs = Vec::new();
    for _ in 0..2 {
        solver.write_state(g, &pipe, &tumbling_state(worlds));
        for _ in 0..30 {
            frame(g, &pipe, &solver);
        }
        runs.push(solver.read_state(g, &pipe).0);
    }
    let bits = |s: &BodyState| -> Vec<u32> {
        s.body_q.iter().flat_map(|t| t.p.iter().chain(t.q.iter()).map(|v| v.to_bits()).collect::<Vec<_>>()).collect()
    };
    assert_eq!(bits(&runs[0]), bits(&runs[1]));
}

#[test]
fn a_broken_world_is_flagged_and_the_others_are_bitwise_unchanged() {
    let worlds = 4;
    let (contacts, bodies) = scene(0.5);
    let g = gpu();
    let pipe = ContactPipeline::new(g, &contacts, worlds, &ContactConfig::default()).unwrap();
    let solver = GpuSolver::new(g, &pipe, &bodies, &SolverConfig::default()).unwrap();
    let run = |state: &BodyState| {
        solver.write_state(g, &pipe, state);
        for _ in 0..20 {
            frame(g, &pipe, &solver);
        }
        solver.read_state(g, &pipe)
    };
    let good = tumbling_state(worlds);
    let mut broken = good.clone();
    broken.body_qd[2][0] = Vec3::new(f32::NAN, 0.0, 0.0);
    let (a, ok_a) = run(&good);
    let (b, ok_b) = run(&broken);
    assert_eq!(ok_a, vec![true; 4]);
    assert_eq!(ok_b, vec![true, true, false, true], "only world 2 is flagged");
    for w in [0, 1, 3] {
        assert_eq!(a.body_q[w].p.map(f32::to_bits), b.body_q[w].p.map(f32::to_bits), "world {w}");
        assert_eq!(a.body_q[w].q.map(f32::to_bits), b.body_q[w].q.map(f32::to_bits), "world {w}");
    }
    // A runaway speed is flagged too.
    let mut fast = good.clone();
    fast.body_qd[1][0] = Vec3::new(0.0, 500.0, 0.0);
    let (_, ok_c) = run(&fast);
    assert_eq!(ok_c, vec![true, false, true, true]);
}

/// The auto-reset of one world: world 2 diverges (NaN velocity), is flagged, and is reset alone to a given
/// state; a run in which world 2 never broke but was reset to the same state at the same frame ends bitwise
/// the same in every world (the reset forgets the world's warm start and status, and touches no other
/// world).
#[test]
fn a_broken_world_is_reset_alone_and_every_world_then_steps_as_if_it_never_broke() {
    let worlds = 4;
    let (contacts, bodies) = scene(0.5);
    let g = gpu();
    let pipe = ContactPipeline::new(g, &contacts, worlds, &ContactConfig::default()).unwrap();
    let solver = GpuSolver::new(g, &pipe, &bodies, &SolverConfig::default()).unwrap();
    let good = tumbling_state(worlds);
    let nb = bodies.body_count();
    let fresh_q = good.body_q[2 * nb..3 * nb].to_vec();
    let fresh_qd = good.body_qd[2 * nb..3 * nb].to_vec();
    let run = |start: &BodyState| {
        solver.write_state(g, &pipe, start);
        for _ in 0..10 {
            frame(g, &pipe, &solver);
        }
        let (_, ok_before) = solver.read_state(g, &pipe);
        solver.reset_world(g, &pipe, 2, &fresh_q, &fresh_qd);
        for _ in 0..10 {
            frame(g, &pipe, &solver);
        }
        let (s, ok) = solver.read_state(g, &pipe);
        (s, ok_before, ok)
    };
    let mut broken = good.clone();
    broken.body_qd[2 * nb][0] = Vec3::new(f32::NAN, 0.0, 0.0);
    let (a, ok_a0, ok_a) = run(&good);
    let (b, ok_b0, ok_b) = run(&broken);
    assert_eq!((ok_a0, ok_b0), (vec![true; 4], vec![true, true, false, true]), "world 2 broke and was flagged");
    assert_eq!((ok_a, ok_b), (vec![true; 4], vec![true; 4]), "after its reset world 2 is ok");
    let bits = |s: &BodyState| -> Vec<u32> { bytemuck::cast_slice::<_, u32>(&s.body_q).to_vec() };
    assert_eq!(bits(&a), bits(&b), "every world, the reset one included, bitwise as if world 2 never broke");
}

#[test]
fn a_box_resting_on_the_table_does_not_drift() {
    let (contacts, bodies) = scene(0.5);
    let g = gpu();
    let pipe = ContactPipeline::new(g, &contacts, 1, &ContactConfig::default()).unwrap();
    let solver = GpuSolver::new(g, &pipe, &bodies, &SolverConfig::default()).unwrap();
    let rest = BodyState {
        body_q: vec![TransformGpu::new(Vec3::new(0.0, 0.0, H.z), Quat::IDENTITY)],
        body_qd: vec![[Vec3::ZERO; 2]],
    };
    solver.write_state(g, &pipe, &rest);
    // Settle for 1 s, then measure the drift over the next 2 s.
    for _ in 0..60 {
        frame(g, &pipe, &solver);
    }
    let (s0, _) = solver.read_state(g, &pipe);
    for _ in 0..120 {
        frame(g, &pipe, &solver);
    }
    let (s1, ok) = solver.read_state(g, &pipe);
    assert!(ok[0]);
    let drift = (Vec3::from_slice(&s1.body_q[0].p[..3]) - Vec3::from_slice(&s0.body_q[0].p[..3])).length() / 2.0;
    assert!(drift < REST_DRIFT, "drift {drift} m/s");
    // It rests on the table, not in it (within the solver's penetration tolerance of a few micrometres).
    assert!((s1.body_q[0].p[2] - H.z).abs() < 1e-5, "z {}", s1.body_q[0].p[2]);
}

#[test]
fn bad_settings_are_refused_naming_the_field() {
    let (contacts, mut bodies) = scene(0.5);
    let g = gpu();
    let pipe = ContactPipeline::new(g, &contacts, 1, &ContactConfig::default()).unwrap();
    for (cfg, field) in [
        (SolverConfig { dt: 0.0, ..Default::default() }, "dt"),
        (SolverConfig { dt: -0.01, ..Default::default() }, "dt"),
        (SolverConfig { substeps: 0, ..Default::default() }, "substeps"),
        (SolverConfig { pos_iters: 0, ..Default::default() }, "pos_iters"),
    ] {
        let e = GpuSolver::new(g, &pipe, &bodies, &cfg).err().expect("refused").to_string();
        assert!(e.contains(field), "{e}");
    }
    bodies.body_inv_mass[0] = -1.0;
    let e = GpuSolver::new(g, &pipe, &bodies, &SolverConfig::default()).err().expect("refused").to_string();
    assert!(e.contains("mass"), "{e}");
}

/// lavapipe cuts every loop short once an invocation has made 65535 loop passes: the solver refuses a
/// step that would exceed that on a software adapter even without contacts ...
#[test]
fn a_step_beyond_lavapipes_loop_budget_is_refused() {
    let g = gpu();
    if !g.is_software() {
        return;
    }
    let (contacts, bodies) = scene(0.5);
    let pipe = ContactPipeline::new(g, &contacts, 1, &ContactConfig::default()).unwrap();
    let too_many = SolverConfig { substeps: 64, pos_iters: 400, ..Default::default() };
    let e = GpuSolver::new(g, &pipe, &bodies, &too_many).err().expect("refused").to_string();
    assert!(e.contains("loop") && e.contains("substeps"), "{e}");
    assert!(GpuSolver::new(g, &pipe, &bodies, &SolverConfig { substeps: 64, ..Default::default() }).is_ok());
}

/// ... and a world whose contacts would take it past the budget in a frame is flagged and left as it was,
/// not stepped with loops cut short; a world without contacts steps on, bitwise as when alone.
#[test]
fn a_world_whose_contacts_exceed_lavapipes_loop_budget_is_flagged_not_truncated() {
    let g = gpu();
    if !g.is_software() {
        return;
    }
    let (contacts, bodies) = scene(0.5);
    // 60 position sweeps x 1000 passes per patch: one resting box's patch needs ~62k passes; none, ~200.
    let cfg = SolverConfig { pos_iters: 60, patch_iters: 1000, ..Default::default() };
    let resting = TransformGpu::new(Vec3::new(0.0, 0.0, H.z), Quat::IDENTITY);
    let falling = TransformGpu::new(Vec3::new(0.0, 0.0, 0.5), Quat::IDENTITY);
    let state = BodyState { body_q: vec![resting, falling], body_qd: vec![[Vec3::ZERO; 2]; 2] };
    let pipe = ContactPipeline::new(g, &contacts, 2, &ContactConfig::default()).unwrap();
    let solver = GpuSolver::new(g, &pipe, &bodies, &cfg).unwrap();
    solver.write_state(g, &pipe, &state);
    solver.submit_frame(g, &pipe);
    let (after, ok) = solver.read_state(g, &pipe);
    assert_eq!(ok, vec![false, true]);
    assert_eq!(solver.worlds_over_loop_budget(g), vec![true, false]);
    assert_eq!(after.body_q[0], resting, "the flagged world moved");
    // The falling world alone.
    let alone_pipe = ContactPipeline::new(g, &contacts, 1, &ContactConfig::default()).unwrap();
    let alone = GpuSolver::new(g, &alone_pipe, &bodies, &cfg).unwrap();
    alone.write_state(g, &alone_pipe, &BodyState { body_q: vec![falling], body_qd: vec![[Vec3::ZERO; 2]] });
    alone.submit_frame(g, &alone_pipe);
    let (single, _) = alone.read_state(g, &alone_pipe);
    assert_eq!(after.body_q[1], single.body_q[0]);
    assert_eq!(after.body_qd[1], single.body_qd[0]);
}

/// A kinematic platform moves with its set velocity, carries a dynamic box, and is not slowed by it.
#[test]
fn a_kinematic_platform_lifts_a_box_at_its_own_speed() {
    let g = gpu();
    let mut bodies = BodyModel { gravity: Vec3::new(0.0, 0.0, -9.81), ..Default::default() };
    let platform = bodies.add_kinematic();
    let mass = 0.2;
    let inertia = Mat3::from_diagonal(
        Vec3::new(H.y * H.y + H.z * H.z, H.x * H.x + H.z * H.z, H.x * H.x + H.y * H.y) * mass / 3.0,
    );
    let box_body = bodies.add_dynamic(mass, inertia, Vec3::ZERO);
    let contacts = ContactModel {
        body_count: 2,
        pairs: vec![PairSpec {
            body_a: box_body,
            a_pose: (Vec3::ZERO, Quat::IDENTITY),
            query: Arc::new(QueryShape::cuboid(H)),
            body_b: platform,
            b_pose: (Vec3::ZERO, Quat::IDENTITY),
            sdf: SdfShape::Plane,
            contact_offset: 0.005,
            friction: 0.5,
        }],
    };
    let pipe = ContactPipeline::new(g, &contacts, 1, &ContactConfig::default()).unwrap();
    let solver = GpuSolver::new(g, &pipe, &bodies, &SolverConfig::default()).unwrap();
    let lift = 0.05; // [m/s]
    let start = BodyState {
        body_q: vec![
            TransformGpu::new(Vec3::ZERO, Quat::IDENTITY),
            TransformGpu::new(Vec3::new(0.0, 0.0, H.z), Quat::IDENTITY),
        ],
        body_qd: vec![[Vec3::new(0.0, 0.0, lift), Vec3::ZERO], [Vec3::ZERO; 2]],
    };
    solver.write_state(g, &pipe, &start);
    for _ in 0..60 {
        frame(g, &pipe, &solver);
    }
    let (s, ok) = solver.read_state(g, &pipe);
    assert!(ok.iter().all(|&o| o));
    let t = 60.0 * SolverConfig::default().dt;
    // The platform moved exactly with its velocity (f32 accumulation over 60 steps).
    assert!((s.body_q[0].p[2] - lift * t).abs() < 1e-6, "platform z {}", s.body_q[0].p[2]);
    assert!((s.body_qd[0][0].z - lift).abs() < 1e-7, "platform velocity {}", s.body_qd[0][0]);
    // The box rides on it.
    assert!(
        (s.body_q[1].p[2] - (s.body_q[0].p[2] + H.z)).abs() < 2e-5,
        "box z {} on platform {}",
        s.body_q[1].p[2],
        s.body_q[0].p[2]
    );
    assert!((s.body_qd[1][0].z - lift).abs() < 2e-3, "box velocity {}", s.body_qd[1][0]);
}

/// External wrenches (`Control::body_f`): a box floating high above the table (no contact within reach) in
/// zero gravity, pushed by a force through its centre of mass and a torque about its z axis, gains
/// v = F t / m and w = I^-1 tau t (the box's principal axes are the world's while w is along z, so the
/// world inertia stays constant). GPU and CPU reference, per world a different wrench; a world without a
/// wrench stays at rest; the wrenches persist across frames until set again; write_state keeps them.
#[test]
fn external_wrenches_accelerate_a_free_body_as_newton_says() {
    let worlds = 3u32;
    let (contacts, mut bodies) = scene(0.0);
    bodies.gravity = Vec3::ZERO;
    let g = gpu();
    let pipe = ContactPipeline::new(g, &contacts, worlds, &ContactConfig::default()).unwrap();
    let cfg = SolverConfig { substeps: 2, pos_iters: 4, vel_iters: 1, ..Default::default() };
    let solver = GpuSolver::new(g, &pipe, &bodies, &cfg).unwrap();
    let start = BodyState {
        body_q: vec![TransformGpu::new(Vec3::new(0.0, 0.0, 1.0), Quat::IDENTITY); worlds as usize],
        body_qd: vec![[Vec3::ZERO; 2]; worlds as usize],
    };
    let mut control = Control::zeros(worlds as usize, 1);
    control.body_f[0] = [Vec3::new(0.3, -0.1, 0.2), Vec3::new(0.0, 0.0, 2e-4)];
    control.body_f[1] = [Vec3::new(-0.05, 0.0, 0.0), Vec3::new(0.0, 0.0, -1e-4)];
    let frames = 30;
    solver.write_state(g, &pipe, &start);
    solver.write_control(g, &control);
    // The CPU reference gets its own pipeline: it writes its poses into the pipeline's body_q.
    let cpu_pipe = ContactPipeline::new(g, &contacts, worlds, &ContactConfig::default()).unwrap();
    let mut cpu = start.clone();
    let mut warm = WarmStart::default();
    for _ in 0..frames {
        frame(g, &pipe, &solver);
        assert!(step_cpu_with_pipeline(g, &cpu_pipe, &bodies, &mut cpu, &cfg, &control, &mut warm).iter().all(|&o| o));
    }
    let (gpu_state, ok) = solver.read_state(g, &pipe);
    assert!(ok.iter().all(|&o| o));
    let t = frames as f32 * cfg.dt;
    let inv_m = bodies.body_inv_mass[0];
    for (who, s) in [("GPU", &gpu_state), ("CPU", &cpu)] {
        for w in 0..worlds as usize {
            let [f, tau] = control.body_f[w];
            let (v, om) = (f * inv_m * t, bodies.body_inv_inertia[0] * tau * t);
            let [vg, og] = s.body_qd[w];
            eprintln!("{who} world {w}: v {vg} (analytic {v}), w {og} (analytic {om})");
            assert!((vg - v).length() <= 1e-5 * v.length().max(1e-3), "{who} world {w}: v {vg}, expected {v}");
            assert!((og - om).length() <= 1e-5 * om.length().max(1e-3), "{who} world {w}: w {og}, expected {om}");
            // Position: x = F t^2 / (2 m) up to the time discretisation (semi-implicit Euler, 60 substeps:
            // x_n = a h^2 n (n + 1) / 2, 1/n above the exact value).
            let x = Vec3::from_slice(&s.body_q[w].p[..3]) - Vec3::new(0.0, 0.0, 1.0);
            let exact = 0.5 * f * inv_m * t * t;
            let n = (frames * cfg.substeps) as f32;
            assert!(
                (x - exact * (1.0 + 1.0 / n)).length() <= 1e-4 * exact.length().max(1e-6),
                "{who} world {w}: x {x}"
            );
        }
        assert_eq!(s.body_qd[2], [Vec3::ZERO; 2], "{who}: the world without a wrench moved");
    }
    // Set to nothing: the bodies coast at the velocity they have.
    solver.write_control(g, &Control::default());
    let before = solver.read_state(g, &pipe).0;
    frame(g, &pipe, &solver);
    let after = solver.read_state(g, &pipe).0;
    assert_eq!(before.body_qd, after.body_qd, "cleared wrenches still act");
}

#[test]
fn add_force_at_a_point_adds_its_moment_about_the_centre_of_mass() {
    let (_, bodies) = scene(0.0);
    let state = BodyState {
        body_q: vec![TransformGpu::new(Vec3::new(1.0, 2.0, 3.0), Quat::from_rotation_z(0.5))],
        body_qd: vec![[Vec3::ZERO; 2]],
    };
    let mut c = Control::zeros(1, 1);
    c.add_force_at(&bodies, &state, 0, 0, Vec3::X, Vec3::new(1.0, 2.5, 3.0));
    c.add_force_at(&bodies, &state, 0, 0, Vec3::Z, Vec3::new(1.0, 2.0, 3.0));
    assert_eq!(c.body_f[0][0], Vec3::new(1.0, 0.0, 1.0));
    // (0, 0.5, 0) x (1, 0, 0) = (0, 0, -0.5); the force through the COM adds none.
    assert!((c.body_f[0][1] - Vec3::new(0.0, 0.0, -0.5)).length() < 1e-6);
}

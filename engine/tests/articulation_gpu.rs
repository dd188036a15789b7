//! The articulation kernels (articulation/gpu.rs, articulation.wgsl) against the CPU reference
//! (articulation/dynamics.rs): `dynamics` against `world_dynamics` and `step` against `step_cpu` on the
//! Franka at 64 seeded worlds, a double pendulum against the textbook equations of motion, and the refusals.
//!
//! Tolerances: the kernels run the host's algorithms in the same order, in f32 both sides, so they differ
//! by rounding only (GPU sin/cos/sqrt/normalize and fused multiply-adds differ from the host's in the last
//! bits). Each quantity is compared against its own largest entry in that world (entry-wise relative error
//! is meaningless for the zeros of a Jacobian or the tiny finger terms of M), measured errors are printed,
//! and every tolerance sits 10x or more above what lavapipe measured, so that a GPU's different rounding
//! passes and a wrong term (a missing armature, a sign, a dropped Coriolis term: errors of 1e-3 relative and
//! up) fails.

use factory_engine::articulation::dynamics::{step_cpu, world_dynamics, WorldDynamics};
use factory_engine::articulation::gpu::{loop_passes, ArticulationGpu};
use factory_engine::articulation::{
    ArticulationControl, ArticulationModel, ArticulationState, Frame, JointKind, NO_DOF, NO_LINK,
};
use factory_engine::gpu::GpuContext;
use factory_engine::rng::SplitMix64;
use factory_engine::urdf::load_urdf;
use factory_engine::EngineError;
use glam::{Mat3, Quat, Vec3};
use std::path::PathBuf;

fn gpu() -> &'static GpuContext {
    GpuContext::global().expect("a GPU or lavapipe")
}

fn franka() -> ArticulationModel {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../assets/franka/franka_panda.urdf");
    let urdf = load_urdf(&path).expect("the Franka URDF loads");
    let mut m = ArticulationModel::from_urdf(&urdf, (Vec3::ZERO, Quat::IDENTITY), Vec3::new(0.0, 0.0, -9.81))
        .expect("the Franka URDF is an articulation");
    // IsaacGymEnvs' Factory gives every Franka joint 0.01 armature (as in articulation_franka.rs).
    m.set_armature(0.01);
    m
}

fn fingertip(m: &ArticulationModel) -> Frame {
    m.frame("panda_fingertip_centered").expect("the Franka has Factory's fingertip frame")
}

fn uniform(rng: &mut SplitMix64, lo: f32, hi: f32) -> f32 {
    lo + (hi - lo) * rng.unit()
}

/// Random joint positions inside the limits (within +-2.8 rad), except that a continuous joint (the
/// Franka's joint 7) turns up to +-12 rad, past the range where GPU sine is accurate without the
/// kernel's angle reduction; velocities up to +-1.5 rad/s (arm) or +-0.1 m/s (fingers).
fn random_state(m: &ArticulationModel, worlds: usize, rng: &mut SplitMix64) -> ArticulationState {
    let mut s = ArticulationState { joint_q: Vec::new(), joint_qd: Vec::new() };
    for _ in 0..worlds {
        for d in 0..m.dof_count() {
            let (lo, hi) = if m.dof_lower[d].is_finite() {
                (m.dof_lower[d].max(-2.8), m.dof_upper[d].min(2.8))
            } else {
                (-12.0, 12.0)
            };
            s.joint_q.push(uniform(rng, lo, hi));
            let v = if m.link_joint[m.dof_link[d] as usize] == JointKind::Prismatic { 0.1 } else { 1.5 };
            s.joint_qd.push(uniform(rng, -v, v));
        }
    }
    s
}

/// Largest |a - b| over two slices, and the largest |b| (the reference's scale).
fn err_scale(a: &[f32], b: &[f32]) -> (f32, f32) {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).fold((0.0f32, 0.0f32), |(e, s), (x, y)| (e.max((x - y).abs()), s.max(y.abs())))
}

/// Worst error of each compared quantity over the worlds: (absolute for poses, relative to the quantity's
/// largest entry for the rest).
#[derive(Debug, Default)]
struct DynamicsErrors {
    link_pos: f32,
    link_rot: f32,
    frame_pos: f32,
    frame_rot: f32,
    twist: f32,
    jacobian: f32,
    mass_matrix: f32,
    gravity: f32,
    coriolis: f32,
}

/// Angle [rad] between two rotations, from the vector part of the relative rotation (an arccosine of
/// their dot product loses small angles to f32 rounding: 1 ulp below 1 reads as 1e-3 rad).
fn angle(a: Quat, b: Quat) -> f32 {
    2.0 * (a.conjugate() * b).xyz().length().min(1.0).asin()
}

fn compare(gpu: &[WorldDynamics], cpu: &[WorldDynamics]) -> DynamicsErrors {
    let mut e = DynamicsErrors::default();
    let rel = |a: &[f32], b: &[f32]| {
        let (err, scale) = err_scale(a, b);
        err / scale.max(1e-6)
    };
    for (g, c) in gpu.iter().zip(cpu) {
        for (pg, pc) in g.link_pose.iter().zip(&c.link_pose) {
            e.link_pos = e.link_pos.max((pg.0 - pc.0).length());
            e.link_rot = e.link_rot.max(angle(pg.1, pc.1));
        }
        e.frame_pos = e.frame_pos.max((g.frame_pose.0 - c.frame_pose.0).length());
        e.frame_rot = e.frame_rot.max(angle(g.frame_pose.1, c.frame_pose.1));
        let twist = |d: &WorldDynamics| [d.frame_linvel.to_array(), d.frame_angvel.to_array()].concat();
        e.twist = e.twist.max(rel(&twist(g), &twist(c)));
        e.jacobian = e.jacobian.max(rel(&g.jacobian, &c.jacobian));
        e.mass_matrix = e.mass_matrix.max(rel(&g.mass_matrix, &c.mass_matrix));
        e.gravity = e.gravity.max(rel(&g.gravity_torque, &c.gravity_torque));
        e.coriolis = e.coriolis.max(rel(&g.coriolis_torque, &c.coriolis_torque));
    }
    e
}

fn gpu_dynamics(g: &GpuContext, art: &ArticulationGpu) -> Vec<WorldDynamics> {
    let mut enc = g.device.create_command_encoder(&Default::default());
    art.encode_dynamics(&mut enc);
    g.queue.submit([enc.finish()]);
    art.read_dynamics(g)
}

/// Positions [m] and rotations [rad] agree to 1e-5: rounding over the 13-link chain of a 1 m arm is a
/// few ulps of 1 m per link (lavapipe: 2.6e-7 m, 7.2e-7 rad). Jacobian, twist, M, g and c agree to 1e-4
/// of their largest entry (lavapipe: 4e-7 to 1.4e-6; dropping the armature, a Coriolis term or halving a
/// prismatic joint's Coriolis force each fails it).
const POSE_TOL: f32 = 1e-5;
const DYNAMICS_REL_TOL: f32 = 1e-4;

#[test]
fn gpu_dynamics_matches_world_dynamics_on_the_franka() {
    let g = gpu();
    let m = franka();
    let frame = fingertip(&m);
    let worlds = 64;
    let state = random_state(&m, worlds, &mut SplitMix64(0xA271));
    let art = ArticulationGpu::new(g, &m, worlds as u32, &frame, 1.0 / 60.0, 2).unwrap();
    art.write_state(g, &state).unwrap();
    let got = gpu_dynamics(g, &art);
    let n = m.dof_count();
    let want: Vec<WorldDynamics> = (0..worlds)
        .map(|w| {
            let r = w * n..(w + 1) * n;
            world_dynamics(&m, &state.joint_q[r.clone()], &state.joint_qd[r], &frame)
        })
        .collect();
    let e = compare(&got, &want);
    println!("Franka dynamics, 64 worlds, GPU vs CPU: {e:?}");
    for (name, err, tol) in [
        ("link position [m]", e.link_pos, POSE_TOL),
        ("link rotation [rad]", e.link_rot, POSE_TOL),
        ("frame position [m]", e.frame_pos, POSE_TOL),
        ("frame rotation [rad]", e.frame_rot, POSE_TOL),
        ("frame twist (rel)", e.twist, DYNAMICS_REL_TOL),
        ("jacobian (rel)", e.jacobian, DYNAMICS_REL_TOL),
        ("mass matrix (rel)", e.mass_matrix, DYNAMICS_REL_TOL),
        ("gravity torque (rel)", e.gravity, DYNAMICS_REL_TOL),
        ("coriolis torque (rel)", e.coriolis, DYNAMICS_REL_TOL),
    ] {
        assert!(err <= tol, "{name}: {err} > {tol}\n{e:?}");
    }
    // The mirrored matrix is exactly symmetric, as the controllers assume.
    for d in &got {
        for i in 0..n {
            for j in 0..n {
                assert_eq!(d.mass_matrix[i * n + j], d.mass_matrix[j * n + i]);
            }
        }
    }
}

/// 60 frames (1 s at Factory's dt = 1/60 s, 2 substeps) of `step` against `step_cpu` from the same
/// states under the same torques; returns the worst |q| [rad or m] and |qd| [rad/s or m/s] differences over
/// every frame and world.
fn step_parity(m: &ArticulationModel, seed: u64, drives: bool) -> (f32, f32) {
    let g = gpu();
    let frame = fingertip(m);
    let (worlds, n) = (64usize, m.dof_count());
    let mut rng = SplitMix64(seed);
    let mut cpu = random_state(m, worlds, &mut rng);
    // Torques: each world's gravity torque at its start (so the arm moves, not falls) plus a seeded random
    // torque of up to 10% of the effort limit (the fingers' 20 N limit, 2 N, slams them into their stops:
    // the position limits are exercised too).
    let mut control = ArticulationControl::default();
    for w in 0..worlds {
        let r = w * n..(w + 1) * n;
        let d = world_dynamics(m, &cpu.joint_q[r.clone()], &cpu.joint_qd[r.clone()], &frame);
        for i in 0..n {
            let limit = m.dof_effort_limit[i];
            control.joint_tau.push(d.gravity_torque[i] + uniform(&mut rng, -0.1, 0.1) * limit);
        }
        if drives {
            control.joint_target_q.extend(r.map(|i| cpu.joint_q[i] + uniform(&mut rng, -0.3, 0.3)));
        }
    }
    let (dt, substeps) = (1.0 / 60.0, 2);
    let mut art = ArticulationGpu::new(g, m, worlds as u32, &frame, dt, substeps).unwrap();
    art.write_state(g, &cpu).unwrap();
    art.write_control(g, &control).unwrap();
    assert_eq!(art.drives(), drives);
    let (mut q_err, mut qd_err) = (0.0f32, 0.0f32);
    for _ in 0..60 {
        let mut enc = g.device.create_command_encoder(&Default::default());
        art.encode_step(&mut enc);
        g.queue.submit([enc.finish()]);
        let diverged = step_cpu(m, &mut cpu, &control, dt, substeps);
        assert!(diverged.iter().all(|d| !d), "the CPU reference stays finite");
        let got = art.read_state(g);
        q_err = q_err.max(err_scale(&got.joint_q, &cpu.joint_q).0);
        qd_err = qd_err.max(err_scale(&got.joint_qd, &cpu.joint_qd).0);
    }
    (q_err, qd_err)
}

/// Stepping compounds rounding differences through 120 substeps of a mildly chaotic arm, and a joint that
/// reaches a limit a substep apart on the two sides differs by one substep's motion. lavapipe measured
/// 1.7e-5 rad and 1.2e-4 rad/s at worst without drives, 1e-6 and 2.5e-6 with (their damping contracts
/// differences). Tolerances 1e-3 rad and 2e-2 rad/s keep a margin of 50x or more for a GPU's rounding and
/// still catch a wrong term: dropping the armature, a Coriolis term, the drive's implicit damping or the
/// velocity clamp each fails one of the step tests.
const STEP_Q_TOL: f32 = 1e-3;
const STEP_QD_TOL: f32 = 2e-2;

#[test]
fn gpu_step_matches_step_cpu_on_the_franka_for_60_frames() {
    let (q_err, qd_err) = step_parity(&franka(), 0x5EED, false);
    println!("Franka step, 64 worlds x 60 frames, GPU vs CPU: q {q_err}, qd {qd_err}");
    assert!(q_err <= STEP_Q_TOL && qd_err <= STEP_QD_TOL, "q {q_err}, qd {qd_err}");
}

/// The same with position drives on every joint, joint damping and tighter velocity limits: the drive
/// force, its implicit damping and the velocity clamp are in play.
#[test]
fn gpu_step_with_drives_and_damping_matches_step_cpu() {
    let mut m = franka();
    for d in 0..m.dof_count() {
        let finger = m.link_joint[m.dof_link[d] as usize] == JointKind::Prismatic;
        m.dof_drive_stiffness[d] = if finger { 500.0 } else { 200.0 };
        m.dof_drive_damping[d] = if finger { 5.0 } else { 20.0 };
        m.dof_damping[d] = if finger { 0.5 } else { 2.0 };
        m.dof_velocity_limit[d] = m.dof_velocity_limit[d].min(1.0);
    }
    let (q_err, qd_err) = step_parity(&m, 0xD21E, true);
    println!("Franka step with drives, 64 worlds x 60 frames, GPU vs CPU: q {q_err}, qd {qd_err}");
    assert!(q_err <= STEP_Q_TOL && qd_err <= STEP_QD_TOL, "q {q_err}, qd {qd_err}");
}

/// Two links swinging about y, point masses m1, m2 at their tips (lengths l1, l2), links along +x at q = 0,
/// gravity -z (the same model as dynamics.rs's unit tests).
fn double_pendulum(l1: f32, l2: f32, m1: f32, m2: f32) -> ArticulationModel {
    ArticulationModel {
        name: "double pendulum".into(),
        link_name: vec!["base".into(), "upper".into(), "lower".into()],
        link_parent: vec![NO_LINK, 0, 1],
        link_joint: vec![JointKind::Fixed, JointKind::Revolute, JointKind::Revolute],
        link_dof: vec![NO_DOF, 0, 1],
        link_origin: vec![
            (Vec3::ZERO, Quat::IDENTITY),
            (Vec3::ZERO, Quat::IDENTITY),
            (Vec3::new(l1, 0.0, 0.0), Quat::IDENTITY),
        ],
        link_axis: vec![Vec3::Y; 3],
        link_mass: vec![0.0, m1, m2],
        link_com: vec![Vec3::ZERO, Vec3::new(l1, 0.0, 0.0), Vec3::new(l2, 0.0, 0.0)],
        link_inertia: vec![Mat3::ZERO; 3],
        dof_name: vec!["j1".into(), "j2".into()],
        dof_link: vec![1, 2],
        dof_lower: vec![f32::NEG_INFINITY; 2],
        dof_upper: vec![f32::INFINITY; 2],
        dof_velocity_limit: vec![f32::INFINITY; 2],
        dof_effort_limit: vec![f32::INFINITY; 2],
        dof_damping: vec![0.0; 2],
        dof_armature: vec![0.0; 2],
        dof_drive_stiffness: vec![0.0; 2],
        dof_drive_damping: vec![0.0; 2],
        frames: vec![],
        gravity: Vec3::new(0.0, 0.0, -9.81),
    }
}

/// The kernel's M, g and c of a planar double pendulum against the textbook (Spong, Hutchinson and
/// Vidyasagar, "Robot Modeling and Control", 2006, section 7.4, point masses; the planar angle is -q, as
/// dynamics.rs's test explains), at 5 worlds (a partial workgroup), and 60 frames of `step` against
/// `step_cpu` (no limits: a free swing).
#[test]
fn gpu_double_pendulum_matches_the_textbook_and_the_cpu_step() {
    let g = gpu();
    let (l1, l2, m1, m2) = (0.7f32, 0.4f32, 1.3f32, 0.6f32);
    let m = double_pendulum(l1, l2, m1, m2);
    let cases = [
        (0.3f32, -0.8f32, 1.1f32, -0.4f32),
        (-1.2, 2.0, -0.3, 2.2),
        (0.0, 0.0, 0.5, 0.5),
        (2.5, -3.0, 0.0, 1.0),
        (-0.4, 0.9, 3.0, -2.0),
    ];
    let state = ArticulationState {
        joint_q: cases.iter().flat_map(|c| [c.0, c.1]).collect(),
        joint_qd: cases.iter().flat_map(|c| [c.2, c.3]).collect(),
    };
    let frame = Frame { name: "tip".into(), link: 2, offset: (Vec3::new(l2, 0.0, 0.0), Quat::IDENTITY) };
    let (dt, substeps) = (1.0 / 60.0, 4);
    let art = ArticulationGpu::new(g, &m, cases.len() as u32, &frame, dt, substeps).unwrap();
    art.write_state(g, &state).unwrap();
    let got = gpu_dynamics(g, &art);
    let grav = 9.81f32;
    let mut worst = 0.0f32;
    for (d, &(q1, q2, v1, v2)) in got.iter().zip(&cases) {
        let c2 = q2.cos();
        let m11 = m1 * l1 * l1 + m2 * (l1 * l1 + l2 * l2 + 2.0 * l1 * l2 * c2);
        let m12 = m2 * (l2 * l2 + l1 * l2 * c2);
        let m22 = m2 * l2 * l2;
        let (t1, t2) = (-q1, -q2);
        let gth1 = grav * (m1 * l1 * t1.cos() + m2 * (l1 * t1.cos() + l2 * (t1 + t2).cos()));
        let gth2 = grav * m2 * l2 * (t1 + t2).cos();
        let (w1, w2) = (-v1, -v2);
        let h = m2 * l1 * l2 * t2.sin();
        let cth = [-h * (2.0 * w1 * w2 + w2 * w2), h * w1 * w1];
        // Scales: M11 for M, the largest gravity torque (m1 + m2) g l1 + m2 g l2 for g, h (|w| + |w|)^2 for c.
        let (sm, sg) = (m11, grav * ((m1 + m2) * l1 + m2 * l2));
        let sc = (m2 * l1 * l2 * (v1.abs() + v2.abs()).powi(2)).max(1e-3);
        let errs = [
            (d.mass_matrix[0] - m11).abs() / sm,
            (d.mass_matrix[1] - m12).abs() / sm,
            (d.mass_matrix[2] - m12).abs() / sm,
            (d.mass_matrix[3] - m22).abs() / sm,
            (d.gravity_torque[0] + gth1).abs() / sg,
            (d.gravity_torque[1] + gth2).abs() / sg,
            (d.coriolis_torque[0] + cth[0]).abs() / sc,
            (d.coriolis_torque[1] + cth[1]).abs() / sc,
        ];
        worst = errs.iter().fold(worst, |a, &b| a.max(b));
        // The tip frame: at l1 (cos t1, sin t1) + l2 (cos(t1 + t2), sin(t1 + t2)) in the x-z plane.
        let tip = Vec3::new(l1 * t1.cos() + l2 * (t1 + t2).cos(), 0.0, l1 * t1.sin() + l2 * (t1 + t2).sin());
        assert!((d.frame_pose.0 - tip).length() < POSE_TOL, "tip {:?} vs {tip:?}", d.frame_pose.0);
    }
    println!("double pendulum vs textbook, worst relative error {worst}");
    assert!(worst < DYNAMICS_REL_TOL, "{worst}\n{got:?}");

    let mut cpu = state.clone();
    let (mut q_err, mut qd_err) = (0.0f32, 0.0f32);
    let control = ArticulationControl::default();
    for _ in 0..60 {
        let mut enc = g.device.create_command_encoder(&Default::default());
        art.encode_step(&mut enc);
        g.queue.submit([enc.finish()]);
        step_cpu(&m, &mut cpu, &control, dt, substeps);
        let s = art.read_state(g);
        q_err = q_err.max(err_scale(&s.joint_q, &cpu.joint_q).0);
        qd_err = qd_err.max(err_scale(&s.joint_qd, &cpu.joint_qd).0);
    }
    println!("double pendulum, 5 worlds x 60 frames, GPU vs CPU: q {q_err}, qd {qd_err}");
    // lavapipe: 2.6e-6 rad, 2.5e-5 rad/s. A double pendulum is chaotic at these energies: over 5 s instead
    // of 1 s the same rounding grows to 5e-2 rad, so the comparison keeps to one second, as the Franka's.
    assert!(q_err <= STEP_Q_TOL && qd_err <= STEP_QD_TOL, "q {q_err}, qd {qd_err}");
}

#[test]
fn shapes_and_loop_budget_are_refused_by_name() {
    let g = gpu();
    let m = franka();
    let frame = fingertip(&m);
    let art = ArticulationGpu::new(g, &m, 4, &frame, 1.0 / 60.0, 2).unwrap();
    let short = ArticulationState { joint_q: vec![0.0; 9 * 3], joint_qd: vec![0.0; 9 * 4] };
    match art.write_state(g, &short) {
        Err(EngineError::Config { field: "joint_q", .. }) => {}
        other => panic!("expected joint_q refused, got {other:?}"),
    }
    let mut bad_frame = frame.clone();
    bad_frame.link = 99;
    match ArticulationGpu::new(g, &m, 4, &bad_frame, 1.0 / 60.0, 2) {
        Err(EngineError::Config { field: "frame.link", .. }) => {}
        Err(e) => panic!("expected frame.link refused, got {e}"),
        Ok(_) => panic!("expected frame.link refused"),
    }
    // lavapipe cuts an invocation's loops short past 65535 passes; a step of 100 Franka substeps would
    // need more than that, so a software adapter refuses it (a GPU has no such limit).
    let budget = factory_engine::contact::LOOP_ITERATION_LIMIT as u64 / 8 * 7;
    let (step2, dynamics) = loop_passes(&m, &frame, 2);
    let (step100, _) = loop_passes(&m, &frame, 100);
    println!("Franka loop passes: step of 2 substeps {step2}, of 100 {step100}, dynamics {dynamics}; budget {budget}");
    assert!(step2 <= budget && dynamics <= budget && step100 > budget);
    if g.is_software() {
        match ArticulationGpu::new(g, &m, 4, &frame, 1.0 / 60.0, 100) {
            Err(EngineError::Config { field: "substeps", .. }) => {}
            Err(e) => panic!("expected substeps refused, got {e}"),
            Ok(_) => panic!("expected substeps refused on a software adapter"),
        }
    }
}

/// A rigid model (one link, no degrees of freedom) runs: its link sits at the base pose, stepping leaves it.
#[test]
fn a_model_without_dofs_runs() {
    let g = gpu();
    let mut m = double_pendulum(0.5, 0.5, 1.0, 1.0);
    let base = (Vec3::new(0.1, -0.2, 0.3), Quat::from_rotation_z(0.4));
    m.link_name.truncate(1);
    m.link_parent.truncate(1);
    m.link_joint.truncate(1);
    m.link_dof.truncate(1);
    m.link_origin = vec![base];
    m.link_axis.truncate(1);
    m.link_mass = vec![2.0];
    m.link_com.truncate(1);
    m.link_inertia = vec![Mat3::IDENTITY];
    m.dof_name.clear();
    m.dof_link.clear();
    for v in [
        &mut m.dof_lower,
        &mut m.dof_upper,
        &mut m.dof_velocity_limit,
        &mut m.dof_effort_limit,
        &mut m.dof_damping,
        &mut m.dof_armature,
        &mut m.dof_drive_stiffness,
        &mut m.dof_drive_damping,
    ] {
        v.clear();
    }
    let frame = Frame { name: "base".into(), link: 0, offset: (Vec3::ZERO, Quat::IDENTITY) };
    let art = ArticulationGpu::new(g, &m, 3, &frame, 1.0 / 60.0, 2).unwrap();
    let mut enc = g.device.create_command_encoder(&Default::default());
    art.encode_step(&mut enc);
    g.queue.submit([enc.finish()]);
    let got = gpu_dynamics(g, &art);
    assert_eq!(got.len(), 3);
    for d in &got {
        assert!((d.link_pose[0].0 - base.0).length() < 1e-6 && angle(d.link_pose[0].1, base.1) < 1e-6, "{d:?}");
        assert!(d.jacobian.is_empty() && d.mass_matrix.is_empty() && d.gravity_torque.is_empty());
    }
    assert!(art.read_state(g).joint_q.is_empty());
}

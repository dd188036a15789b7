//! Factory's controllers on the simulated Franka (assets/franka/franka_panda.urdf, the engine's
//! articulation): the motion controllers reach a 10 cm / 30 degree free-space target, the force controllers
//! press the fingertip on a table with 5 N, and the hybrid controller holds 5 N along z while tracking a
//! path in xy. Settings: Factory's dt = 1/60 s with 2 substeps; the controller acts once per frame.

use factory_controllers::{build, ArmBatch, Controller, ControllerConfig, Targets};
use factory_engine::articulation::dynamics::step_cpu;
use factory_engine::articulation::{ArticulationControl, ArticulationModel, ArticulationState, Frame};
use factory_engine::builder::ModelBuilder;
use factory_engine::contact::roles::ShapeGeometry;
use factory_engine::contact::{ContactConfig, TransformGpu};
use factory_engine::gpu::GpuContext;
use factory_engine::sdf::cache::SdfCache;
use factory_engine::sim::ArticulatedSim;
use factory_engine::solver::{BodyState, Control, SolverConfig};
use factory_engine::urdf::{load_urdf, UrdfModel};
use glam::{Quat, Vec3};
use std::path::PathBuf;

const DT: f32 = 1.0 / 60.0;
const SUBSTEPS: u32 = 2;
/// IsaacGymEnvs' Pick reset pose (FactoryTaskNutBoltPick.yaml), fingers 2 cm open.
const Q_PICK: [f32; 9] = [0.3413, -0.8011, -0.0670, -1.8299, 0.0266, 1.0185, 1.0927, 0.02, 0.02];
/// Factory's Screw reset pose (the hand points straight down), fingers closed.
const Q_SCREW: [f32; 9] = [1.5178e-3, -0.19651, -1.4364e-3, -1.9761, -2.7717e-4, 1.7796, 0.78556, 0.0, 0.0];

fn franka() -> (UrdfModel, ArticulationModel) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../assets/franka/franka_panda.urdf");
    let urdf = load_urdf(&path).unwrap();
    let mut m = ArticulationModel::from_urdf(&urdf, (Vec3::ZERO, Quat::IDENTITY), Vec3::new(0.0, 0.0, -9.81)).unwrap();
    // IsaacGymEnvs' Factory: armature 0.01 on every joint (factory_base.py's Franka asset options).
    m.set_armature(0.01);
    (urdf, m)
}

fn tip(m: &ArticulationModel) -> Frame {
    m.frame("panda_fingertip_centered").unwrap()
}

fn controller(toml: &str) -> Box<dyn Controller> {
    build(&ControllerConfig::from_toml_str(toml).unwrap(), 9, 7).unwrap()
}

/// Position [m] and rotation [rad] error of the fingertip against a target.
fn pose_error(arm: &ArmBatch, t: &Targets) -> (f32, f32) {
    let dq = t.ee_quat[0] * arm.ee_quat[0].inverse();
    (arm.ee_pos[0].distance(t.ee_pos[0]), 2.0 * dq.w.abs().min(1.0).acos())
}

/// Runs `ctrl` in free space from the Pick pose towards a target 10 cm away and turned 30 degrees;
/// returns the first time [s] the fingertip is within `pos_tol` [m] and `rot_tol` [rad] and stays within
/// them to the end of `seconds`, and the final errors.
fn reach(ctrl: &dyn Controller, seconds: f32, pos_tol: f32, rot_tol: f32) -> (Option<f32>, f32, f32) {
    let (_, m) = franka();
    let frame = tip(&m);
    let mut state = ArticulationState::replicate(&Q_PICK, 1);
    let arm = ArmBatch::from_articulation(&m, &state, &frame, 7, &[]);
    let mut targets = Targets::hold(&arm);
    // 10 cm along a direction with a component on every axis; 30 degrees about a tilted axis.
    targets.ee_pos[0] += Vec3::new(0.06, -0.05, -0.0625).normalize() * 0.1;
    targets.ee_quat[0] =
        Quat::from_axis_angle(Vec3::new(0.3, -0.5, 0.8).normalize(), 30f32.to_radians()) * targets.ee_quat[0];
    let mut tau = vec![0.0f32; 9];
    let mut settled_at = None;
    let frames = (seconds / DT).round() as usize;
    let mut last = (0.0, 0.0);
    for f in 0..frames {
        let arm = ArmBatch::from_articulation(&m, &state, &frame, 7, &[]);
        last = pose_error(&arm, &targets);
        let inside = last.0 < pos_tol && last.1 < rot_tol;
        match (inside, settled_at) {
            (true, None) => settled_at = Some(f as f32 * DT),
            (false, Some(_)) => settled_at = None,
            _ => {}
        }
        ctrl.compute(&arm, &targets, &mut tau);
        let diverged = step_cpu(
            &m,
            &mut state,
            &ArticulationControl { joint_tau: tau.clone(), ..Default::default() },
            DT,
            SUBSTEPS,
        );
        assert!(!diverged[0], "{}: diverged", ctrl.name());
    }
    (settled_at, last.0, last.1)
}

/// Each motion controller reaches a 10 cm / 30 degree free-space target within a stated time and
/// error. Gains: IsaacGymEnvs' joint-space ID and OSC gains scaled for an arm with gravity (compensated)
/// and without its added damping; IndustReal's task-space impedance gains (IsaacGymEnvs' IndustReal task
/// configs); joint-space IK with per-joint gains kept within what an explicit PD on the light wrist joints
/// allows at h = 1/120 s (kd h / I < 2).
#[test]
fn motion_controllers_reach_a_10_cm_30_degree_target() {
    // (config, time bound [s], position tolerance [m], rotation tolerance [rad])
    let cases = [
        (
            "type = \"joint_space_ik\"\nik_method = \"dls\"\nkp = [100, 100, 100, 100, 30, 30, 10]\nkd = [20, 20, 20, 20, 2, 2, 0.5]",
            3.0,
            1e-3,
            1f32.to_radians(),
        ),
        ("type = \"joint_space_id\"\nik_method = \"dls\"\nkp = 100\nkd = 20", 2.0, 1e-3, 1f32.to_radians()),
        (
            "type = \"task_space_impedance\"\nkp = [300, 300, 300, 50, 50, 50]\nkd = [34, 34, 34, 1.4, 1.4, 1.4]",
            // Without inertia shaping the slowest task direction and the undamped elbow (null space) take
            // about 4 s to bring the last millimetre in (measured 4.0 s).
            4.5,
            1e-3,
            1f32.to_radians(),
        ),
        ("type = \"osc\"\nkp = 100\nkd = 20", 2.0, 1e-3, 1f32.to_radians()),
    ];
    let mut failures = Vec::new();
    for (toml, bound, pos_tol, rot_tol) in cases {
        let ctrl = controller(toml);
        let (t, pe, re) = reach(ctrl.as_ref(), 5.0, pos_tol, rot_tol);
        eprintln!(
            "{:<22} within {} mm / {:.1} deg after {:?} s; at 5 s: {:.4} mm, {:.4} deg",
            ctrl.name(),
            pos_tol * 1e3,
            rot_tol.to_degrees(),
            t,
            pe * 1e3,
            re.to_degrees()
        );
        match t {
            None => failures.push(format!("{}: not within tolerance at the end ({pe} m, {re} rad)", ctrl.name())),
            Some(t) if t > bound => failures.push(format!("{}: took {t} s, bound {bound} s", ctrl.name())),
            _ => {}
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// The Franka at the Screw pose with its finger pads `gap` [m] above a table (a half-space), contacts on
/// the GPU pipeline every frame.
fn table_scene(gap: f32, q: &[f32; 9]) -> (ArticulatedSim, Frame, usize) {
    let (urdf, mut m) = franka();
    // A little joint damping keeps the arm's null space (the force controllers leave 5 of 6 task axes
    // and the elbow free) from wandering; it exerts no force at rest, so it does not bias the 5 N.
    for d in 0..7 {
        m.dof_damping[d] = 2.0;
    }
    let frame = tip(&m);
    let state = ArticulationState::replicate(q, 1);
    let tip_z = ArmBatch::from_articulation(&m, &state, &frame, 7, &[]).ee_pos[0].z;
    let mut b = ModelBuilder::new(m.gravity);
    let table = b.add_shape(None, (Vec3::new(0.0, 0.0, tip_z - gap), Quat::IDENTITY), ShapeGeometry::Plane);
    // Factory: table friction 0.3, Franka 1.0.
    b.shape_mut(table).friction = 0.3;
    let (_, left) = b.add_urdf_link(&urdf, &m, "panda_leftfinger", 1.0, 0.005).unwrap();
    let (_, right) = b.add_urdf_link(&urdf, &m, "panda_rightfinger", 1.0, 0.005).unwrap();
    b.filter_pair(left[0], right[0]);
    let model = b.build(&SdfCache::new(SdfCache::default_dir())).unwrap();
    let nb = model.bodies.body_count();
    let bodies = BodyState {
        body_q: vec![TransformGpu::new(Vec3::ZERO, Quat::IDENTITY); nb],
        body_qd: vec![[Vec3::ZERO; 2]; nb],
    };
    let solver = SolverConfig { dt: DT, substeps: SUBSTEPS, pos_iters: 16, vel_iters: 0, ..Default::default() };
    let pairs = model.contacts.pairs.len();
    let sim =
        ArticulatedSim::new(GpuContext::global().unwrap(), model, m, solver, &ContactConfig::default(), bodies, state)
            .unwrap();
    (sim, frame, pairs)
}

/// The force the finger pads exert on the table [N] (world frame): the opposite of the table's push on
/// the pads, over the pad-table pairs (every pair of this scene but none other).
fn force_on_table(sim: &ArticulatedSim, pairs: usize) -> Vec3 {
    -(0..pairs).map(|p| sim.pair_force(GpuContext::global().unwrap(), 0, p)).sum::<Vec3>()
}

/// Runs `ctrl` on the table scene for `seconds`, the targets from `target(t, hold)`; the measured wrench
/// fed back is last frame's pad force on the table. Returns per frame (time, force on table, fingertip).
fn press(
    ctrl: &dyn Controller,
    seconds: f32,
    mut target: impl FnMut(f32, &Targets) -> Targets,
) -> Vec<(f32, Vec3, Vec3)> {
    let (mut sim, frame, pairs) = table_scene(2e-3, &Q_SCREW);
    let gpu = GpuContext::global().unwrap();
    let hold = Targets::hold(&ArmBatch::from_articulation(&sim.articulation, &sim.joints, &frame, 7, &[]));
    let mut tau = vec![0.0f32; 9];
    let mut measured = [0.0f32; 6];
    let mut out = Vec::new();
    for f in 0..(seconds / DT).round() as usize {
        let t = f as f32 * DT;
        let arm = ArmBatch::from_articulation(&sim.articulation, &sim.joints, &frame, 7, &[measured]);
        ctrl.compute(&arm, &target(t, &hold), &mut tau);
        let diverged =
            sim.step(gpu, &Control::default(), &ArticulationControl { joint_tau: tau.clone(), ..Default::default() });
        assert!(!diverged[0], "{}: diverged", ctrl.name());
        let force = force_on_table(&sim, pairs);
        measured = [force.x, force.y, force.z, 0.0, 0.0, 0.0];
        let tip = ArmBatch::from_articulation(&sim.articulation, &sim.joints, &frame, 7, &[]).ee_pos[0];
        out.push((t, force, tip));
    }
    out
}

/// Mean and largest deviation of the z force over the last second [N].
fn steady_z(trace: &[(f32, Vec3, Vec3)]) -> (f32, f32) {
    let tail = &trace[trace.len() - 60..];
    let mean = tail.iter().map(|x| x.1.z).sum::<f32>() / tail.len() as f32;
    (mean, tail.iter().map(|x| (x.1.z - mean).abs()).fold(0.0, f32::max))
}

/// The open-loop and closed-loop force controllers press the fingertip on the table at 5 N within 5%
/// at steady state. The target wrench is the force the fingertip applies: 5 N down, (0, 0, -5).
#[test]
fn force_controllers_press_the_table_with_5_n() {
    let press_down = |_: f32, hold: &Targets| {
        let mut t = hold.clone();
        t.ee_wrench[0] = [0.0, 0.0, -5.0, 0.0, 0.0, 0.0];
        t
    };
    for toml in ["type = \"open_loop_force\"", "type = \"closed_loop_force\"\nkf = 0.1"] {
        let ctrl = controller(toml);
        let trace = press(ctrl.as_ref(), 3.0, press_down);
        let (mean, spread) = steady_z(&trace);
        eprintln!("{}: last second mean {mean:.4} N (spread {spread:.4} N) on the table", ctrl.name());
        assert!((mean + 5.0).abs() < 0.25, "{}: {mean} N, want -5 N within 5%", ctrl.name());
        // Frame by frame the pads' friction rows trade load (the fingertip creeps by micrometres), so single
        // frames scatter by up to about 5% around the mean (measured 0.25-0.27 N).
        assert!(spread < 0.5, "{}: force wanders by {spread} N", ctrl.name());
    }
}

/// The hybrid controller holds 5 N along z while tracking an xy path (a 4 cm circle in 8 s)
/// with OSC on x, y and the rotations. The pads slide on the table with Coulomb friction (mu 0.65 of the
/// pads' 1.0 and the table's 0.3): a P law without integral lags by mu F_n / (Lambda kp), about 3.3 N /
/// (0.95 kg x 1000 / s^2) = 3.5 mm along x (measured 3.5 mm at the end); along y the pads' friction is
/// taken up by the finger joints (the fingers slide along the hand's y axis against the gripper PD), so
/// the hand tracks y closely.
#[test]
fn hybrid_controller_holds_5_n_while_tracking_a_circle() {
    let ctrl = controller(
        "type = \"hybrid_force_motion\"\nmotion = \"osc\"\nkp = 1000\nkd = 63\nmotion_axes = [1, 1, 0, 1, 1, 1]\nforce = \"closed\"\nforce_axes = [0, 0, 1, 0, 0, 0]\nkf = 0.1",
    );
    let radius = 0.02f32;
    let path = |t: f32, hold: &Targets| {
        let mut g = hold.clone();
        // Settle for 1 s, then one circle in 4 s.
        let s = ((t - 1.0) / 8.0).clamp(0.0, 1.0) * std::f32::consts::TAU;
        g.ee_pos[0] += Vec3::new(radius * (s.cos() - 1.0), radius * s.sin(), 0.0);
        g.ee_wrench[0] = [0.0, 0.0, -5.0, 0.0, 0.0, 0.0];
        g
    };
    let trace = press(ctrl.as_ref(), 10.0, path);
    let (_, _, start) = trace[0];
    let mut worst_xy = 0.0f32;
    let mut worst_f = 0.0f32;
    for &(t, f, tip) in trace.iter().filter(|x| x.0 >= 1.0) {
        let s = ((t + DT - 1.0) / 8.0).clamp(0.0, 1.0) * std::f32::consts::TAU;
        let want = start + Vec3::new(radius * (s.cos() - 1.0), radius * s.sin(), 0.0);
        worst_xy = worst_xy.max((tip - want).truncate().length());
        worst_f = worst_f.max((f.z + 5.0).abs());
    }
    eprintln!("hybrid: xy tracking error up to {:.3} mm, z force error up to {:.3} N", worst_xy * 1e3, worst_f);
    assert!(worst_f < 0.5, "force error {worst_f} N while tracking (10% of 5 N)");
    assert!(worst_xy < 5e-3, "xy tracking error {worst_xy} m");
}

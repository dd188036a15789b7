//! `franka_nut_bolt`: IsaacGymEnvs' FactoryEnvNutBolt as a batched [`Env`], with the task chosen in config
//! (`task = "screw"`; Pick and Place are not written yet and are refused by name).
//!
//! Actions (12, in [-1, 1], paper section V and IsaacGymEnvs' `_apply_actions_as_ctrl_targets`): a position
//! increment (x `pos_action_scale` m), an axis-angle increment (x `rot_action_scale` rad), a force (x
//! `force_action_scale` N) and a torque (x `torque_action_scale` N m), all relative to the current fingertip
//! pose: `target_pos = pos + dp`, `target_quat = quat(dr) * quat` (increments below 1e-6 rad are none). With
//! `unidirectional_rot` (Screw's default) the yaw action maps to `-(a + 1) / 2`, so the policy can only turn
//! the nut clockwise (tightening). The controller (`[env.controller]`, any of the seven) turns the targets
//! into joint torques; the gripper is held closed by the finger drives. One action per control step of `dt`.
//!
//! The Screw task (FactoryTaskNutBoltScrew): the nut starts resting on the bolt's chamfered tip in the closed
//! hand (IsaacGymEnvs; or on the first thread, `start_engaged`), gripped with the fingertip at its bottom; the
//! observation is the fingertip's pose and twist and the nut's centre-of-mass pose and twist (26; plus the
//! finger contact forces (6) and the previous action (12) when asked, the paper's observation ablation);
//! the reward is `-(nut-to-target keypoint distance + pads-to-nut keypoint distance)`, each the sum over
//! 4 points spaced along a 0.112071 m segment (the hand plus finger length) rising from the body along its
//! axis, the pads' segment from the midpoint between the finger pads' centres ([`pad_midpoint`], half a pad
//! above the fingertip: IsaacGymEnvs' `fingerpad_midpoint_pos`); success when the nut's centre of mass is
//! within one thread pitch of its seated position (episode terminated); failure (terminated) when it is
//! more than `far_error` from it, has slipped from the fingers (its centre of mass farther from the pads'
//! midpoint than half the pad length plus half the nut height) or fallen off the bolt, or the world
//! diverged; truncated after `max_episode_steps`.

use factory_controllers::rotation::{pose_error, JacobianKind};
use factory_controllers::{build, linalg, ArmBatch, Controller, ControllerConfig, Targets};
use factory_engine::articulation::sim::CoupledSolve;
use factory_engine::articulation::{ArticulationControl, ArticulationState};
use factory_engine::contact::ContactConfig;
use factory_engine::gpu::GpuContext;
use factory_engine::rng::SplitMix64;
use factory_engine::solver::{Control, SolverConfig};
use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};

use super::scene::{NutBoltScene, SceneConfig, ARM_DOF, BASE, DOF, Q_START};
use crate::env::{Env, EnvSpec, StepBuffers, StepDiagnostics};
use crate::error::{EnvError, Result};

/// Factory's hand plus finger length [m] (factory_asset_info_franka_table.yaml: 0.0584 + 0.053671): the
/// keypoint segment's length.
pub const KEYPOINT_AXIS: f32 = 0.112071;
/// Factory's finger pad length [m] (the slip test).
pub const FINGERPAD_LENGTH: f32 = 0.017608;

/// The tasks on this env.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TaskName {
    /// Screw the nut from the bolt's tip down to the head.
    Screw,
}

/// Reset randomisation of the Screw task, each value drawn uniformly from `[lo, hi]` per episode. The default
/// draws nothing (IsaacGymEnvs' Screw); the paper's Table III ranges are in each field's doc.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ScrewRandomization {
    /// Hand and nut turned together about the bolt's axis [deg] (Table III "hand angle": [-90, 90]); the nut
    /// stays on the thread (its height follows the helix, one pitch per turn).
    pub hand_angle_deg: [f32; 2],
    /// Fingertip offset from the nut's grasp point [mm], in the nut's frame after the turn: x along the
    /// fingers' closing axis (each finger closes to its flat), y along the flats, z up (Table III:
    /// [-3, 3], [-3, 3], [0, 3]). An x offset grips the nut off-centre, and the two finger drives (both
    /// pulling to 0, as Factory's) then squeeze it unequally: a world drawn with 0.3 mm lost the nut within
    /// 21 steps of zero actions (measured). Keep x at [0, 0] until the gripper balances its fingers.
    pub fingertip_offset_mm: [[f32; 2]; 3],
}

impl Default for ScrewRandomization {
    fn default() -> Self {
        Self { hand_angle_deg: [0.0; 2], fingertip_offset_mm: [[0.0; 2]; 3] }
    }
}

/// `[env] type = "franka_nut_bolt"`. Defaults are IsaacGymEnvs' FactoryTaskNutBoltScrew where it has one.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FrankaNutBoltConfig {
    /// The task: "screw".
    pub task: TaskName,
    /// Control step [s] (Factory: 1/60).
    pub dt: f32,
    /// Solver substeps per control step (Factory's tasks: 2; default 4, see below).
    pub substeps: u32,
    /// Gauss-Seidel position iterations per substep (Factory's tasks: 16; default 32, see below).
    pub pos_iters: u32,
    /// Extra passes over the finger pads' contact patches per sweep (SolverConfig::link_patch_iters).
    pub link_patch_iters: u32,
    /// Control steps after which an episode is truncated (Factory's Screw: 8192).
    pub max_episode_steps: u32,
    /// Position action scale per axis [m].
    pub pos_action_scale: [f32; 3],
    /// Rotation action scale per axis [rad].
    pub rot_action_scale: [f32; 3],
    /// Force action scale per axis [N].
    pub force_action_scale: [f32; 3],
    /// Torque action scale per axis [N m].
    pub torque_action_scale: [f32; 3],
    /// Yaw action mapped to [-1, 0] (clockwise only).
    pub unidirectional_rot: bool,
    /// The controller (`type` = one of the seven; Factory's Screw: operational-space motion on z and yaw).
    pub controller: ControllerConfig,
    /// Damping of arm joints 1-6 [N m s/rad] (IsaacGymEnvs' Factory Franka URDF: 10). Factory's Screw
    /// controller acts on z and yaw only; this damping is what keeps the other axes and the arm's null space
    /// still while the hand turns. With 0.1 the hand rose along the nut's flats by ~9 mm in 2 s of turning and
    /// lost it (regression test `the_hand_screws_the_nut_down_without_climbing_it`).
    pub arm_damping: f32,
    /// Damping of joint 7, the wrist that screws [N m s/rad] (the URDF: none). At 10, as the other joints,
    /// the OSC's yaw (kp 200) turned the hand at ~0.1 rad/s, too slow to screw the nut down in an episode.
    pub wrist_damping: f32,
    /// Height of the fingertip frame (the pads' bottom edge) above the nut's bottom while holding it [m].
    /// Factory grasps with the fingertip at the nut's bottom (0, the default). At -2.3 mm the pads reached
    /// the bolt's head before the nut was seated (measured with `examples/screw_diag`, 2026-12-04).
    pub grasp_height: f32,
    /// Stiffness of the fingers' drive [N/m] (the gripper PD as an implicit joint drive; IsaacGymEnvs'
    /// Factory `gym_default` drive: gripper 500). Closed on the nut, each finger squeezes it with this x
    /// 12 mm (6 N at 500). At 2000 (24 N) the pads crept up a still nut by 7.6 mm in 500 steps and lost
    /// it while screwing (regression test `the_pads_do_not_creep_up_a_still_nut`); at 500 they stay.
    pub finger_stiffness: f32,
    /// Damping of the fingers' drive [N s/m] (IsaacGymEnvs' Factory `gym_default`: 20).
    pub finger_damping: f32,
    /// Friction of the thread.
    pub thread_mu: f32,
    /// Chamfer the bolt's tip: ISO 4753's 45-degree cone down to the minor diameter, as Factory's M16 bolt
    /// (its mesh: radius 7.98 -> 6.72 mm over the top 1.3 mm). A nut set on a flat-cut tip rested its bore's
    /// edge on the crest and slid off sideways under the hand within ~30 steps (the tip start could not be
    /// trained); on the cone it stays centred and engages as it turns (`examples/screw_diag`, 2026-12-04).
    pub bolt_tip_chamfer: bool,
    /// Thread columns per turn of the generated nut mesh.
    pub segments_per_turn: usize,
    /// Projected-gradient iterations per nut triangle in contact generation (ContactConfig::iterations;
    /// the engine's default 12).
    pub contact_descent_iters: u32,
    /// Nut triangles each contact-generation invocation takes per reduction batch
    /// (ContactConfig::candidates_per_invocation: 1, 2 or 4; default 1, the setting the Screw policy of
    /// docs/RESULTS.md was trained with). 4 runs a quarter of the reduction's rounds: a trained policy's
    /// Screw steps 1.23x faster on lavapipe, and that policy (trained at 1) seated 120 of 128 episodes at 4
    /// against 123 at 1 (docs/BENCHMARKS.md, 2026-12-05); batches in another order keep other contacts.
    pub contact_candidates_per_invocation: u32,
    /// Start the nut on the bolt's first full thread below the tip's chamfer (engaged) instead of resting
    /// on the tip (IsaacGymEnvs' Screw, the default). Factory's Screw controller acts on z and yaw only, so
    /// only the bolt holds the hand sideways: on a flat-cut tip the nut slid off it (see
    /// `bolt_tip_chamfer`); on the chamfer it is centred. The engaged start is the easier task.
    pub start_engaged: bool,
    /// Nut centre-of-mass distance from its target that ends the episode as a failure [m].
    pub far_error: f32,
    /// Reward added on the step that succeeds (Factory's Screw: 0).
    pub success_bonus: f32,
    /// Reward subtracted on the step that fails (Factory: none). With a reward that is negative every step
    /// and episodes that end on failure, ending early pays; a penalty of about the return of a long episode
    /// removes that.
    pub failure_penalty: f32,
    /// Reset randomisation (`[env.randomize]`).
    pub randomize: ScrewRandomization,
    /// Append the finger pads' contact forces on the nut [N] (6) to the observation.
    pub observe_finger_force: bool,
    /// Append the previous action (12) to the observation.
    pub observe_previous_action: bool,
    /// Where the arm, fingers, nut and bolt are solved together: "host" (solver::step_cpu_articulated),
    /// "device" (the GPU kernel, solver::articulated; lavapipe without a GPU) or "auto" (the default: the
    /// device on a hardware GPU, the host on a software adapter, where the host was the faster at 128
    /// worlds, docs/BENCHMARKS.md). Contacts are generated on the device either way.
    pub solve: CoupledSolve,
}

impl Default for FrankaNutBoltConfig {
    fn default() -> Self {
        Self {
            task: TaskName::Screw,
            dt: 1.0 / 60.0,
            // Factory's 2 substeps and 16 iterations do not hold the nut here: with zero actions the pads
            // slid up the nut and let it go within 0.7 s (measured, envs/tests/franka_screw.rs); 4 and 32 (the
            // scripted scene's settings, docs/BENCHMARKS.md) held it 10 s. Our Gauss-Seidel needs more sweeps
            // than PhysX's for the arm - pads - nut - bolt chain (issue 21's open point).
            substeps: 4,
            pos_iters: 32,
            link_patch_iters: 8,
            max_episode_steps: 8192,
            pos_action_scale: [0.1; 3],
            rot_action_scale: [0.1; 3],
            force_action_scale: [1.0; 3],
            torque_action_scale: [1.0; 3],
            unidirectional_rot: true,
            controller: ControllerConfig::from_toml_str(
                "type = \"osc\"\nkp = [1, 1, 1, 1, 1, 200]\nkd = 1\nmotion_axes = [0, 0, 1, 0, 0, 1]\n\
                 gripper_kp = 100\ngripper_kd = 1",
            )
            .expect("Factory's Screw controller config is valid"),
            arm_damping: 10.0,
            wrist_damping: 0.0,
            grasp_height: 0.0,
            finger_stiffness: 500.0,
            finger_damping: 20.0,
            thread_mu: 0.3,
            bolt_tip_chamfer: true,
            segments_per_turn: 48,
            contact_descent_iters: ContactConfig::default().iterations,
            contact_candidates_per_invocation: 1,
            far_error: 0.1,
            success_bonus: 0.0,
            failure_penalty: 0.0,
            randomize: ScrewRandomization::default(),
            start_engaged: false,
            observe_finger_force: false,
            observe_previous_action: false,
            solve: CoupledSolve::Auto,
        }
    }
}

impl FrankaNutBoltConfig {
    /// The contact settings of the scene.
    fn contact_config(&self) -> ContactConfig {
        // One split of the contact jobs for every batch size, so a world's physics (and an evaluation with
        // any `--envs`) is that of training at 128 worlds (tests/franka_screw.rs).
        ContactConfig {
            chunk_world_count: 128,
            iterations: self.contact_descent_iters,
            candidates_per_invocation: self.contact_candidates_per_invocation,
            ..ContactConfig::default()
        }
    }

    fn check(&self) -> Result<()> {
        let bad = |field: &'static str, reason: String| Err(EnvError::InvalidValue { field, reason });
        if !(self.dt.is_finite() && self.dt > 0.0) {
            return bad("dt", format!("{} is not a finite number > 0", self.dt));
        }
        if self.max_episode_steps == 0 {
            return bad("max_episode_steps", "must be at least 1".into());
        }
        for (field, v) in [
            ("arm_damping", self.arm_damping),
            ("wrist_damping", self.wrist_damping),
            ("finger_stiffness", self.finger_stiffness),
            ("finger_damping", self.finger_damping),
            ("thread_mu", self.thread_mu),
            ("far_error", self.far_error),
            ("success_bonus", self.success_bonus),
            ("failure_penalty", self.failure_penalty),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(field, format!("{v} is not a finite number >= 0"));
            }
        }
        if !(self.grasp_height.is_finite() && (-0.005..=0.01).contains(&self.grasp_height)) {
            return bad(
                "grasp_height",
                format!("{} m is not in [-0.005, 0.01] m (the pads must span the nut)", self.grasp_height),
            );
        }
        let r = &self.randomize;
        let ranges = [("randomize.hand_angle_deg", r.hand_angle_deg, 180.0)]
            .into_iter()
            .chain(r.fingertip_offset_mm.iter().map(|&x| ("randomize.fingertip_offset_mm", x, 5.0)));
        for (field, [lo, hi], limit) in ranges {
            if !(lo.is_finite() && hi.is_finite() && lo <= hi && lo >= -limit && hi <= limit) {
                return bad(field, format!("[{lo}, {hi}] must be a range lo <= hi within [-{limit}, {limit}]"));
            }
        }
        if !(1..=64).contains(&self.contact_descent_iters) {
            return bad("contact_descent_iters", format!("{} is not in 1..=64", self.contact_descent_iters));
        }
        // The engine's own rules for the contact settings, under this config's names; any other refusal
        // passes on as the engine's error, never silently.
        match self.contact_config().validate() {
            Ok(()) => {}
            Err(factory_engine::EngineError::Config { field, value, expected }) => {
                let field = match field {
                    "iterations" => "contact_descent_iters",
                    "candidates_per_invocation" => "contact_candidates_per_invocation",
                    other => other,
                };
                return bad(field, format!("{value} is not {expected}"));
            }
            Err(e) => return Err(e.into()),
        }
        if self.segments_per_turn < 8 {
            return bad("segments_per_turn", format!("{} is below 8", self.segments_per_turn));
        }
        Ok(())
    }
}

/// What a task sees of one world after a step.
#[derive(Clone, Copy, Debug)]
pub struct WorldView {
    /// Fingertip position [m], orientation, linear [m/s] and angular [rad/s] velocity.
    pub tip_pos: Vec3,
    pub tip_quat: Quat,
    pub tip_linvel: Vec3,
    pub tip_angvel: Vec3,
    /// Nut centre of mass [m], orientation, linear and angular velocity.
    pub nut_com: Vec3,
    pub nut_quat: Quat,
    pub nut_linvel: Vec3,
    pub nut_angvel: Vec3,
    /// The nut's frame position (its assembly frame: zero when seated) [m].
    pub nut_frame: Vec3,
}

/// Whether an episode ended and how.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// Still running.
    Running,
    /// Terminated in success.
    Success,
    /// Terminated in failure, and why (`far`, `slipped`, `fallen`, `diverged`).
    Failure(&'static str),
}

/// The midpoint between the finger pads' centres [m]: half a pad length up the fingers from the fingertip
/// frame (whose z points out of the hand). IsaacGymEnvs' `fingerpad_midpoint_pos` (the fingers' midpoint
/// moved `finger_length - fingerpad_length / 2` along the hand's z); its Screw reward and slip test measure
/// the nut from here. Measured from the fingertip instead, a grasp at the nut's bottom (Factory's) was
/// 7.4 mm short of the nut's centre and the reward pulled the hand up the nut (the mean action of a
/// 208-update policy lifted the nut off the bolt's tip, 2026-12-04).
pub fn pad_midpoint(tip_pos: Vec3, tip_quat: Quat) -> Vec3 {
    tip_pos + tip_quat * -Vec3::Z * (0.5 * FINGERPAD_LENGTH)
}

/// Four keypoints spaced along the segment from `p` along `axis` by [`KEYPOINT_AXIS`].
fn keypoints(p: Vec3, axis: Vec3) -> [Vec3; 4] {
    [0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0].map(|t| p + axis * (t * KEYPOINT_AXIS))
}

fn keypoint_distance(a: [Vec3; 4], b: [Vec3; 4]) -> f32 {
    a.iter().zip(&b).map(|(x, y)| x.distance(*y)).sum()
}

/// A task on the nut-and-bolt env: what an episode rewards and when it ends. One required method and
/// defaulted hooks; the env owns the scene, the actions and the resets.
pub trait NutBoltTask: Send + Sync {
    /// The task's `task = "..."` name.
    fn name(&self) -> &'static str;

    /// The reward of a step that left the world as `v` shows.
    fn reward(&self, v: &WorldView) -> f32;

    /// Whether the episode ended (success or failure) in the world `v` shows; the env adds divergence and the
    /// time limit.
    fn outcome(&self, _v: &WorldView) -> Outcome {
        Outcome::Running
    }
}

/// The Screw task's geometry (FactoryTaskNutBoltScrew).
#[derive(Clone, Debug)]
pub struct Screw {
    /// Where the nut's centre of mass is when seated [m].
    pub target: Vec3,
    /// Thread pitch [m] (the success distance).
    pub pitch: f32,
    /// Nut height [m].
    pub nut_height: f32,
    /// Bolt nominal diameter [m].
    pub bolt_diameter: f32,
    /// Height of the bolt's top [m].
    pub bolt_top: f32,
    /// Failure distance [m].
    pub far_error: f32,
}

impl NutBoltTask for Screw {
    fn name(&self) -> &'static str {
        "screw"
    }

    fn reward(&self, v: &WorldView) -> f32 {
        let nut_kp = keypoints(v.nut_com, v.nut_quat * Vec3::Z);
        let target_kp = keypoints(self.target, Vec3::Z);
        // The fingertip's z points down, out of the hand: the pads' segment rises along -z.
        let pads_kp = keypoints(pad_midpoint(v.tip_pos, v.tip_quat), v.tip_quat * -Vec3::Z);
        -(keypoint_distance(nut_kp, target_kp) + keypoint_distance(nut_kp, pads_kp))
    }

    fn outcome(&self, v: &WorldView) -> Outcome {
        let to_target = v.nut_com.distance(self.target);
        if to_target < self.pitch {
            return Outcome::Success;
        }
        let pads = pad_midpoint(v.tip_pos, v.tip_quat);
        let off_axis = Vec3::new(v.nut_com.x, v.nut_com.y, 0.0).length() > 0.5 * self.bolt_diameter;
        // Several can hold at once (a fallen nut has usually slipped too); the first named is reported.
        if off_axis && v.nut_com.z < self.bolt_top + 0.5 * self.nut_height {
            Outcome::Failure("fallen")
        } else if v.nut_com.distance(pads) > 0.5 * FINGERPAD_LENGTH + 0.5 * self.nut_height {
            Outcome::Failure("slipped")
        } else if to_target > self.far_error {
            Outcome::Failure("far")
        } else {
            Outcome::Running
        }
    }
}

/// The FrankaNutBolt env (see the module docs).
pub struct FrankaNutBolt {
    cfg: FrankaNutBoltConfig,
    spec: EnvSpec,
    gpu: &'static GpuContext,
    scene: NutBoltScene,
    controller: Box<dyn Controller>,
    task: Box<dyn NutBoltTask>,
    /// The Screw task's geometry (the device step's copy of `task`).
    screw: Screw,
    /// The nut's centre of mass in its frame [m].
    com_local: Vec3,
    /// Joint positions an unrandomised episode starts from (Factory's Screw pose, fingertip put on the nut by
    /// IK).
    reset_q: [f32; DOF],
    /// The nut's frame pose an unrandomised episode starts from.
    reset_nut: (Vec3, Quat),
    /// The fingertip's orientation at yaw 0 (pointing down, fingers closing along x).
    down: Quat,
    /// Draws of the reset randomisation.
    rng: SplitMix64,
    /// Pad-nut contact pairs (for the finger-force observation) and whether the nut is their query side.
    pad_pairs: Vec<(usize, bool)>,
    /// Control steps of each world's episode, shape [env_count].
    world_steps: Vec<u32>,
    /// Last action per world, shape [env_count * 12].
    world_prev_action: Vec<f32>,
    /// The last step's measurements.
    last_diagnostics: StepDiagnostics,
}

/// Joint positions that put the fingertip at `pos` with orientation `quat`, from `q0` (damped least squares
/// on the fingertip's geometric Jacobian; fingers kept).
fn inverse_kinematics(scene: &NutBoltScene, q0: &[f32; DOF], pos: Vec3, quat: Quat) -> [f32; DOF] {
    let mut q = *q0;
    for _ in 0..200 {
        let state = ArticulationState::replicate(&q, 1);
        let arm = ArmBatch::from_articulation(&scene.sim.articulation, &state, &scene.tip, ARM_DOF, &[]);
        let e = pose_error(pos, quat, arm.ee_pos[0], arm.ee_quat[0], JacobianKind::Geometric);
        if e.iter().map(|x| x * x).sum::<f32>().sqrt() < 1e-6 {
            break;
        }
        let j = &arm.ee_jacobian;
        let mut a = [0.0f32; 36];
        for r in 0..6 {
            for c in 0..6 {
                a[r * 6 + c] = (0..ARM_DOF).map(|k| j[r * DOF + k] * j[c * DOF + k]).sum::<f32>();
            }
            a[r * 6 + r] += 1e-4;
        }
        let mut y = e;
        linalg::solve_spd6(&a, &mut y);
        for k in 0..ARM_DOF {
            q[k] += (0..6).map(|r| j[r * DOF + k] * y[r]).sum::<f32>();
        }
    }
    q
}

impl FrankaNutBolt {
    /// `env_count` worlds; `seed` draws the reset randomisation.
    pub fn new(cfg: &FrankaNutBoltConfig, env_count: usize, seed: u64) -> Result<Self> {
        cfg.check()?;
        let gpu = GpuContext::global()?;
        let solver = SolverConfig {
            dt: cfg.dt,
            substeps: cfg.substeps,
            pos_iters: cfg.pos_iters,
            vel_iters: 0,
            link_patch_iters: cfg.link_patch_iters,
            ..Default::default()
        };
        let scene_cfg = SceneConfig {
            worlds: env_count as u32,
            solver,
            contact: cfg.contact_config(),
            segments_per_turn: cfg.segments_per_turn,
            thread_mu: cfg.thread_mu,
            base: BASE,
            arm_damping: std::array::from_fn(|d| if d + 1 == ARM_DOF { cfg.wrist_damping } else { cfg.arm_damping }),
            finger_drive: [cfg.finger_stiffness, cfg.finger_damping],
            bolt_tip_chamfer: cfg.bolt_tip_chamfer,
        };
        let mut scene = NutBoltScene::build(
            gpu,
            &scene_cfg,
            |_, _| (Vec3::ZERO, Quat::IDENTITY),
            ArticulationState::replicate(&Q_START, env_count),
        )?;
        let controller = build(&cfg.controller, DOF, ARM_DOF)?;
        let d = scene.nb.dims;
        let (head, shank, nut_h) = (d.head_height as f32, d.shank_length as f32, d.nut_height as f32);
        // The nut on the bolt's first full thread: the highest whole number of pitches above its seat that
        // is not above the tip or in its chamfer (the thread maps onto itself under a one-pitch translation,
        // so the nut fits there at yaw 0, flats normal to x: the fingers close along x at yaw 0).
        let pitch = scene.nb.pitch;
        let chamfer = match scene.nb.bolt_tip_radius {
            Some(_) => factory_assets::bolt_tip_chamfer_height(&scene.nb.spec) as f32,
            None => 0.0,
        };
        let start_z = if cfg.start_engaged { ((shank - chamfer) / pitch + 1e-4).floor() * pitch } else { shank };
        let reset_nut = (Vec3::Z * start_z, Quat::IDENTITY);
        // Factory's Screw pose, its fingertip moved onto the nut by IK: pointing down (Q_START's orientation
        // without its yaw), fingers just open around the flats.
        let arm0 = ArmBatch::from_articulation(
            &scene.sim.articulation,
            &ArticulationState::replicate(&Q_START, 1),
            &scene.tip,
            ARM_DOF,
            &[],
        );
        let y = arm0.ee_quat[0] * Vec3::Y;
        let down = Quat::from_rotation_z(-y.y.atan2(y.x)) * arm0.ee_quat[0];
        let mut q = Q_START;
        let half_width = 0.5 * d.width_across_flats as f32;
        q[ARM_DOF] = half_width + 2e-4;
        q[ARM_DOF + 1] = half_width + 2e-4;
        let reset_q = inverse_kinematics(&scene, &q, Vec3::new(0.0, 0.0, head + start_z + cfg.grasp_height), down);
        let com_local = scene.nb.nut.mass_properties.com;
        // The task registry: one entry per `task` name.
        let screw = Screw {
            target: com_local,
            pitch: scene.nb.pitch,
            nut_height: nut_h,
            bolt_diameter: scene.nb.spec.nominal_diameter as f32,
            bolt_top: head + shank,
            far_error: cfg.far_error,
        };
        let task: Box<dyn NutBoltTask> = match cfg.task {
            TaskName::Screw => Box::new(screw.clone()),
        };
        let nut = scene.nut as u32;
        let pad_pairs = scene
            .sim
            .model
            .contacts
            .pairs
            .iter()
            .enumerate()
            .filter_map(|(i, p)| {
                let other = if p.body_a == nut {
                    p.body_b
                } else if p.body_b == nut {
                    p.body_a
                } else {
                    return None;
                };
                let is_link = scene.sim.model.bodies.link(other as usize).is_some();
                is_link.then_some((i, p.body_a == nut))
            })
            .collect::<Vec<_>>();
        if pad_pairs.len() != 2 {
            return Err(EnvError::Build(format!("expected 2 pad-nut contact pairs, found {}", pad_pairs.len())));
        }
        for w in 0..env_count {
            scene.reset_world(gpu, w, reset_nut, &reset_q);
        }
        scene.sim.sync_links();
        scene.sim.solve_on(gpu, cfg.solve)?;
        let mut names: Vec<String> = Vec::new();
        for body in ["fingertip", "nut"] {
            for (what, axes) in [("pos_m", "xyz"), ("quat", "xyzw"), ("linvel_m_s", "xyz"), ("angvel_rad_s", "xyz")] {
                for a in axes.chars() {
                    names.push(format!("{body}_{what}_{a}"));
                }
            }
        }
        if cfg.observe_finger_force {
            for f in ["left", "right"] {
                for a in "xyz".chars() {
                    names.push(format!("{f}_finger_force_n_{a}"));
                }
            }
        }
        let action_names: Vec<String> = ["dpos_x", "dpos_y", "dpos_z", "drot_x", "drot_y", "drot_z"]
            .into_iter()
            .chain(["force_x", "force_y", "force_z", "torque_x", "torque_y", "torque_z"])
            .map(String::from)
            .collect();
        if cfg.observe_previous_action {
            names.extend(action_names.iter().map(|a| format!("prev_{a}")));
        }
        let spec = EnvSpec {
            name: "franka_nut_bolt".into(),
            env_count,
            observation_names: names,
            action_names,
            max_episode_steps: cfg.max_episode_steps,
        };
        Ok(Self {
            cfg: cfg.clone(),
            spec,
            gpu,
            scene,
            controller,
            task,
            screw,
            com_local,
            reset_q,
            reset_nut,
            down,
            rng: SplitMix64(seed),
            pad_pairs,
            world_steps: vec![0; env_count],
            world_prev_action: vec![0.0; env_count * 12],
            last_diagnostics: StepDiagnostics::default(),
        })
    }

    /// The scene (for tests and benchmarks).
    pub fn scene(&self) -> &NutBoltScene {
        &self.scene
    }

    /// The scene, mutable (diagnostics and scripted starts; the env's episode counters do not see changes).
    pub fn scene_mut(&mut self) -> &mut NutBoltScene {
        &mut self.scene
    }

    fn views(&self, arm: &ArmBatch) -> Vec<WorldView> {
        (0..self.spec.env_count)
            .map(|w| {
                let (p, q) = self.scene.nut_pose(w);
                let [v, omega] = self.scene.nut_velocity(w);
                WorldView {
                    tip_pos: arm.ee_pos[w],
                    tip_quat: arm.ee_quat[w],
                    tip_linvel: arm.ee_linvel[w],
                    tip_angvel: arm.ee_angvel[w],
                    nut_com: p + q * self.com_local,
                    nut_quat: q,
                    nut_linvel: v,
                    nut_angvel: omega,
                    nut_frame: p,
                }
            })
            .collect()
    }

    fn observe(&self, arm: &ArmBatch, out: &mut [f32]) {
        // The pads' forces on the nut, every world at once (one readback where the device solves).
        let pads = [self.pad_pairs[0].0, self.pad_pairs[1].0];
        let pad_forces =
            if self.cfg.observe_finger_force { self.scene.sim.pair_forces(self.gpu, &pads) } else { Vec::new() };
        let d = self.spec.observation_dim();
        for (w, v) in self.views(arm).iter().enumerate() {
            let o = &mut out[w * d..(w + 1) * d];
            let mut k = 0;
            let mut put = |x: &[f32]| {
                o[k..k + x.len()].copy_from_slice(x);
                k += x.len();
            };
            put(&v.tip_pos.to_array());
            put(&v.tip_quat.to_array());
            put(&v.tip_linvel.to_array());
            put(&v.tip_angvel.to_array());
            put(&v.nut_com.to_array());
            put(&v.nut_quat.to_array());
            put(&v.nut_linvel.to_array());
            put(&v.nut_angvel.to_array());
            if self.cfg.observe_finger_force {
                for (k, &(_, nut_is_query)) in self.pad_pairs.iter().enumerate() {
                    let f = pad_forces[w * pads.len() + k];
                    put(&(if nut_is_query { f } else { -f }).to_array());
                }
            }
            if self.cfg.observe_previous_action {
                put(&self.world_prev_action[w * 12..(w + 1) * 12]);
            }
        }
    }

    /// The config.
    pub fn config(&self) -> &FrankaNutBoltConfig {
        &self.cfg
    }

    /// The controller.
    pub fn controller(&self) -> &dyn Controller {
        self.controller.as_ref()
    }

    /// The Screw task's geometry.
    pub fn screw(&self) -> &Screw {
        &self.screw
    }

    /// The pads' contact pairs with the nut (left, right) and whether the nut is each pair's query side.
    pub fn pad_pairs(&self) -> &[(usize, bool)] {
        &self.pad_pairs
    }

    /// The nut's centre of mass in its frame [m].
    pub fn nut_com_local(&self) -> Vec3 {
        self.com_local
    }

    /// Resets world `w` to a new episode's start, drawing the randomisation (the host state; the link bodies
    /// follow at the next [`ArticulatedSim::sync_links`](factory_engine::articulation::sim::ArticulatedSim::sync_links)).
    pub fn reset_world(&mut self, w: usize) {
        let r = self.cfg.randomize.clone();
        let mut draw = |[lo, hi]: [f32; 2]| if hi > lo { lo + (hi - lo) * self.rng.unit() } else { lo };
        let angle = draw(r.hand_angle_deg).to_radians();
        let o =
            Vec3::new(draw(r.fingertip_offset_mm[0]), draw(r.fingertip_offset_mm[1]), draw(r.fingertip_offset_mm[2]))
                * 1e-3;
        if angle == 0.0 && o == Vec3::ZERO {
            self.scene.reset_world(self.gpu, w, self.reset_nut, &self.reset_q);
            return;
        }
        let turn = Quat::from_rotation_z(angle);
        // On the helix: turning counterclockwise by `angle` raises a right-hand nut by pitch * angle / 2 pi.
        let nut_p = self.reset_nut.0 + Vec3::Z * (self.scene.nb.pitch * angle / std::f32::consts::TAU);
        let head = self.scene.nb.dims.head_height as f32;
        let grasp = Vec3::new(0.0, 0.0, head + nut_p.z + self.cfg.grasp_height);
        let tip = grasp + turn * Vec3::new(o.x, o.y, 0.0) + Vec3::Z * o.z;
        let mut q = inverse_kinematics(&self.scene, &self.reset_q, tip, turn * self.down);
        // The fingers close along the nut's x: the left one (+y of the hand) to the flat at -o.x + w/2.
        let half_width = 0.5 * self.scene.nb.dims.width_across_flats as f32;
        q[ARM_DOF] = half_width - o.x + 2e-4;
        q[ARM_DOF + 1] = half_width + o.x + 2e-4;
        self.scene.reset_world(self.gpu, w, (nut_p, turn * self.reset_nut.1), &q);
    }

    /// Records the step's torque norms and contact forces (before any reset clears a world's warm start).
    fn measure(&mut self, joint_tau: &[f32]) {
        let n = self.spec.env_count;
        let sim = &self.scene.sim;
        let torque = (0..n).map(|w| joint_tau[w * DOF..w * DOF + ARM_DOF].iter().map(|t| t * t).sum::<f32>().sqrt());
        let mut on_nut = vec![Vec3::ZERO; n];
        let mut forces = Vec::new();
        // Both pads' pairs and the thread's, every world at once (one readback where the device solves).
        let pairs = [self.pad_pairs[0].0, self.pad_pairs[1].0, self.scene.thread_pair];
        let all = sim.pair_forces(self.gpu, &pairs);
        for (k, (name, &(_, nut_is_query))) in ["left_finger", "right_finger"].iter().zip(&self.pad_pairs).enumerate() {
            let f: Vec<Vec3> = (0..n).map(|w| all[w * 3 + k] * if nut_is_query { 1.0 } else { -1.0 }).collect();
            for w in 0..n {
                on_nut[w] += f[w];
            }
            forces.push((name.to_string(), f.iter().map(|x| x.length()).collect()));
        }
        // The thread pair's query shape is the nut: the force on it from the bolt.
        let bolt: Vec<Vec3> = (0..n).map(|w| all[w * 3 + 2]).collect();
        for w in 0..n {
            on_nut[w] += bolt[w];
        }
        forces.push(("bolt".into(), bolt.iter().map(|x| x.length()).collect()));
        forces.push(("nut".into(), on_nut.iter().map(|x| x.length()).collect()));
        self.last_diagnostics = StepDiagnostics { joint_torque_norm: torque.collect(), contact_force_norms: forces };
    }
}

/// The controller's targets for every world's action (shape [world_count * 12], clipped to [-1, 1]): the
/// module docs' mapping, relative to the fingertip pose in `arm`; the fingers' targets closed (their drives
/// squeeze the nut). The device twin is [`super::action_gpu::ActionGpu`].
pub fn action_targets(c: &FrankaNutBoltConfig, arm: &ArmBatch, action: &[f32]) -> Targets {
    let mut t = Targets::hold(arm);
    for w in 0..arm.world_count {
        let a: Vec<f32> = action[w * 12..(w + 1) * 12].iter().map(|x| x.clamp(-1.0, 1.0)).collect();
        let dp = Vec3::new(a[0], a[1], a[2]) * Vec3::from_array(c.pos_action_scale);
        let yaw = if c.unidirectional_rot { -(a[5] + 1.0) * 0.5 } else { a[5] };
        let dr = Vec3::new(a[3], a[4], yaw) * Vec3::from_array(c.rot_action_scale);
        t.ee_pos[w] = arm.ee_pos[w] + dp;
        let angle = dr.length();
        t.ee_quat[w] =
            if angle > 1e-6 { Quat::from_axis_angle(dr / angle, angle) * arm.ee_quat[w] } else { arm.ee_quat[w] };
        for k in 0..3 {
            t.ee_wrench[w][k] = a[6 + k] * c.force_action_scale[k];
            t.ee_wrench[w][3 + k] = a[9 + k] * c.torque_action_scale[k];
        }
        // The gripper stays closed (its drives squeeze the nut).
        t.gripper_q[w * 2] = 0.0;
        t.gripper_q[w * 2 + 1] = 0.0;
    }
    t
}

impl Env for FrankaNutBolt {
    fn spec(&self) -> &EnvSpec {
        &self.spec
    }

    fn reset(&mut self, out: &mut StepBuffers) {
        for w in 0..self.spec.env_count {
            self.reset_world(w);
            self.world_steps[w] = 0;
        }
        self.world_prev_action.fill(0.0);
        self.scene.sim.sync_links();
        out.reward.fill(0.0);
        out.terminated.fill(0.0);
        out.truncated.fill(0.0);
        out.success.fill(0.0);
        let arm = self.scene.arm();
        self.observe(&arm, &mut out.observation);
    }

    fn diagnostics(&self) -> Option<StepDiagnostics> {
        Some(self.last_diagnostics.clone())
    }

    fn set_episode_steps(&mut self, steps: &[u32]) -> Result<()> {
        crate::env::check_episode_steps(&self.spec, steps)?;
        self.world_steps.copy_from_slice(steps);
        Ok(())
    }

    fn save_state(&self) -> Option<Vec<u8>> {
        let sim = &self.scene.sim;
        // The device solve keeps its warm-start rows on the device, which these bytes do not hold: a resumed
        // run starts fresh episodes rather than one that continues almost, not exactly.
        if sim.on_device() {
            return None;
        }
        let qd: Vec<f32> = sim.state.body_qd.iter().flat_map(|[v, w]| [v.x, v.y, v.z, w.x, w.y, w.z]).collect();
        let sections: [Vec<u8>; 8] = [
            bytemuck::cast_slice(&sim.state.body_q).to_vec(),
            bytemuck::cast_slice(&qd).to_vec(),
            bytemuck::cast_slice(&sim.joints.joint_q).to_vec(),
            bytemuck::cast_slice(&sim.joints.joint_qd).to_vec(),
            bytemuck::cast_slice(&self.world_steps).to_vec(),
            bytemuck::cast_slice(&self.world_prev_action).to_vec(),
            sim.warm.to_bytes(),
            self.rng.0.to_le_bytes().to_vec(),
        ];
        let mut b = Vec::new();
        crate::env::frame_sections(&mut b, &sections.each_ref().map(|s| s.as_slice()));
        Some(b)
    }

    fn load_state(&mut self, bytes: &[u8]) -> Result<()> {
        let bad =
            |reason: &str| EnvError::InvalidValue { field: "state", reason: format!("franka_nut_bolt: {reason}") };
        let (sections, _) = crate::env::split_sections(bytes, 8).ok_or_else(|| bad("truncated"))?;
        let sim = &mut self.scene.sim;
        let f32s =
            |b: &[u8]| -> Vec<f32> { b.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect() };
        let want = [
            sim.state.body_q.len() * 32,
            sim.state.body_qd.len() * 24,
            sim.joints.joint_q.len() * 4,
            sim.joints.joint_qd.len() * 4,
            self.world_steps.len() * 4,
            self.world_prev_action.len() * 4,
        ];
        if sections[..6].iter().zip(want).any(|(s, w)| s.len() != w) || sections[7].len() != 8 {
            return Err(bad("saved for another number of worlds or bodies"));
        }
        let warm = factory_engine::solver::WarmStart::from_bytes(sections[6]).ok_or_else(|| bad("warm start"))?;
        let q = f32s(sections[0]);
        for (t, c) in sim.state.body_q.iter_mut().zip(q.chunks_exact(8)) {
            t.p.copy_from_slice(&c[..4]);
            t.q.copy_from_slice(&c[4..]);
        }
        let qd = f32s(sections[1]);
        for (v, c) in sim.state.body_qd.iter_mut().zip(qd.chunks_exact(6)) {
            *v = [Vec3::new(c[0], c[1], c[2]), Vec3::new(c[3], c[4], c[5])];
        }
        sim.joints.joint_q = f32s(sections[2]);
        sim.joints.joint_qd = f32s(sections[3]);
        self.world_steps = sections[4].chunks_exact(4).map(|c| u32::from_le_bytes(c.try_into().unwrap())).collect();
        self.world_prev_action = f32s(sections[5]);
        sim.warm = warm;
        self.rng.0 = u64::from_le_bytes(sections[7].try_into().unwrap());
        Ok(())
    }

    fn step(&mut self, action: &[f32], out: &mut StepBuffers) {
        let n = self.spec.env_count;
        let arm = self.scene.arm();
        let targets = action_targets(&self.cfg, &arm, action);
        let mut tau = vec![0.0f32; n * DOF];
        self.controller.compute(&arm, &targets, &mut tau);
        let mut control = ArticulationControl { joint_tau: tau, joint_target_q: self.scene.sim.joints.joint_q.clone() };
        for w in 0..n {
            // The fingers follow the gripper target through their drives; the arm joints have no drive.
            for f in 0..2 {
                control.joint_tau[w * DOF + ARM_DOF + f] = 0.0;
                control.joint_target_q[w * DOF + ARM_DOF + f] = targets.gripper_q[w * 2 + f];
            }
        }
        let diverged = self.scene.sim.step(self.gpu, &Control::default(), &control);
        self.measure(&control.joint_tau);
        for w in 0..n {
            for k in 0..12 {
                self.world_prev_action[w * 12 + k] = action[w * 12 + k].clamp(-1.0, 1.0);
            }
        }
        let arm = self.scene.arm();
        let views = self.views(&arm);
        let mut any_reset = false;
        for (w, v) in views.iter().enumerate() {
            self.world_steps[w] += 1;
            let outcome = if diverged[w] { Outcome::Failure("diverged") } else { self.task.outcome(v) };
            let reward = if diverged[w] { 0.0 } else { self.task.reward(v) }
                + match outcome {
                    Outcome::Success => self.cfg.success_bonus,
                    Outcome::Failure(_) => -self.cfg.failure_penalty,
                    Outcome::Running => 0.0,
                };
            let timed_out = outcome == Outcome::Running && self.world_steps[w] >= self.cfg.max_episode_steps;
            out.reward[w] = reward;
            out.terminated[w] = (outcome != Outcome::Running) as u8 as f32;
            out.truncated[w] = timed_out as u8 as f32;
            out.success[w] = (outcome == Outcome::Success) as u8 as f32;
            out.failure[w] = match outcome {
                Outcome::Failure(cause) => Some(cause),
                _ => None,
            };
            if outcome != Outcome::Running || timed_out {
                self.reset_world(w);
                self.world_steps[w] = 0;
                self.world_prev_action[w * 12..(w + 1) * 12].fill(0.0);
                any_reset = true;
            }
        }
        let arm = if any_reset {
            self.scene.sim.sync_links();
            self.scene.arm()
        } else {
            arm
        };
        self.observe(&arm, &mut out.observation);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Regression: the Screw reward and slip test measured the nut from the fingertip, not from the pads'
    /// midpoint (IsaacGymEnvs), so a grasp at the nut's bottom was rewarded for sliding the hand up.
    #[test]
    fn the_screw_reward_and_slip_test_measure_the_nut_from_the_pads_midpoint() {
        let nut_height = 0.0148;
        let task = Screw {
            target: Vec3::new(0.0, 0.0, 0.02),
            pitch: 0.002,
            nut_height,
            bolt_diameter: 0.016,
            bolt_top: 0.05,
            far_error: 0.1,
        };
        // The hand points down: the fingertip frame's z is the world's -z.
        let tip_quat = Quat::from_rotation_x(std::f32::consts::PI);
        let view = |tip: Vec3| WorldView {
            tip_pos: tip,
            tip_quat,
            tip_linvel: Vec3::ZERO,
            tip_angvel: Vec3::ZERO,
            nut_com: task.target,
            nut_quat: Quat::IDENTITY,
            nut_linvel: Vec3::ZERO,
            nut_angvel: Vec3::ZERO,
            nut_frame: Vec3::ZERO,
        };
        let half_pad = 0.5 * FINGERPAD_LENGTH;
        // The pads' centres level with the nut's centre of mass, which is at its target: no distance left.
        let level = task.target - Vec3::Z * half_pad;
        assert!((pad_midpoint(level, tip_quat) - task.target).length() < 1e-7);
        assert!(task.reward(&view(level)).abs() < 1e-6, "{}", task.reward(&view(level)));
        // The fingertip at the nut's centre puts the pads half a pad above it: 4 keypoints x half a pad.
        let r = task.reward(&view(task.target));
        assert!((r + 4.0 * half_pad).abs() < 1e-6, "{r}");
        // Slip: the nut's centre farther than half a pad plus half the nut from the pads' midpoint (the
        // nut 5 cm above its target: neither seated nor far).
        let limit = half_pad + 0.5 * nut_height;
        let above = Screw { target: task.target - Vec3::Z * 0.05, ..task.clone() };
        let at = |d: f32| above.outcome(&view(level + Vec3::Z * d));
        assert_eq!(at(limit - 1e-4), Outcome::Running);
        assert_eq!(at(limit + 1e-4), Outcome::Failure("slipped"));
        assert_eq!(at(-(limit - 1e-4)), Outcome::Running);
    }

    /// Bad config values are refused naming the field and the valid range, before any scene is built.
    #[test]
    fn bad_config_values_name_their_field() {
        let cases = [
            (FrankaNutBoltConfig { contact_descent_iters: 0, ..Default::default() }, "contact_descent_iters", "1..=64"),
            (FrankaNutBoltConfig { grasp_height: 0.02, ..Default::default() }, "grasp_height", "[-0.005, 0.01]"),
            (FrankaNutBoltConfig { segments_per_turn: 4, ..Default::default() }, "segments_per_turn", "below 8"),
            (
                FrankaNutBoltConfig { contact_candidates_per_invocation: 3, ..Default::default() },
                "contact_candidates_per_invocation",
                "1, 2 or 4",
            ),
        ];
        for (cfg, field, valid) in cases {
            let e = cfg.check().unwrap_err().to_string();
            assert!(e.contains(field) && e.contains(valid), "{e}");
        }
        assert!(FrankaNutBoltConfig::default().check().is_ok());
    }

    /// Each failure is reported by its cause: off the axis below the bolt's top is `fallen` (whether or not the
    /// pads still hold it), more than `far_error` from the target with the pads on the nut is `far`.
    #[test]
    fn screw_failures_name_their_cause() {
        let task = Screw {
            target: Vec3::ZERO,
            pitch: 0.002,
            nut_height: 0.0148,
            bolt_diameter: 0.016,
            bolt_top: 0.05,
            far_error: 0.1,
        };
        let tip_quat = Quat::from_rotation_x(std::f32::consts::PI);
        let view = |nut: Vec3| WorldView {
            // The pads' midpoint on the nut's centre of mass.
            tip_pos: nut - Vec3::Z * (0.5 * FINGERPAD_LENGTH),
            tip_quat,
            tip_linvel: Vec3::ZERO,
            tip_angvel: Vec3::ZERO,
            nut_com: nut,
            nut_quat: Quat::IDENTITY,
            nut_linvel: Vec3::ZERO,
            nut_angvel: Vec3::ZERO,
            nut_frame: Vec3::ZERO,
        };
        assert_eq!(task.outcome(&view(Vec3::new(0.0, 0.0, 0.03))), Outcome::Running);
        assert_eq!(task.outcome(&view(Vec3::new(0.0, 0.0, 0.0015))), Outcome::Success);
        assert_eq!(task.outcome(&view(Vec3::new(0.02, 0.0, 0.03))), Outcome::Failure("fallen"));
        assert_eq!(task.outcome(&view(Vec3::new(0.0, 0.0, 0.11))), Outcome::Failure("far"));
    }
}

//! The `franka_nut_bolt` env's configuration ([`FrankaNutBoltConfig`], `[env]` in TOML) and its checks.

use factory_controllers::ControllerConfig;
use factory_engine::contact::ContactConfig;
use factory_engine::sim::CoupledSolve;
use serde::{Deserialize, Serialize};

use crate::error::{EnvError, Result};
use crate::franka::scene::{screw_solver, ContactMaterials};

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
    /// Fingertip offset from the nut's grasp point [mm], in the hand's frame after the turn: x along the
    /// fingers' closing axis (each finger closes to its side of the nut), y along the flats, z up (Table
    /// III: [-3, 3], [-3, 3], [0, 3]). An x offset grips the nut off-centre, which needs `balanced_grip`:
    /// the two finger drives pulling each to 0 (Factory's) squeeze an off-centre nut unequally and push it
    /// further off (a world drawn with 0.3 mm lost the nut within 21 steps of zero actions).
    pub fingertip_offset_mm: [[f32; 2]; 3],
    /// The nut's offset in the closed hand [mm]: y along the pads' width (Table III's nut-in-gripper x:
    /// [-3.5, 3.5]) and z up the fingers (Table III's nut-in-gripper z: [-6.5, 1.0], read with z up, so a
    /// nut up to 6.5 mm further out of the fingers; read with the fingertip frame's z, out of the hand, the
    /// fingertips would sit up to 6.5 mm below the nut and reach the bolt's head before the nut seats, as
    /// they do from 2.3 mm: see `grasp_height`). The nut stays on the bolt's axis, so the hand moves by the
    /// opposite offset (added to `fingertip_offset_mm`).
    pub nut_in_gripper_mm: [[f32; 2]; 2],
    /// The nut turned in the hand about its axis [deg] (Table III's nut-in-gripper yaw: [-15, 15]): the
    /// fingers close on the hexagon turned by this angle, wider than across its flats (by 11.5% at 15 deg),
    /// touching it near two opposite corners.
    pub nut_in_gripper_yaw_deg: [f32; 2],
    /// A calibration file of stable starts (`factory-calibrate`, FrankaCalibrate of the paper's App. D3) to
    /// draw every reset from, uniformly, in place of the ranges above; refused when it was made for other
    /// physics or other ranges (each differing key named with both values).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub starts_file: Option<String>,
}

impl ScrewRandomization {
    /// The paper's Table III ranges for Screw, every one of the seven drawn.
    pub fn table_iii() -> Self {
        Self {
            hand_angle_deg: [-90.0, 90.0],
            fingertip_offset_mm: [[-3.0, 3.0], [-3.0, 3.0], [0.0, 3.0]],
            nut_in_gripper_mm: [[-3.5, 3.5], [-6.5, 1.0]],
            nut_in_gripper_yaw_deg: [-15.0, 15.0],
            starts_file: None,
        }
    }
}

impl Default for ScrewRandomization {
    fn default() -> Self {
        Self {
            hand_angle_deg: [0.0; 2],
            fingertip_offset_mm: [[0.0; 2]; 3],
            nut_in_gripper_mm: [[0.0; 2]; 2],
            nut_in_gripper_yaw_deg: [0.0; 2],
            starts_file: None,
        }
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
    /// Solver substeps per control step (Factory's tasks: 2; default 4, see `scene::screw_solver`).
    pub substeps: u32,
    /// Gauss-Seidel position iterations per substep (Factory's tasks: 16; default 32, see `scene::screw_solver`).
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
    /// Factory grasps with the fingertip at the nut's bottom (0, the default). At -2.3 mm the pads reach
    /// the bolt's head before the nut is seated (measured with `examples/screw_diag`).
    pub grasp_height: f32,
    /// Stiffness of the fingers' drive [N/m] (the gripper PD as an implicit joint drive; IsaacGymEnvs'
    /// Factory `gym_default` drive: gripper 500). Closed on the nut, each finger squeezes it with this x
    /// 12 mm (6 N at 500). At 2000 (24 N) the pads crept up a still nut by 7.6 mm in 500 steps and lost
    /// it while screwing (regression test `the_pads_do_not_creep_up_a_still_nut`); at 500 they stay.
    pub finger_stiffness: f32,
    /// Damping of the fingers' drive [N s/m] (IsaacGymEnvs' Factory `gym_default`: 20).
    pub finger_damping: f32,
    /// Both fingers squeeze with the same force, their drives' mean (a Franka hand's fingers are coupled):
    /// each step each finger's drive target is set to its own opening minus the two fingers' mean opening
    /// (plus the gripper target). Off (Factory's independent drives, each pulling to its target), an
    /// off-centre nut is squeezed harder from the farther finger and pushed further off; on, a nut is held
    /// wherever the fingers close on it. On a centred nut the two agree.
    pub balanced_grip: bool,
    /// Contact materials (`[env.materials]`): the friction of the nut, bolt, finger pads and table, and the
    /// rule that combines a pair's two (defaults: Factory's, which give nut-bolt 0.3, nut-table 0.3,
    /// nut-pad 0.65, pad-table 0.65).
    pub materials: ContactMaterials,
    /// The thread pair's Coulomb friction coefficient in place of the materials' nut-bolt combination
    /// (unset: combined, 0.3 at the default materials); the other pairs keep theirs.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub thread_mu: Option<f32>,
    /// Chamfer the bolt's tip: ISO 4753's 45-degree cone down to the minor diameter, as Factory's M16 bolt
    /// (its mesh: radius 7.98 -> 6.72 mm over the top 1.3 mm). A nut set on a flat-cut tip rests its bore's
    /// edge on the crest and slides off sideways under the hand within ~30 steps (the tip start cannot be
    /// trained); on the cone it stays centred and engages as it turns (`examples/screw_diag`).
    pub bolt_tip_chamfer: bool,
    /// Thread columns per turn of the generated nut mesh.
    pub segments_per_turn: usize,
    /// Projected-gradient iterations per nut triangle in contact generation (ContactConfig::iterations;
    /// the engine's default 12). At 4, with 4 candidates per invocation in workgroups of 32, the Screw env's
    /// contact handling takes about half the time on lavapipe, but the frozen policy of docs/BENCHMARKS.md
    /// ("Training pace") loses more nuts from the hand.
    pub contact_descent_iters: u32,
    /// Nut triangles each contact-generation invocation takes per reduction batch
    /// (ContactConfig::candidates_per_invocation: 1, 2 or 4; default 1). 4 runs a quarter of the
    /// reduction's rounds, faster on lavapipe, but batches in another order keep other contacts: at 4 the
    /// frozen policy of docs/BENCHMARKS.md ("Training pace") seats 62 of 128 episodes against 113 (its nut
    /// slips in the hand more often).
    pub contact_candidates_per_invocation: u32,
    /// Invocations per contact-generation workgroup (ContactConfig::workgroup_size: 32, 64, 128 or 256, at
    /// most 256 candidates a batch with `contact_candidates_per_invocation`; default 64).
    pub contact_workgroup_size: u32,
    /// Start the nut on the bolt's first full thread below the tip's chamfer (engaged) instead of resting
    /// on the tip (IsaacGymEnvs' Screw, the default). Factory's Screw controller acts on z and yaw only, so
    /// only the bolt holds the hand sideways: on a flat-cut tip the nut slid off it (see
    /// `bolt_tip_chamfer`); on the chamfer it is centred. The engaged start is the easier task.
    pub start_engaged: bool,
    /// Whole turns (thread pitches) the nut starts below the first full thread, with `start_engaged`: the
    /// deeper starts of the whole-run training benchmark (scripts/bench_training.sh), so each phase of a
    /// Screw episode can be timed on its own. At most the turns that leave two pitches above the seat.
    pub start_turns_down: u32,
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
        // The Franka scenes' solver (scene::screw_solver: dt 1/60 s, 4 substeps x 32 iterations, not
        // Factory's 2 x 16) and the engine's contact settings.
        let (solver, contact) = (screw_solver(), ContactConfig::default());
        Self {
            task: TaskName::Screw,
            dt: solver.dt,
            substeps: solver.substeps,
            pos_iters: solver.pos_iters,
            link_patch_iters: solver.link_patch_iters,
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
            balanced_grip: false,
            materials: ContactMaterials::default(),
            thread_mu: None,
            bolt_tip_chamfer: true,
            segments_per_turn: 48,
            contact_descent_iters: contact.iterations,
            contact_candidates_per_invocation: contact.candidates_per_invocation,
            contact_workgroup_size: contact.workgroup_size,
            far_error: 0.1,
            success_bonus: 0.0,
            failure_penalty: 0.0,
            randomize: ScrewRandomization::default(),
            start_engaged: false,
            start_turns_down: 0,
            observe_finger_force: false,
            observe_previous_action: false,
            solve: CoupledSolve::Auto,
        }
    }
}

impl FrankaNutBoltConfig {
    /// The contact settings of the scene.
    pub(super) fn contact_config(&self) -> ContactConfig {
        // One split of the contact jobs for every batch size, so a world's physics (and an evaluation with
        // any `--envs`) is that of training at 128 worlds (tests/franka_screw.rs).
        ContactConfig {
            chunk_world_count: 128,
            iterations: self.contact_descent_iters,
            candidates_per_invocation: self.contact_candidates_per_invocation,
            workgroup_size: self.contact_workgroup_size,
            ..ContactConfig::default()
        }
    }

    pub(super) fn check(&self) -> Result<()> {
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
            ("far_error", self.far_error),
            ("success_bonus", self.success_bonus),
            ("failure_penalty", self.failure_penalty),
        ]
        .into_iter()
        .chain(self.materials.coefficients())
        .chain(self.thread_mu.map(|mu| ("thread_mu", mu)))
        {
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
        let ranges = [
            ("randomize.hand_angle_deg", r.hand_angle_deg, 180.0),
            ("randomize.nut_in_gripper_yaw_deg", r.nut_in_gripper_yaw_deg, 30.0),
        ]
        .into_iter()
        .chain(r.fingertip_offset_mm.iter().map(|&x| ("randomize.fingertip_offset_mm", x, 5.0)))
        .chain(r.nut_in_gripper_mm.iter().map(|&x| ("randomize.nut_in_gripper_mm", x, 8.0)));
        for (field, [lo, hi], limit) in ranges {
            if !(lo.is_finite() && hi.is_finite() && lo <= hi && lo >= -limit && hi <= limit) {
                return bad(field, format!("[{lo}, {hi}] must be a range lo <= hi within [-{limit}, {limit}]"));
            }
        }
        if r.fingertip_offset_mm[0] != [0.0, 0.0] && !self.balanced_grip {
            return bad(
                "randomize.fingertip_offset_mm",
                format!(
                    "an offset along the closing axis ({:?} mm) needs balanced_grip = true: independent finger \
                     drives push an off-centre nut further off",
                    r.fingertip_offset_mm[0]
                ),
            );
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
                    "workgroup_size" => "contact_workgroup_size",
                    other => other,
                };
                return bad(field, format!("{value} is not {expected}"));
            }
            Err(e) => return Err(e.into()),
        }
        if self.start_turns_down > 0 && !self.start_engaged {
            return bad(
                "start_turns_down",
                format!(
                    "{} needs start_engaged = true (the turns count down from the first full thread)",
                    self.start_turns_down
                ),
            );
        }
        if self.segments_per_turn < 8 {
            return bad("segments_per_turn", format!("{} is below 8", self.segments_per_turn));
        }
        Ok(())
    }
}

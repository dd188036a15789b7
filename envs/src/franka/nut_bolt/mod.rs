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
use factory_controllers::{build, linalg, ArmBatch, Controller, Targets};
use factory_engine::articulation::{ArticulationControl, ArticulationState};
use factory_engine::gpu::GpuContext;
use factory_engine::rng::SplitMix64;
use factory_engine::solver::{Control, SolverConfig};
use glam::{Quat, Vec3};

use super::scene::{NutBoltScene, SceneConfig, ARM_DOF, BASE, DOF, Q_START};
use crate::env::{Env, EnvProfile, EnvSpec, StepBuffers, StepDiagnostics};
use crate::error::{EnvError, Result};

pub mod calibrate;
mod config;
mod task;

pub use config::{FrankaNutBoltConfig, ScrewRandomization, TaskName};
pub use task::{pad_midpoint, NutBoltTask, Outcome, Screw, WorldView, FINGERPAD_LENGTH, KEYPOINT_AXIS};

/// One episode's draw of [`ScrewRandomization`] (zero where a range is [0, 0]), in the ranges' units.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StartDraw {
    /// Hand (and nut) turn about the bolt's axis [deg].
    pub hand_angle_deg: f32,
    /// Fingertip offset from the nut's grasp point in the hand's frame [mm] (x closing, y along the flats, z up).
    pub fingertip_offset_mm: [f32; 3],
    /// The nut's offset in the hand [mm] (y along the pads, z up).
    pub nut_in_gripper_mm: [f32; 2],
    /// The nut's turn in the hand [deg].
    pub nut_in_gripper_yaw_deg: f32,
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
    /// Each world's draw of the reset randomisation for its running episode, shape [env_count].
    world_draw: Vec<StartDraw>,
    /// The calibrated starts resets draw from (`randomize.starts_file`), in place of the ranges.
    starts: Option<calibrate::CalibrationFile>,
    /// The last step's measurements.
    last_diagnostics: StepDiagnostics,
    /// The nut frame's height when resting on the bolt's tip [m] (the Screw progress's start).
    tip_rest_z: f32,
    /// Stage times and progress counts since the env was built.
    profile: EnvProfile,
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

/// The nut frame's height above its seat at the start of an episode [m]: resting on the bolt's tip (the
/// shank's top), or on the first full thread (`start_engaged`) and `start_turns_down` pitches below it.
fn start_height(scene: &NutBoltScene, cfg: &FrankaNutBoltConfig) -> Result<f32> {
    let shank = scene.nb.dims.shank_length as f32;
    if !cfg.start_engaged {
        return Ok(shank);
    }
    // The first full thread: the highest whole number of pitches above the seat that is not above the tip or
    // in its chamfer (the thread maps onto itself under a one-pitch translation, so the nut fits there at yaw
    // 0, flats normal to x: the fingers close along x at yaw 0).
    let pitch = scene.nb.pitch;
    let chamfer = match scene.nb.bolt_tip_radius {
        Some(_) => factory_assets::bolt_tip_chamfer_height(&scene.nb.spec) as f32,
        None => 0.0,
    };
    let first = ((shank - chamfer) / pitch + 1e-4).floor();
    // Two pitches above the seat at the deepest: success is within one.
    let most = (first as u32).saturating_sub(2);
    if cfg.start_turns_down > most {
        return Err(EnvError::InvalidValue {
            field: "start_turns_down",
            reason: format!(
                "{} turns below the first full thread ({first} pitches above the seat); valid: 0..={most}",
                cfg.start_turns_down
            ),
        });
    }
    Ok((first - cfg.start_turns_down as f32) * pitch)
}

/// The observation's names (fingertip and nut pose and twist; the pads' forces and the previous action when
/// observed) and the action's.
fn observation_and_action_names(cfg: &FrankaNutBoltConfig) -> (Vec<String>, Vec<String>) {
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
    (names, action_names)
}

impl FrankaNutBolt {
    /// `env_count` worlds; `seed` draws the reset randomisation.
    pub fn new(cfg: &FrankaNutBoltConfig, env_count: usize, seed: u64) -> Result<Self> {
        cfg.check()?;
        let starts = match &cfg.randomize.starts_file {
            Some(path) => {
                let path = std::path::Path::new(path);
                let file = calibrate::CalibrationFile::load(path)?;
                file.check_env(cfg, path)?;
                Some(file)
            }
            None => None,
        };
        let gpu = GpuContext::global()?;
        let solver = SolverConfig {
            dt: cfg.dt,
            substeps: cfg.substeps,
            pos_iters: cfg.pos_iters,
            link_patch_iters: cfg.link_patch_iters,
            ..crate::franka::scene::screw_solver()
        };
        let scene_cfg = SceneConfig {
            worlds: env_count as u32,
            solver,
            contact: cfg.contact_config(),
            segments_per_turn: cfg.segments_per_turn,
            materials: cfg.materials.clone(),
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
        let start_z = start_height(&scene, cfg)?;
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
        let (names, action_names) = observation_and_action_names(cfg);
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
            world_draw: vec![StartDraw::default(); env_count],
            starts,
            last_diagnostics: StepDiagnostics::default(),
            tip_rest_z: shank,
            profile: EnvProfile::default(),
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

    /// Each world's draw of the reset randomisation for its running episode.
    pub fn start_draws(&self) -> &[StartDraw] {
        &self.world_draw
    }

    /// The nut's centre of mass in its frame [m].
    pub fn nut_com_local(&self) -> Vec3 {
        self.com_local
    }

    /// Resets world `w` to a new episode's start, drawing the randomisation (the host state; the link bodies
    /// follow at the next [`ArticulatedSim::sync_links`](factory_engine::sim::ArticulatedSim::sync_links)).
    pub fn reset_world(&mut self, w: usize) {
        if let Some(file) = &self.starts {
            let i = ((self.rng.unit() * file.starts.len() as f32) as usize).min(file.starts.len() - 1);
            let (pose, q, draw) = file.start(i);
            self.world_draw[w] = draw;
            self.scene.reset_world(self.gpu, w, pose, &q);
            return;
        }
        let r = self.cfg.randomize.clone();
        let mut draw = |[lo, hi]: [f32; 2]| if hi > lo { lo + (hi - lo) * self.rng.unit() } else { lo };
        let angle = draw(r.hand_angle_deg).to_radians();
        let o =
            Vec3::new(draw(r.fingertip_offset_mm[0]), draw(r.fingertip_offset_mm[1]), draw(r.fingertip_offset_mm[2]))
                * 1e-3;
        // Ranges at [0, 0] draw nothing, so the draws above stay those of a config without these.
        let in_hand = Vec3::new(0.0, draw(r.nut_in_gripper_mm[0]), draw(r.nut_in_gripper_mm[1])) * 1e-3;
        let nut_yaw = draw(r.nut_in_gripper_yaw_deg).to_radians();
        self.world_draw[w] = StartDraw {
            hand_angle_deg: angle.to_degrees(),
            fingertip_offset_mm: (o * 1e3).to_array(),
            nut_in_gripper_mm: [in_hand.y * 1e3, in_hand.z * 1e3],
            nut_in_gripper_yaw_deg: nut_yaw.to_degrees(),
        };
        if angle == 0.0 && o == Vec3::ZERO && in_hand == Vec3::ZERO && nut_yaw == 0.0 {
            self.scene.reset_world(self.gpu, w, self.reset_nut, &self.reset_q);
            return;
        }
        let turn = Quat::from_rotation_z(angle);
        let nut_turn = angle + nut_yaw;
        // On the helix: turning counterclockwise by `nut_turn` raises a right-hand nut by pitch * turn / 2 pi.
        let nut_p = self.reset_nut.0 + Vec3::Z * (self.scene.nb.pitch * nut_turn / std::f32::consts::TAU);
        let head = self.scene.nb.dims.head_height as f32;
        let grasp = Vec3::new(0.0, 0.0, head + nut_p.z + self.cfg.grasp_height);
        // The nut stays on the bolt's axis: its offset in the hand moves the hand the other way.
        let o = o - in_hand;
        let tip = grasp + turn * Vec3::new(o.x, o.y, 0.0) + Vec3::Z * o.z;
        let mut q = inverse_kinematics(&self.scene, &self.reset_q, tip, turn * self.down);
        // The fingers close along the hand's x: the left one (+y of the hand) to the nut's side at -o.x + s,
        // where s is the turned hexagon's half-extent along x (its support: the apothem at yaw 0, a corner's
        // projection R cos(30 deg - |yaw|) with R = apothem / cos 30 deg otherwise).
        let apothem = 0.5 * self.scene.nb.dims.width_across_flats as f32;
        let s = apothem * (std::f32::consts::FRAC_PI_6 - nut_yaw.abs()).cos() / std::f32::consts::FRAC_PI_6.cos();
        q[ARM_DOF] = s - o.x + 2e-4;
        q[ARM_DOF + 1] = s + o.x + 2e-4;
        self.scene.reset_world(self.gpu, w, (nut_p, Quat::from_rotation_z(nut_turn) * self.reset_nut.1), &q);
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

    /// The scripted Franka scene's screw stage (factory-bench's `franka-nut-bolt`) in this env's action
    /// space: the fingertip moved to put the nut's axis on the bolt's and pressed 2 mm below where it is, the
    /// hand turned back to pointing straight down, and the yaw turned clockwise (tightening) with its target
    /// half the yaw action's range ahead (0.05 rad a step at the default scale, 3 rad/s: already above
    /// joint 7's 2.61 rad/s limit, so the wrist sets the pace; the full action's lead of twice that lets the
    /// nut fall off the bolt's tip). Force and torque actions are zero.
    fn scripted_actions(&self) -> Option<Vec<f32>> {
        let c = &self.cfg;
        let arm = self.scene.arm();
        let mut action = vec![0.0f32; self.spec.env_count * 12];
        for (w, v) in self.views(&arm).iter().enumerate() {
            let a = &mut action[w * 12..(w + 1) * 12];
            let dp = Vec3::new(-v.nut_frame.x, -v.nut_frame.y, -0.002);
            // The small rotation that turns the hand's axis (z, out of the palm) back to straight down.
            let tilt = (v.tip_quat * Vec3::Z).cross(-Vec3::Z);
            for k in 0..3 {
                a[k] = (dp[k] / c.pos_action_scale[k]).clamp(-1.0, 1.0);
            }
            for k in 0..2 {
                a[3 + k] = (tilt[k] / c.rot_action_scale[k]).clamp(-1.0, 1.0);
            }
            a[5] = if c.unidirectional_rot { 0.0 } else { -0.5 };
        }
        Some(action)
    }

    fn diagnostics(&self) -> Option<StepDiagnostics> {
        Some(self.last_diagnostics.clone())
    }

    fn profile(&self) -> Option<EnvProfile> {
        Some(self.profile.clone())
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
        let started = std::time::Instant::now();
        let n = self.spec.env_count;
        let arm = self.scene.arm();
        let targets = action_targets(&self.cfg, &arm, action);
        let mut tau = vec![0.0f32; n * DOF];
        self.controller.compute(&arm, &targets, &mut tau);
        let mut control = ArticulationControl { joint_tau: tau, joint_target_q: self.scene.sim.joints.joint_q.clone() };
        for w in 0..n {
            // The fingers follow the gripper target through their drives; the arm joints have no drive. A
            // balanced grip moves each finger's target by its opening's difference from the mean, so both
            // drives pull with the mean's force.
            let q = &self.scene.sim.joints.joint_q[w * DOF + ARM_DOF..w * DOF + ARM_DOF + 2];
            let mean = 0.5 * (q[0] + q[1]);
            for f in 0..2 {
                let balance = if self.cfg.balanced_grip { q[f] - mean } else { 0.0 };
                control.joint_tau[w * DOF + ARM_DOF + f] = 0.0;
                control.joint_target_q[w * DOF + ARM_DOF + f] = targets.gripper_q[w * 2 + f] + balance;
            }
        }
        let controlled = started.elapsed().as_secs_f64();
        let diverged = self.scene.sim.step(self.gpu, &Control::default(), &control);
        let (contacts, solve) = (self.scene.sim.last_handling_s, self.scene.sim.last_solve_s);
        if let Some(c) = &self.scene.sim.contacts {
            self.profile.add_work("candidates", c.candidates.iter().map(|&k| k as u64).sum());
            self.profile.add_work("contacts", (0..c.patches.len()).map(|i| c.contact_count(i) as u64).sum());
        }
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
            // The descent from resting on the tip (the frame at the shank's top) to seated (the frame at 0).
            self.profile.add_progress(1.0 - v.nut_frame.z / self.tip_rest_z);
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
        let p = &mut self.profile;
        p.add_seconds("controller", controlled);
        p.add_seconds("contacts", contacts);
        p.add_seconds("solve", solve);
        p.add_seconds("task", started.elapsed().as_secs_f64() - controlled - contacts - solve);
    }
}

#[cfg(test)]
mod tests;

//! The Franka + nut-and-bolt scene every nut-bolt env and the scripted benchmark share (paper section
//! III-D's eighth scene without the feeder; IsaacGymEnvs' FactoryEnvNutBolt).
//!
//! Scene (z up, the table's surface at z = 0, the robot's base at x = -0.5 m as Factory's franka_depth):
//! the Franka ([`FRANKA_URDF`], armature 0.01), its finger pads (boxes queried at a 4 x 4 grid per face) the
//! only links that touch anything; the nut a dynamic body (the generated ISO nut, steel); the bolt static at
//! the origin, its thread the exact analytic field (nut triangles queried against it); the table a
//! half-space. Pads and table see the nut through its convex hull (a hexagonal prism: the flats the fingers
//! grip are exact). The nut's frame is the assembly's: its pose is the identity when it is seated.

use std::sync::Arc;

use factory_assets::{nut_bolt, Fit, IsoSize, NutBolt, ThreadOptions};
use factory_controllers::ArmBatch;
use factory_engine::articulation::sim::ArticulatedSim;
use factory_engine::articulation::{ArticulationModel, ArticulationState, Frame};
use factory_engine::builder::ModelBuilder;
use factory_engine::contact::roles::ShapeGeometry;
use factory_engine::contact::{ContactConfig, PairSpec, QueryShape, SdfShape, TransformGpu, NO_BODY};
use factory_engine::gpu::GpuContext;
use factory_engine::sdf::cache::SdfCache;
use factory_engine::solver::{BodyState, SolverConfig};
use factory_engine::urdf::{parse_urdf, UrdfModel};
use glam::{Quat, Vec3};

use crate::error::{EnvError, Result};

/// The project's Franka description (where it lives in the source tree; the name in error messages).
pub const FRANKA_URDF: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../assets/franka/franka_panda.urdf");
/// Its text, compiled in: it has primitives only (no mesh files), so a built binary needs no source tree
/// (`factory-train` copied or installed elsewhere once failed reading [`FRANKA_URDF`]).
pub const FRANKA_URDF_TEXT: &str = include_str!("../../../assets/franka/franka_panda.urdf");

/// The Franka parsed from [`FRANKA_URDF_TEXT`].
pub fn franka_urdf() -> std::result::Result<UrdfModel, factory_engine::EngineError> {
    let path = std::path::Path::new(FRANKA_URDF);
    parse_urdf(FRANKA_URDF_TEXT, path, path.parent().unwrap_or(std::path::Path::new("")))
}

/// Factory's Screw reset pose (IsaacGymEnvs FactoryTaskNutBoltScrew): the hand points down over the bolt;
/// fingers open.
pub const Q_START: [f32; 9] = [1.5178e-3, -0.19651, -1.4364e-3, -1.9761, -2.7717e-4, 1.7796, 0.78556, 0.04, 0.04];
/// Robot base position [m]. Factory (FactoryBase.yaml, factory_env_nut_bolt.py): the Franka stands on the floor
/// franka_depth 0.5 m behind the table's centre and the table top is table_height 0.4 m above the floor, so with
/// the table top at z = 0 here the base is 0.4 m below it; Q_START then puts the fingertip over the bolt's tip.
pub const BASE: Vec3 = Vec3::new(-0.5, 0.0, -0.4);
/// Arm joints of the Franka (the other two are the fingers).
pub const ARM_DOF: usize = 7;
/// All joints.
pub const DOF: usize = 9;

/// How the scene is built.
#[derive(Clone, Debug)]
pub struct SceneConfig {
    /// Worlds.
    pub worlds: u32,
    /// The solver (substeps, iterations, dt).
    pub solver: SolverConfig,
    /// Contact generation and reduction.
    pub contact: ContactConfig,
    /// Thread columns per turn of the generated nut (its triangles are queried against the bolt).
    pub segments_per_turn: usize,
    /// Friction of the nut-bolt pair (Factory's nut and bolt: 0.3).
    pub thread_mu: f32,
    /// The robot's base position [m] ([`BASE`] is Factory's).
    pub base: Vec3,
    /// Damping of each arm joint [N m s/rad] (IsaacGymEnvs' Factory Franka URDF: 10 on joints 1-6, none on
    /// joint 7).
    pub arm_damping: [f32; ARM_DOF],
    /// The fingers' drive toward the gripper target: stiffness [N/m] and damping [N s/m]. Closed on the
    /// 24 mm nut (target 0), each finger squeezes it with stiffness x 12 mm.
    pub finger_drive: [f32; 2],
    /// Chamfer the bolt's tip (ISO 4753, as Factory's bolt; `ThreadOptions::bolt_tip_chamfer`).
    pub bolt_tip_chamfer: bool,
}

/// The built scene: the simulator and what the envs need to find in it.
pub struct NutBoltScene {
    /// Bodies, joints and their stepping.
    pub sim: ArticulatedSim,
    /// The nut and bolt (dimensions, meshes, the bolt's field).
    pub nb: NutBolt,
    /// The fingertip-centred frame.
    pub tip: Frame,
    /// Body index of the nut.
    pub nut: usize,
    /// The thread pair's index among the contact pairs (for its contact force).
    pub thread_pair: usize,
}

fn steel_nut(size: IsoSize, segments_per_turn: usize, bolt_tip_chamfer: bool) -> Result<NutBolt> {
    nut_bolt(size, Fit::Loose, &ThreadOptions { segments_per_turn, bolt_tip_chamfer, ..Default::default() })
        .map_err(|e| EnvError::Build(format!("M16 nut and bolt: {e}")))
}

impl NutBoltScene {
    /// Builds `cfg.worlds` worlds with the nut at `nut_pose(&nut_and_bolt, w)` (its assembly frame) and the
    /// joints at `joints`.
    pub fn build(
        gpu: &GpuContext,
        cfg: &SceneConfig,
        mut nut_pose: impl FnMut(&NutBolt, usize) -> (Vec3, Quat),
        joints: ArticulationState,
    ) -> Result<Self> {
        if cfg.worlds == 0 {
            return Err(EnvError::InvalidValue { field: "env_count", reason: "must be at least 1".into() });
        }
        let urdf = franka_urdf()?;
        let mut art = ArticulationModel::from_urdf(&urdf, (cfg.base, Quat::IDENTITY), Vec3::new(0.0, 0.0, -9.81))?;
        // IsaacGymEnvs' Factory: armature 0.01 on every Franka joint.
        art.set_armature(0.01);
        // The gripper PD as an implicit joint drive (as explicit torques such gains are unstable on a 15 g
        // finger at Factory's time step).
        for d in ARM_DOF..DOF {
            art.dof_drive_stiffness[d] = cfg.finger_drive[0];
            art.dof_drive_damping[d] = cfg.finger_drive[1];
        }
        art.dof_damping[..ARM_DOF].copy_from_slice(&cfg.arm_damping);
        let tip = art
            .frame("panda_fingertip_centered")
            .ok_or_else(|| EnvError::Build(format!("{FRANKA_URDF} has no panda_fingertip_centered frame")))?;
        let nb = steel_nut(IsoSize::M16, cfg.segments_per_turn, cfg.bolt_tip_chamfer)?;
        let mut b = ModelBuilder::new(art.gravity);
        // Factory: nut friction 0.3, Franka 1.0, table 0.3 (pairs take the mean).
        let nut = b.add_dynamic_body(&nb.nut.mass_properties);
        let nut_shape = b.add_shape(
            Some(nut),
            (Vec3::ZERO, Quat::IDENTITY),
            ShapeGeometry::Mesh { mesh: Arc::new(nb.nut.mesh.clone()), sdf_resolution: None },
        );
        b.shape_mut(nut_shape).friction = 0.3;
        let table = b.add_shape(None, (Vec3::ZERO, Quat::IDENTITY), ShapeGeometry::Plane);
        b.shape_mut(table).friction = 0.3;
        let (_, left) = b.add_urdf_link(&urdf, &art, "panda_leftfinger", 1.0, 0.005)?;
        let (_, right) = b.add_urdf_link(&urdf, &art, "panda_rightfinger", 1.0, 0.005)?;
        b.filter_pair(left[0], right[0]);
        // The pads are wider than the nut's flats (17.5 vs 13.9 mm): queried at a 4 x 4 grid per face, as
        // Factory subdivides its finger mesh, they hold the flat at several points, not at a face
        // triangle's one deepest point (which let the nut turn in the hand).
        for pad in [left[0], right[0]] {
            if let ShapeGeometry::Box { half_extents } = b.shape_mut(pad).geometry {
                b.shape_mut(pad).geometry = ShapeGeometry::GridBox { half_extents, points_per_edge: 4 };
            }
        }
        b.replicate(cfg.worlds);
        let mut model = b.build(&SdfCache::new(SdfCache::default_dir()))?;
        // The thread: the nut's triangles against the bolt's exact field, the bolt fixed at the origin.
        let thread_pair = model.contacts.pairs.len();
        model.contacts.pairs.push(PairSpec {
            body_a: nut.0,
            a_pose: (Vec3::ZERO, Quat::IDENTITY),
            query: Arc::new(QueryShape::mesh(&nb.nut.mesh)),
            body_b: NO_BODY,
            b_pose: (Vec3::ZERO, Quat::IDENTITY),
            sdf: SdfShape::Thread(nb.bolt_sdf()),
            contact_offset: 0.002,
            friction: cfg.thread_mu,
        });
        let body_count = model.bodies.body_count();
        let worlds = cfg.worlds as usize;
        let mut body_q = vec![TransformGpu::new(Vec3::ZERO, Quat::IDENTITY); worlds * body_count];
        for w in 0..worlds {
            let (p, q) = nut_pose(&nb, w);
            body_q[w * body_count + nut.0 as usize] = TransformGpu::new(p, q);
        }
        let state = BodyState { body_q, body_qd: vec![[Vec3::ZERO; 2]; worlds * body_count] };
        let sim = ArticulatedSim::new(gpu, model, art, cfg.solver.clone(), &cfg.contact, state, joints)?;
        Ok(Self { sim, nb, tip, nut: nut.0 as usize, thread_pair })
    }

    /// Worlds.
    pub fn world_count(&self) -> usize {
        self.sim.world_count()
    }

    /// The nut's pose in world `w` (its assembly frame: the identity when seated).
    pub fn nut_pose(&self, w: usize) -> (Vec3, Quat) {
        let t = self.sim.state.body_q[w * self.sim.model.bodies.body_count() + self.nut];
        (Vec3::from_slice(&t.p[..3]), Quat::from_array(t.q))
    }

    /// The nut's linear and angular velocity in world `w` [m/s, rad/s].
    pub fn nut_velocity(&self, w: usize) -> [Vec3; 2] {
        self.sim.state.body_qd[w * self.sim.model.bodies.body_count() + self.nut]
    }

    /// Puts world `w`'s nut at `pose`, at rest, and its joints at `q` (at rest); forgets its warm start.
    /// Call [`ArticulatedSim::sync_links`] after the last such reset of a step.
    pub fn reset_world(&mut self, gpu: &GpuContext, w: usize, pose: (Vec3, Quat), q: &[f32; DOF]) {
        let nb = self.sim.model.bodies.body_count();
        self.sim.state.body_q[w * nb + self.nut] = TransformGpu::new(pose.0, pose.1);
        self.sim.state.body_qd[w * nb + self.nut] = [Vec3::ZERO; 2];
        self.sim.joints.joint_q[w * DOF..(w + 1) * DOF].copy_from_slice(q);
        self.sim.joints.joint_qd[w * DOF..(w + 1) * DOF].fill(0.0);
        self.sim.forget_world(gpu, w);
    }

    /// The controllers' view of the arm in every world (fingertip pose, twist, Jacobian, M, g).
    pub fn arm(&self) -> ArmBatch {
        ArmBatch::from_articulation(&self.sim.articulation, &self.sim.joints, &self.tip, ARM_DOF, &[])
    }
}

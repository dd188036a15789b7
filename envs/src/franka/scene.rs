//! The Franka + nut-and-bolt scene every nut-bolt env and the scripted benchmark share (paper section
//! III-D's eighth scene without the feeder; IsaacGymEnvs' FactoryEnvNutBolt).
//!
//! Scene (z up, the table's surface at z = 0, the robot's base at x = -0.5 m as Factory's franka_depth):
//! the Franka ([`FRANKA_URDF`], armature 0.01), its finger pads (boxes queried at a 4 x 4 grid per face) the
//! only links that touch anything; the nut a dynamic body (the generated ISO nut, steel); the bolt static at
//! the origin, its thread the exact analytic field (nut triangles queried against it); the table a
//! half-space. Pads and table see the nut through its convex hull (a hexagonal prism: the flats the fingers
//! grip are exact). The nut's frame is the assembly's: its pose is the identity when it is seated.
//!
//! Contact materials ([`ContactMaterials`], `[env.materials]`): each surface (nut, bolt, finger pads, table)
//! has a Coulomb friction coefficient, and every contact pair takes the two surfaces' coefficients through
//! one [`CombineRule`] (PhysX's combine modes; the default, "average", is PhysX's default and Factory's).
//! The defaults are Factory's values (FactoryEnvNutBolt: nut and bolt 0.3; FactoryBase: Franka 1.0, table
//! 0.3), which give the pairs: nut-table 0.3, nut-pad 0.65, pad-table 0.65, nut-bolt thread 0.3.

use std::sync::Arc;

use factory_assets::{nut_bolt, Fit, IsoSize, NutBolt, ThreadOptions};
use factory_controllers::ArmBatch;
use factory_engine::articulation::{ArticulationModel, ArticulationState, Frame};
use factory_engine::builder::{BodyHandle, Model, ModelBuilder, ShapeHandle};
use factory_engine::contact::roles::ShapeGeometry;
use factory_engine::contact::{ContactConfig, PairSpec, QueryShape, SdfShape, TransformGpu, NO_BODY};
use factory_engine::gpu::GpuContext;
use factory_engine::sdf::cache::SdfCache;
use factory_engine::sim::ArticulatedSim;
use factory_engine::solver::{BodyState, SolverConfig};
use factory_engine::urdf::{parse_urdf, UrdfModel};
use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};

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

/// How a contact pair's friction follows from its two surfaces' coefficients: PhysX's combine modes, which
/// Isaac Gym and Isaac Lab expose (`friction_combine_mode`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CombineRule {
    /// `(a + b) / 2`: PhysX's default, which Factory's scenes use.
    #[default]
    Average,
    /// The smaller coefficient.
    Min,
    /// The product `a * b`.
    Multiply,
    /// The larger coefficient.
    Max,
}

impl CombineRule {
    /// The pair's coefficient for two surfaces of coefficients `a` and `b`.
    pub fn combine(self, a: f32, b: f32) -> f32 {
        match self {
            // `ModelBuilder::build`'s expression: the pairs it makes keep their coefficient bit for bit.
            CombineRule::Average => 0.5 * (a + b),
            CombineRule::Min => a.min(b),
            CombineRule::Multiply => a * b,
            CombineRule::Max => a.max(b),
        }
    }
}

/// A surface of the scene with a contact material.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Surface {
    /// The nut: its flats and faces (against the pads and the table) and its thread (against the bolt).
    Nut,
    /// The bolt's thread.
    Bolt,
    /// The two finger pads.
    FingerPads,
    /// The table top.
    Table,
}

/// `[env.materials]`: each surface's Coulomb friction coefficient (unitless) and the rule that combines a
/// pair's two. The defaults are Factory's (FactoryEnvNutBolt's `nut_bolt_friction`, FactoryBase's
/// `franka_friction` and `table_friction`) with PhysX's average.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ContactMaterials {
    /// Friction of the nut's steel (Factory's `nut_bolt_friction`: 0.3).
    pub nut: f32,
    /// Friction of the bolt's steel (Factory's `nut_bolt_friction`: 0.3).
    pub bolt: f32,
    /// Friction of the finger pads (Factory's `franka_friction`: 1.0).
    pub finger_pads: f32,
    /// Friction of the table top (Factory's `table_friction`: 0.3).
    pub table: f32,
    /// How a pair combines its two surfaces' coefficients: "average" (PhysX's default and Factory's), "min",
    /// "multiply" or "max".
    pub combine: CombineRule,
}

impl Default for ContactMaterials {
    fn default() -> Self {
        Self { nut: 0.3, bolt: 0.3, finger_pads: 1.0, table: 0.3, combine: CombineRule::Average }
    }
}

impl ContactMaterials {
    /// Surface `s`'s coefficient.
    pub fn friction(&self, s: Surface) -> f32 {
        match s {
            Surface::Nut => self.nut,
            Surface::Bolt => self.bolt,
            Surface::FingerPads => self.finger_pads,
            Surface::Table => self.table,
        }
    }

    /// The coefficient of a contact pair between surfaces `a` and `b`.
    pub fn pair_friction(&self, a: Surface, b: Surface) -> f32 {
        self.combine.combine(self.friction(a), self.friction(b))
    }

    /// Each surface's key under `[env.materials]` and its coefficient (for checks that name the key).
    pub fn coefficients(&self) -> [(&'static str, f32); 4] {
        [
            ("materials.nut", self.nut),
            ("materials.bolt", self.bolt),
            ("materials.finger_pads", self.finger_pads),
            ("materials.table", self.table),
        ]
    }
}

/// The solver of the Franka nut-and-bolt scenes (the Screw env's defaults and factory-bench's scripted
/// scene): dt 1/60 s, 4 substeps x 32 position iterations, no velocity iterations (Factory's tasks), and 8
/// extra passes over each finger pad's patch per sweep (`link_patch_iters`). Factory's tasks run 2 x 16;
/// here the pads then slide along the nut and a screwing hand loses it, since plain Gauss-Seidel converges
/// slowly on the arm - pads - nut - bolt chain (docs/ARCHITECTURE.md section 6). Fewer sweeps lose the grasp
/// more often: at 4 x 24 the frozen policy of docs/BENCHMARKS.md ("Training pace") lets more nuts slip from
/// the hand, and at 4 x 16 the pads creep along a still nut (`envs/examples/grip_check.rs`).
pub fn screw_solver() -> SolverConfig {
    SolverConfig { dt: 1.0 / 60.0, substeps: 4, pos_iters: 32, vel_iters: 0, link_patch_iters: 8, ..Default::default() }
}

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
    /// Friction of every surface and how a pair combines them.
    pub materials: ContactMaterials,
    /// The thread pair's friction in place of the materials' nut-bolt combination (`None`: combined).
    pub thread_mu: Option<f32>,
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
    /// The two surfaces of each contact pair, in the contact model's pair order (the materials they take).
    pub pair_surfaces: Vec<(Surface, Surface)>,
}

fn steel_nut(size: IsoSize, segments_per_turn: usize, bolt_tip_chamfer: bool) -> Result<NutBolt> {
    nut_bolt(size, Fit::Loose, &ThreadOptions { segments_per_turn, bolt_tip_chamfer, ..Default::default() })
        .map_err(|e| EnvError::Build(format!("M16 nut and bolt: {e}")))
}

/// Contact offset of the pads', nut's and table's pairs [m] (candidates farther apart are ignored).
const CONTACT_OFFSET: f32 = 0.005;
/// Contact offset of the thread pair [m].
const THREAD_CONTACT_OFFSET: f32 = 0.002;

/// The scene's bodies and contact pairs, before the simulator takes them.
struct SceneModel {
    model: Model,
    nb: NutBolt,
    /// The nut's body.
    nut: BodyHandle,
    /// The thread pair's index among the contact pairs.
    thread_pair: usize,
    /// The two surfaces of each contact pair, in `model.contacts.pairs` order.
    pair_surfaces: Vec<(Surface, Surface)>,
}

/// One world's nut, table and finger pads (on `art`'s links) replicated `cfg.worlds` times, and the thread
/// pair; each pair's friction is `cfg.materials`' combination of its two surfaces' (the thread's is
/// `cfg.thread_mu` where that is set).
fn scene_model(cfg: &SceneConfig, urdf: &UrdfModel, art: &ArticulationModel) -> Result<SceneModel> {
    let materials = &cfg.materials;
    let nb = steel_nut(IsoSize::M16, cfg.segments_per_turn, cfg.bolt_tip_chamfer)?;
    let mut b = ModelBuilder::new(art.gravity);
    let mut surfaces = Vec::new();
    let nut = b.add_dynamic_body(&nb.nut.mass_properties);
    let nut_shape = b.add_shape(
        Some(nut),
        (Vec3::ZERO, Quat::IDENTITY),
        ShapeGeometry::Mesh { mesh: Arc::new(nb.nut.mesh.clone()), sdf_resolution: None },
    );
    surfaces.push((nut_shape, Surface::Nut));
    let table = b.add_shape(None, (Vec3::ZERO, Quat::IDENTITY), ShapeGeometry::Plane);
    surfaces.push((table, Surface::Table));
    for s in [nut_shape, table] {
        b.shape_mut(s).contact_offset = CONTACT_OFFSET;
    }
    let pads = materials.finger_pads;
    let (_, left) = b.add_urdf_link(urdf, art, "panda_leftfinger", pads, CONTACT_OFFSET)?;
    let (_, right) = b.add_urdf_link(urdf, art, "panda_rightfinger", pads, CONTACT_OFFSET)?;
    surfaces.extend(left.iter().chain(&right).map(|&s| (s, Surface::FingerPads)));
    b.filter_pair(left[0], right[0]);
    // The pads are wider than the nut's flats (17.5 vs 13.9 mm): queried at a 4 x 4 grid per face, as
    // Factory subdivides its finger mesh, they hold the flat at several points, not at a face triangle's one
    // deepest point (which let the nut turn in the hand).
    for pad in [left[0], right[0]] {
        if let ShapeGeometry::Box { half_extents } = b.shape_mut(pad).geometry {
            b.shape_mut(pad).geometry = ShapeGeometry::GridBox { half_extents, points_per_edge: 4 };
        }
    }
    for &(s, surface) in &surfaces {
        b.shape_mut(s).friction = materials.friction(surface);
    }
    b.replicate(cfg.worlds);
    let mut model = b.build(&SdfCache::new(SdfCache::default_dir()))?;
    // Every pair's friction by the materials' rule (the builder's own is the average).
    let surface = |s: ShapeHandle| {
        surfaces
            .iter()
            .find(|(h, _)| *h == s)
            .map(|&(_, surface)| surface)
            .ok_or_else(|| EnvError::Build(format!("shape {} has no contact material", s.0)))
    };
    let mut pair_surfaces = Vec::with_capacity(model.pair_shapes.len() + 1);
    for (pair, &(a, b)) in model.contacts.pairs.iter_mut().zip(&model.pair_shapes) {
        let (a, b) = (surface(a)?, surface(b)?);
        pair.friction = materials.pair_friction(a, b);
        pair_surfaces.push((a, b));
    }
    // The thread: the nut's triangles against the bolt's exact field, the bolt fixed at the origin.
    let thread_pair = model.contacts.pairs.len();
    model.contacts.pairs.push(PairSpec {
        body_a: nut.0,
        a_pose: (Vec3::ZERO, Quat::IDENTITY),
        query: Arc::new(QueryShape::mesh(&nb.nut.mesh)),
        body_b: NO_BODY,
        b_pose: (Vec3::ZERO, Quat::IDENTITY),
        sdf: SdfShape::Thread(nb.bolt_sdf()),
        contact_offset: THREAD_CONTACT_OFFSET,
        friction: cfg.thread_mu.unwrap_or_else(|| materials.pair_friction(Surface::Nut, Surface::Bolt)),
    });
    pair_surfaces.push((Surface::Nut, Surface::Bolt));
    Ok(SceneModel { model, nb, nut, thread_pair, pair_surfaces })
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
        let SceneModel { model, nb, nut, thread_pair, pair_surfaces } = scene_model(cfg, &urdf, &art)?;
        let body_count = model.bodies.body_count();
        let worlds = cfg.worlds as usize;
        let mut body_q = vec![TransformGpu::new(Vec3::ZERO, Quat::IDENTITY); worlds * body_count];
        for w in 0..worlds {
            let (p, q) = nut_pose(&nb, w);
            body_q[w * body_count + nut.0 as usize] = TransformGpu::new(p, q);
        }
        let state = BodyState { body_q, body_qd: vec![[Vec3::ZERO; 2]; worlds * body_count] };
        let sim = ArticulatedSim::new(gpu, model, art, cfg.solver.clone(), &cfg.contact, state, joints)?;
        Ok(Self { sim, nb, tip, nut: nut.0 as usize, thread_pair, pair_surfaces })
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The Screw env's scene, one world.
    fn screw_scene() -> SceneConfig {
        SceneConfig {
            worlds: 1,
            solver: SolverConfig::default(),
            contact: ContactConfig::default(),
            segments_per_turn: 48,
            materials: ContactMaterials::default(),
            thread_mu: None,
            base: BASE,
            arm_damping: [10.0; ARM_DOF],
            finger_drive: [500.0, 20.0],
            bolt_tip_chamfer: true,
        }
    }

    /// Factory's coefficients of each pair, as the scene set them before it had materials: the builder's
    /// `0.5 * (a + b)` of the shapes' literals (nut 0.3, pads 1.0, table 0.3) and the thread's 0.3.
    fn factorys(a: Surface, b: Surface) -> f32 {
        use Surface::*;
        match (a, b) {
            (Nut, Table) | (Table, Nut) => 0.3,
            (Nut, FingerPads) | (FingerPads, Nut) | (FingerPads, Table) | (Table, FingerPads) => 0.65,
            (Nut, Bolt) | (Bolt, Nut) => 0.3,
            _ => panic!("no {a:?}-{b:?} pair in the scene"),
        }
    }

    #[test]
    fn the_default_materials_give_factorys_pair_frictions_bit_for_bit() {
        use Surface::*;
        let m = ContactMaterials::default();
        for (a, b) in [(Nut, Table), (Nut, FingerPads), (FingerPads, Table), (Nut, Bolt)] {
            assert_eq!(m.pair_friction(a, b).to_bits(), factorys(a, b).to_bits(), "{a:?}-{b:?}");
            assert_eq!(m.pair_friction(b, a).to_bits(), factorys(a, b).to_bits(), "{b:?}-{a:?}");
        }
        // The literal 0.65 is what the builder's mean of the old literals gave.
        assert_eq!((0.5 * (0.3f32 + 1.0f32)).to_bits(), 0.65f32.to_bits());
        assert_eq!((0.5 * (0.3f32 + 0.3f32)).to_bits(), 0.3f32.to_bits());
    }

    #[test]
    fn each_rule_combines_as_named() {
        let (a, b) = (0.3, 1.0);
        assert_eq!(CombineRule::Average.combine(a, b), 0.5 * (a + b));
        assert_eq!(CombineRule::Min.combine(a, b), 0.3);
        assert_eq!(CombineRule::Multiply.combine(a, b), 0.3);
        assert_eq!(CombineRule::Max.combine(a, b), 1.0);
        assert_eq!(CombineRule::default(), CombineRule::Average);
    }

    /// Every contact pair of the built scene (nut-table, two nut-pad, two pad-table, the thread) takes the
    /// coefficient the scene had before it had materials; `thread_mu` replaces the thread's alone, and
    /// another rule reaches every combined pair.
    #[test]
    fn the_scene_pairs_take_their_materials() {
        let urdf = franka_urdf().unwrap();
        let art = ArticulationModel::from_urdf(&urdf, (BASE, Quat::IDENTITY), Vec3::new(0.0, 0.0, -9.81)).unwrap();
        let s = scene_model(&screw_scene(), &urdf, &art).unwrap();
        let pairs = &s.model.contacts.pairs;
        assert_eq!(s.pair_surfaces.len(), pairs.len());
        assert_eq!(s.pair_surfaces[s.thread_pair], (Surface::Nut, Surface::Bolt));
        let count = |x: Surface, y: Surface| s.pair_surfaces.iter().filter(|&&p| p == (x, y) || p == (y, x)).count();
        use Surface::*;
        assert_eq!(
            [count(Nut, Table), count(Nut, FingerPads), count(FingerPads, Table), count(Nut, Bolt), pairs.len()],
            [1, 2, 2, 1, 6],
            "{:?}",
            s.pair_surfaces
        );
        for (pair, &(a, b)) in pairs.iter().zip(&s.pair_surfaces) {
            assert_eq!(pair.friction.to_bits(), factorys(a, b).to_bits(), "{a:?}-{b:?}: {}", pair.friction);
        }

        let cfg = SceneConfig {
            thread_mu: Some(0.2),
            materials: ContactMaterials { combine: CombineRule::Max, ..Default::default() },
            ..screw_scene()
        };
        let s = scene_model(&cfg, &urdf, &art).unwrap();
        for (i, (pair, &(a, b))) in s.model.contacts.pairs.iter().zip(&s.pair_surfaces).enumerate() {
            let expected = match (a, b) {
                _ if i == s.thread_pair => 0.2,
                (FingerPads, _) | (_, FingerPads) => 1.0,
                _ => 0.3,
            };
            assert_eq!(pair.friction, expected, "{a:?}-{b:?}");
        }
    }
}

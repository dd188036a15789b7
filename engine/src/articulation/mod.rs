//! Articulated robots in reduced (joint) coordinates: a tree of links connected by revolute, continuous,
//! prismatic and fixed joints, fixed to the world at its root (the Franka of Factory's section IV;
//! docs/ARCHITECTURE.md section 3).
//!
//! The state of a world is its joint positions and velocities (`joint_q`, `joint_qd`, `dof_count` each).
//! From them [`dynamics`] computes, per world: forward kinematics (link poses), the geometric Jacobian of
//! any link point or named frame, the joint-space mass matrix M(q) (armature on its diagonal), the
//! generalised gravity torque g(q) and the Coriolis and centrifugal torque c(q, qd), by the recursive
//! Newton-Euler algorithm (Featherstone, "Rigid Body Dynamics Algorithms", 2008, ch. 5; Siciliano et al.,
//! "Robotics: Modelling, Planning and Control", 2009, section 7.5) and, for M, the sum over links of
//! J_com^T m J_com + J_w^T I J_w (Siciliano et al. eq. 7.32), which needs only the Jacobians the
//! controllers compute anyway. Equation of motion, per world:
//!
//!   M(q) qdd + c(q, qd) + g(q) + D qd = tau
//!
//! with D the joint damping. [`dynamics::step_cpu`] integrates it (semi-implicit Euler with the damping and
//! drive damping implicit, as PhysX and MuJoCo treat them), clamps torques to the effort limits and
//! velocities to the velocity limits, and stops joints at their position limits. The world is the batch
//! axis: every world shares the model and has its own state.
//!
//! Conventions: a URDF joint frame is its child link's frame (<http://wiki.ros.org/urdf/XML/joint>), so a
//! revolute axis passes through the child link's origin; links are stored parent before child.

pub mod dynamics;
pub mod gpu;
pub mod rotation;

use crate::error::{EngineError, Result};
use crate::urdf::{JointType, UrdfModel};
use glam::{Mat3, Quat, Vec3};
use std::collections::HashMap;

/// Parent index of the root link.
pub const NO_LINK: u32 = u32::MAX;
/// Degree-of-freedom index of a link whose joint is fixed (or of the root).
pub const NO_DOF: u32 = u32::MAX;

/// How a link moves relative to its parent.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JointKind {
    /// Rigidly attached (or the root, attached to the world at the base pose).
    Fixed,
    /// Rotation about the joint axis (URDF revolute and continuous).
    Revolute,
    /// Translation along the joint axis.
    Prismatic,
}

/// A named frame rigidly attached to a link (a fingertip, a tool centre point).
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    pub name: String,
    /// The link carrying it.
    pub link: u32,
    /// Its pose in the link frame: position [m], rotation.
    pub offset: (Vec3, Quat),
}

/// The static description of one articulation, shared by every world.
#[derive(Clone, Debug, PartialEq)]
pub struct ArticulationModel {
    /// Where the model came from (named in errors).
    pub name: String,
    /// Link names, shape [link_count]; parents come before their children.
    pub link_name: Vec<String>,
    /// Parent link index, [`NO_LINK`] for the root, shape [link_count].
    pub link_parent: Vec<u32>,
    /// Joint connecting the link to its parent, shape [link_count].
    pub link_joint: Vec<JointKind>,
    /// The link's degree of freedom, [`NO_DOF`] for fixed joints, shape [link_count].
    pub link_dof: Vec<u32>,
    /// The link (= joint) frame in the parent link frame at joint position 0 [m, unit quat], shape
    /// [link_count]; for the root, its pose in the world (the base pose).
    pub link_origin: Vec<(Vec3, Quat)>,
    /// Unit joint axis in the link frame, shape [link_count] (unused for fixed joints).
    pub link_axis: Vec<Vec3>,
    /// Mass [kg], shape [link_count] (0 for massless links).
    pub link_mass: Vec<f32>,
    /// Centre of mass in the link frame [m], shape [link_count].
    pub link_com: Vec<Vec3>,
    /// Inertia about the centre of mass in link axes [kg m^2], shape [link_count].
    pub link_inertia: Vec<Mat3>,
    /// Joint names of the degrees of freedom, shape [dof_count].
    pub dof_name: Vec<String>,
    /// The link each degree of freedom moves, shape [dof_count].
    pub dof_link: Vec<u32>,
    /// Position limits [rad or m], shape [dof_count]; -inf / +inf for continuous joints.
    pub dof_lower: Vec<f32>,
    pub dof_upper: Vec<f32>,
    /// Speed limit [rad/s or m/s], shape [dof_count]; +inf for none.
    pub dof_velocity_limit: Vec<f32>,
    /// Effort limit [N m or N], shape [dof_count]; +inf for none.
    pub dof_effort_limit: Vec<f32>,
    /// Viscous joint damping [N m s/rad or N s/m], shape [dof_count].
    pub dof_damping: Vec<f32>,
    /// Armature (rotor inertia reflected to the joint) added to M's diagonal [kg m^2 or kg], shape
    /// [dof_count]. IsaacGymEnvs' Factory sets 0.01 on every Franka joint.
    pub dof_armature: Vec<f32>,
    /// Position-drive stiffness [N m/rad or N/m] and damping [N m s/rad or N s/m], shape [dof_count]; 0:
    /// the joint is driven by effort alone (Factory's controllers command torques).
    pub dof_drive_stiffness: Vec<f32>,
    pub dof_drive_damping: Vec<f32>,
    /// Named frames (from URDF links with no mass and a fixed joint are also kept as links).
    pub frames: Vec<Frame>,
    /// Gravity [m/s^2].
    pub gravity: Vec3,
}

impl ArticulationModel {
    pub fn link_count(&self) -> usize {
        self.link_name.len()
    }

    pub fn dof_count(&self) -> usize {
        self.dof_name.len()
    }

    /// Index of the link named `name`.
    pub fn link_index(&self, name: &str) -> Option<u32> {
        self.link_name.iter().position(|n| n == name).map(|i| i as u32)
    }

    /// Index of the degree of freedom whose joint is named `name`.
    pub fn dof_index(&self, name: &str) -> Option<u32> {
        self.dof_name.iter().position(|n| n == name).map(|i| i as u32)
    }

    /// The frame named `name`: a link, or a frame added with [`ArticulationModel::add_frame`].
    pub fn frame(&self, name: &str) -> Option<Frame> {
        if let Some(f) = self.frames.iter().find(|f| f.name == name) {
            return Some(f.clone());
        }
        self.link_index(name).map(|link| Frame { name: name.to_string(), link, offset: (Vec3::ZERO, Quat::IDENTITY) })
    }

    /// Attaches a named frame to `link` at `offset` (position [m], rotation in the link frame).
    pub fn add_frame(&mut self, name: &str, link: u32, offset: (Vec3, Quat)) {
        self.frames.push(Frame { name: name.to_string(), link, offset });
    }

    /// Sets every joint's armature [kg m^2 or kg].
    pub fn set_armature(&mut self, armature: f32) {
        self.dof_armature.iter_mut().for_each(|a| *a = armature);
    }

    /// Builds the articulation of a URDF robot whose root link is fixed to the world at `base` (position
    /// [m], rotation). Revolute and continuous joints become rotational degrees of freedom, prismatic ones
    /// translational, fixed joints rigid attachments; every link keeps its own mass properties. Floating and
    /// planar joints are refused (a fixed-base articulation has none), and so is a `<mimic>` (the engine
    /// has no joint coupling: a Franka's fingers are two independent prismatic joints here, which is how
    /// Factory drives them), each naming the joint and the file.
    pub fn from_urdf(urdf: &UrdfModel, base: (Vec3, Quat), gravity: Vec3) -> Result<Self> {
        let refuse = |message: String| EngineError::Asset { path: urdf.source.clone(), message };
        for j in &urdf.joints {
            match j.joint_type {
                JointType::Floating | JointType::Planar => {
                    return Err(refuse(format!(
                        "joint '{}' has type '{}', which an articulation does not support (supported: revolute, \
                         continuous, prismatic, fixed)",
                        j.name,
                        JointType::NAMES[j.joint_type as usize]
                    )))
                }
                _ => {}
            }
            if let Some(m) = &j.mimic {
                return Err(refuse(format!(
                    "joint '{}' mimics '{}': joint coupling is not supported; drive the joints independently",
                    j.name, m.joint
                )));
            }
        }
        // Parent before child: a depth-first walk from the root, children in document order.
        let mut children: HashMap<&str, Vec<usize>> = HashMap::new();
        for (i, j) in urdf.joints.iter().enumerate() {
            children.entry(j.parent.as_str()).or_default().push(i);
        }
        let root = urdf.root_link();
        let mut m = ArticulationModel {
            name: urdf.name.clone(),
            link_name: Vec::new(),
            link_parent: Vec::new(),
            link_joint: Vec::new(),
            link_dof: Vec::new(),
            link_origin: Vec::new(),
            link_axis: Vec::new(),
            link_mass: Vec::new(),
            link_com: Vec::new(),
            link_inertia: Vec::new(),
            dof_name: Vec::new(),
            dof_link: Vec::new(),
            dof_lower: Vec::new(),
            dof_upper: Vec::new(),
            dof_velocity_limit: Vec::new(),
            dof_effort_limit: Vec::new(),
            dof_damping: Vec::new(),
            dof_armature: Vec::new(),
            dof_drive_stiffness: Vec::new(),
            dof_drive_damping: Vec::new(),
            frames: Vec::new(),
            gravity,
        };
        let mut stack: Vec<(&str, u32, Option<usize>)> = vec![(root.name.as_str(), NO_LINK, None)];
        while let Some((name, parent, joint)) = stack.pop() {
            let link = urdf.link(name).expect("validated at load: joints name existing links");
            let index = m.link_name.len() as u32;
            m.link_name.push(link.name.clone());
            m.link_parent.push(parent);
            let (mass, com, inertia) = match &link.inertial {
                Some(i) => {
                    let r = Mat3::from_quat(i.origin.rotation);
                    (i.mass, i.origin.translation, r * i.inertia * r.transpose())
                }
                None => (0.0, Vec3::ZERO, Mat3::ZERO),
            };
            m.link_mass.push(mass);
            m.link_com.push(com);
            m.link_inertia.push(inertia);
            match joint {
                None => {
                    m.link_joint.push(JointKind::Fixed);
                    m.link_dof.push(NO_DOF);
                    m.link_origin.push(base);
                    m.link_axis.push(Vec3::Z);
                }
                Some(ji) => {
                    let j = &urdf.joints[ji];
                    m.link_origin.push((j.origin.translation, j.origin.rotation));
                    let axis = j.axis.normalize_or_zero();
                    if j.joint_type != JointType::Fixed && axis == Vec3::ZERO {
                        return Err(refuse(format!("joint '{}' has a zero axis", j.name)));
                    }
                    m.link_axis.push(axis);
                    let kind = match j.joint_type {
                        JointType::Revolute | JointType::Continuous => JointKind::Revolute,
                        JointType::Prismatic => JointKind::Prismatic,
                        _ => JointKind::Fixed,
                    };
                    m.link_joint.push(kind);
                    if kind == JointKind::Fixed {
                        m.link_dof.push(NO_DOF);
                    } else {
                        m.link_dof.push(m.dof_name.len() as u32);
                        m.dof_name.push(j.name.clone());
                        m.dof_link.push(index);
                        let limited = j.joint_type != JointType::Continuous;
                        let lim = j.limit;
                        m.dof_lower.push(match (limited, lim) {
                            (true, Some(l)) => l.lower,
                            _ => f32::NEG_INFINITY,
                        });
                        m.dof_upper.push(match (limited, lim) {
                            (true, Some(l)) => l.upper,
                            _ => f32::INFINITY,
                        });
                        // URDF's 0 means "not given" for these two in practice; treat it as no limit.
                        let positive_or_inf = |v: f32| if v > 0.0 { v } else { f32::INFINITY };
                        m.dof_velocity_limit.push(lim.map_or(f32::INFINITY, |l| positive_or_inf(l.velocity)));
                        m.dof_effort_limit.push(lim.map_or(f32::INFINITY, |l| positive_or_inf(l.effort)));
                        m.dof_damping.push(j.dynamics.map_or(0.0, |d| d.damping));
                        m.dof_armature.push(0.0);
                        m.dof_drive_stiffness.push(0.0);
                        m.dof_drive_damping.push(0.0);
                    }
                }
            }
            // Reverse so that the first child in document order is visited first.
            if let Some(cs) = children.get(name) {
                for &ci in cs.iter().rev() {
                    stack.push((urdf.joints[ci].child.as_str(), index, Some(ci)));
                }
            }
        }
        Ok(m)
    }
}

/// The joint state of every world.
#[derive(Clone, Debug, PartialEq)]
pub struct ArticulationState {
    /// Joint positions [rad or m], shape [world_count * dof_count].
    pub joint_q: Vec<f32>,
    /// Joint velocities [rad/s or m/s], shape [world_count * dof_count].
    pub joint_qd: Vec<f32>,
}

impl ArticulationState {
    /// Every world at `q` (length dof_count), at rest.
    pub fn replicate(q: &[f32], world_count: usize) -> Self {
        ArticulationState { joint_q: q.repeat(world_count), joint_qd: vec![0.0; q.len() * world_count] }
    }

    pub fn world_count(&self, model: &ArticulationModel) -> usize {
        self.joint_q.len() / model.dof_count().max(1)
    }
}

/// What drives the joints during a step, held over the step.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ArticulationControl {
    /// Joint torques or forces [N m or N], shape [world_count * dof_count] (empty: none).
    pub joint_tau: Vec<f32>,
    /// Position-drive targets [rad or m], shape [world_count * dof_count] (empty: the drives are off; used
    /// with the model's `dof_drive_stiffness`).
    pub joint_target_q: Vec<f32>,
}

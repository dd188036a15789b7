//! Controller configs: one TOML table per controller, selected by `type`.
//!
//! ```toml
//! [controller]
//! type = "osc"                      # or "operational_space_motion"
//! kp = [1, 1, 1, 1, 1, 200]         # a number means the same gain on every axis: kd = 1
//! kd = 1
//! motion_axes = [0, 0, 1, 0, 0, 1]
//! gripper_kp = [100, 100]
//! gripper_kd = [1, 1]
//! ```
//!
//! Every key is optional (the defaults are IsaacGymEnvs' Factory values, see each struct); unknown keys are
//! refused. Lengths are checked when the controller is built for a robot ([`crate::build`]), because only then
//! are `dof` and `arm_dof` known; the error names the field, its length and the expected length.

use serde::{Deserialize, Serialize};

use crate::error::{ControllerError, Result};
use crate::registry::{canonical_name, NAMES};
use crate::rotation::JacobianKind;

/// A gain or selection vector: a number (the same value on every axis or joint) or an array with one value per
/// axis or joint. TOML integers are accepted (`kp = [40, 40, 40, 40, 40, 40]`).
#[derive(Debug, Clone, PartialEq)]
pub enum Gains {
    /// One value for every entry.
    All(f32),
    /// One value per entry; the length is checked against the controller's when it is built.
    Each(Vec<f32>),
}

impl Gains {
    /// The per-entry values for a vector of length `expected`, or [`ControllerError::WrongLength`] naming
    /// `field`.
    pub fn resolve(&self, field: &'static str, expected: usize) -> Result<Vec<f32>> {
        match self {
            Gains::All(x) => Ok(vec![*x; expected]),
            Gains::Each(v) if v.len() == expected => Ok(v.clone()),
            Gains::Each(v) => Err(ControllerError::WrongLength { field, len: v.len(), expected }),
        }
    }
}

impl From<f32> for Gains {
    fn from(x: f32) -> Self {
        Gains::All(x)
    }
}

impl From<Vec<f32>> for Gains {
    fn from(v: Vec<f32>) -> Self {
        Gains::Each(v)
    }
}

impl Serialize for Gains {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        match self {
            Gains::All(x) => s.serialize_f32(*x),
            Gains::Each(v) => v.serialize(s),
        }
    }
}

impl<'de> Deserialize<'de> for Gains {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V;
        impl<'de> serde::de::Visitor<'de> for V {
            type Value = Gains;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a number or an array of numbers")
            }
            fn visit_f64<E: serde::de::Error>(self, x: f64) -> std::result::Result<Gains, E> {
                Ok(Gains::All(x as f32))
            }
            fn visit_i64<E: serde::de::Error>(self, x: i64) -> std::result::Result<Gains, E> {
                Ok(Gains::All(x as f32))
            }
            fn visit_u64<E: serde::de::Error>(self, x: u64) -> std::result::Result<Gains, E> {
                Ok(Gains::All(x as f32))
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> std::result::Result<Gains, A::Error> {
                let mut v = Vec::with_capacity(seq.size_hint().unwrap_or(6));
                while let Some(x) = seq.next_element::<f32>()? {
                    v.push(x);
                }
                Ok(Gains::Each(v))
            }
        }
        d.deserialize_any(V)
    }
}

/// How joint-space controllers turn the 6-D task error into a joint error (paper appendix D4 eq. 1; IsaacGymEnvs
/// `_get_delta_dof_pos`). J is the arm's 6 x arm_dof Jacobian, e the task error.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum IkMethod {
    /// Moore-Penrose pseudoinverse `J⁺ e` (singular values below `max(6, n)·ε·σmax` dropped, as
    /// `torch.linalg.pinv`).
    Pinv,
    /// Jacobian transpose `Jᵀ e` (gain 1).
    Trans,
    /// Damped least squares (Levenberg-Marquardt) `Jᵀ (J Jᵀ + λ² I)⁻¹ e`.
    #[default]
    Dls,
    /// Adaptive SVD: the pseudoinverse with singular values below `svd_min_singular_value` dropped.
    Svd,
}

/// The motion half of the hybrid controller (paper appendix D4 eq. 7: "stacks a task-space impedance or OSC
/// motion controller").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MotionLaw {
    /// Operational-space motion (eq. 4): the task-space PD scaled by Λ.
    #[default]
    Osc,
    /// Task-space impedance (eq. 3): the task-space PD as a wrench.
    Impedance,
}

/// The force half of the hybrid controller ("with an open- or closed-loop force controller").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ForceLaw {
    /// Closed-loop P force control (eq. 6).
    #[default]
    Closed,
    /// Open-loop force control (eq. 5).
    Open,
}

/// IsaacGymEnvs' finger PD stiffness in Pick and Place (`ctrl.all.gripper_prop_gains`) [N/m]; Screw uses 100.
pub const DEFAULT_GRIPPER_KP: f32 = 50.0;
/// IsaacGymEnvs' finger PD damping in Pick and Place (`ctrl.all.gripper_deriv_gains`) [N s/m]; Screw uses 1.
pub const DEFAULT_GRIPPER_KD: f32 = 2.0;
/// IsaacGymEnvs clamps every joint torque to ±100 (`factory_control.compute_dof_torque`) [N m, N].
pub const DEFAULT_TORQUE_LIMIT: f32 = 100.0;

/// The settings every controller shares (the finger PD, torque limits, gravity compensation), as read from
/// any of the config structs by their `common()` method.
#[derive(Debug, Clone, PartialEq)]
pub struct CommonSettings {
    /// Finger PD stiffness [N/m], one per finger joint (`dof - arm_dof`).
    pub gripper_kp: Gains,
    /// Finger PD damping [N s/m], one per finger joint.
    pub gripper_kd: Gains,
    /// Symmetric clamp on every joint's torque [N m] or force [N].
    pub torque_limit: f32,
    /// Optional per-joint effort limits [N m, N], length `dof`, applied on top of `torque_limit`.
    pub effort_limit: Option<Vec<f32>>,
    /// Add the gravity torques g(q) to the arm's torques.
    pub gravity_compensation: bool,
}

/// Defines a config struct with its own fields plus the common ones, `Default`, and `common()`.
macro_rules! controller_config {
    (
        $(#[$meta:meta])*
        pub struct $name:ident {
            $( $(#[$fmeta:meta])* pub $field:ident : $ty:ty = $default:expr, )*
        }
    ) => {
        $(#[$meta])*
        #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
        #[serde(deny_unknown_fields, default)]
        pub struct $name {
            $( $(#[$fmeta])* pub $field: $ty, )*
            /// Finger PD stiffness [N/m], a number or one per finger joint (`dof - arm_dof`): the fingers get
            /// `τ_f = gripper_kp·(q_target − q) − gripper_kd·q̇` under every controller. Default 50 (IsaacGymEnvs
            /// Pick/Place `ctrl.all`; Screw uses 100).
            pub gripper_kp: Gains,
            /// Finger PD damping [N s/m], a number or one per finger joint. Default 2 (Screw uses 1).
            pub gripper_kd: Gains,
            /// Every joint's torque [N m] (force [N] for the fingers) is clamped to ±torque_limit. Default 100
            /// (IsaacGymEnvs).
            pub torque_limit: f32,
            /// Optional per-joint effort limits [N m, N], length `dof`, applied on top of `torque_limit`
            /// (e.g. the Franka's 87 N m on joints 1-4 and 12 N m on joints 5-7, from its URDF).
            #[serde(skip_serializing_if = "Option::is_none")]
            pub effort_limit: Option<Vec<f32>>,
            /// Add the gravity torques g(q) to the arm's torques (default true). The real Franka compensates
            /// gravity in its firmware under libfranka torque control; IsaacGymEnvs instead turned gravity off on
            /// the arm. For joint-space ID and OSC, g is part of the law (eqs. 2, 4) and this flag is the
            /// ablation that drops it; it is never added twice.
            pub gravity_compensation: bool,
        }

        impl Default for $name {
            fn default() -> Self {
                $name {
                    $( $field: $default, )*
                    gripper_kp: Gains::All(DEFAULT_GRIPPER_KP),
                    gripper_kd: Gains::All(DEFAULT_GRIPPER_KD),
                    torque_limit: DEFAULT_TORQUE_LIMIT,
                    effort_limit: None,
                    gravity_compensation: true,
                }
            }
        }

        impl $name {
            /// The settings shared by every controller.
            pub fn common(&self) -> CommonSettings {
                CommonSettings {
                    gripper_kp: self.gripper_kp.clone(),
                    gripper_kd: self.gripper_kd.clone(),
                    torque_limit: self.torque_limit,
                    effort_limit: self.effort_limit.clone(),
                    gravity_compensation: self.gravity_compensation,
                }
            }
        }
    };
}

controller_config! {
    /// Joint-space inverse differential kinematics (paper eq. 1): `τ_arm = kp·Δq − kd·q̇`, Δq from the task
    /// error through `ik_method`. Defaults: IsaacGymEnvs `ctrl.joint_space_ik` (kp 1, kd 0.1, dls), tuned for an
    /// arm with gravity off and PhysX joint damping; expect to raise them on an undamped arm.
    pub struct JointSpaceIkConfig {
        /// Joint stiffness [N m/rad], a number or one per arm joint (`arm_dof`).
        pub kp: Gains = Gains::All(1.0),
        /// Joint damping [N m s/rad], a number or one per arm joint.
        pub kd: Gains = Gains::All(0.1),
        /// IK method: "pinv", "trans", "dls" or "svd".
        pub ik_method: IkMethod = IkMethod::Dls,
        /// Damping λ of `dls` [m] (mixed units: it is added as λ² to J Jᵀ). Default 0.1 (IsaacGymEnvs).
        pub dls_lambda: f32 = 0.1,
        /// Singular values below this are dropped by `svd` [m/rad]. Default 1e-5 (IsaacGymEnvs).
        pub svd_min_singular_value: f32 = 1e-5,
        /// "geometric" or "analytic" Jacobian (and the matching orientation error).
        pub jacobian: JacobianKind = JacobianKind::Geometric,
    }
}

controller_config! {
    /// Joint-space inverse dynamics (paper eq. 2): `τ_arm = M_arm·(kp·Δq − kd·q̇) + g`. Defaults: IsaacGymEnvs
    /// `ctrl.joint_space_id` (kp 40, kd 8, dls), the Pick/Place default controller.
    pub struct JointSpaceIdConfig {
        /// Joint stiffness [1/s²] (an acceleration per rad of error, since M scales it), a number or one per arm
        /// joint.
        pub kp: Gains = Gains::All(40.0),
        /// Joint damping [1/s], a number or one per arm joint.
        pub kd: Gains = Gains::All(8.0),
        /// IK method: "pinv", "trans", "dls" or "svd".
        pub ik_method: IkMethod = IkMethod::Dls,
        /// Damping λ of `dls` (added as λ² to J Jᵀ). Default 0.1.
        pub dls_lambda: f32 = 0.1,
        /// Singular values below this are dropped by `svd`. Default 1e-5.
        pub svd_min_singular_value: f32 = 1e-5,
        /// "geometric" or "analytic" Jacobian.
        pub jacobian: JacobianKind = JacobianKind::Geometric,
    }
}

controller_config! {
    /// Task-space impedance (paper eq. 3): `F = S_m (kp·e − kd·ẋ)`, `τ_arm = Jᵀ F`. Defaults: IsaacGymEnvs
    /// `ctrl.task_space_impedance` (kp 40, kd 8, all axes).
    pub struct TaskSpaceImpedanceConfig {
        /// Task stiffness, 6 values (x, y, z [N/m]; rx, ry, rz [N m/rad]) or one number.
        pub kp: Gains = Gains::All(40.0),
        /// Task damping, 6 values ([N s/m] ×3, [N m s/rad] ×3) or one number.
        pub kd: Gains = Gains::All(8.0),
        /// Motion selection S_m: 6 flags (0 or 1), 1 = the axis is motion-controlled.
        pub motion_axes: Gains = Gains::All(1.0),
        /// "geometric" or "analytic" Jacobian.
        pub jacobian: JacobianKind = JacobianKind::Geometric,
    }
}

controller_config! {
    /// Operational-space motion control (paper eq. 4): `F = S_m Λ (kp·e − kd·ẋ)` with the task-space inertia
    /// `Λ = (J M⁻¹ Jᵀ)⁻¹`, `τ_arm = Jᵀ F + g`. Defaults: IsaacGymEnvs `ctrl.operational_space_motion` (kp 1,
    /// kd 1, all axes; Screw uses axes [0,0,1,0,0,1] and kp rz 200).
    pub struct OscConfig {
        /// Task stiffness [1/s²] (an acceleration per unit of error, since Λ scales it), 6 values or one number.
        pub kp: Gains = Gains::All(1.0),
        /// Task damping [1/s], 6 values or one number.
        pub kd: Gains = Gains::All(1.0),
        /// Motion selection S_m: 6 flags (0 or 1).
        pub motion_axes: Gains = Gains::All(1.0),
        /// "geometric" or "analytic" Jacobian.
        pub jacobian: JacobianKind = JacobianKind::Geometric,
    }
}

controller_config! {
    /// Open-loop force control (paper eq. 5): `τ_arm = Jᵀ S_f F_target`. Default axes: z force only
    /// (IsaacGymEnvs `ctrl.open_loop_force`). Uses the geometric Jacobian (the wrench is physical).
    pub struct OpenLoopForceConfig {
        /// Force selection S_f: 6 flags (0 or 1) over (fx, fy, fz, tx, ty, tz).
        pub force_axes: Gains = Gains::Each(vec![0.0, 0.0, 1.0, 0.0, 0.0, 0.0]),
    }
}

controller_config! {
    /// Closed-loop P force control (paper eq. 6): `τ_arm = Jᵀ S_f (F_t + kf·(F_t − F_measured))`. Defaults:
    /// IsaacGymEnvs `ctrl.closed_loop_force` (z only, kf 0.1).
    pub struct ClosedLoopForceConfig {
        /// Force selection S_f: 6 flags (0 or 1).
        pub force_axes: Gains = Gains::Each(vec![0.0, 0.0, 1.0, 0.0, 0.0, 0.0]),
        /// Wrench error gain [dimensionless], 6 values or one number.
        pub kf: Gains = Gains::All(0.1),
    }
}

controller_config! {
    /// Hybrid force-motion control (paper eq. 7): `τ_arm = J_mᵀ S_m F_motion + Jᵀ S_f F_force (+ g)`, motion by
    /// OSC or impedance, force closed- or open-loop. Defaults: IsaacGymEnvs `ctrl.hybrid_force_motion` (OSC
    /// motion with kp 40 kd 8 on all but z, closed-loop force on z with kf 0.1).
    pub struct HybridForceMotionConfig {
        /// "osc" or "impedance".
        pub motion: MotionLaw = MotionLaw::Osc,
        /// Task stiffness, 6 values or one number ([1/s²] with OSC; [N/m], [N m/rad] with impedance).
        pub kp: Gains = Gains::All(40.0),
        /// Task damping, 6 values or one number ([1/s] with OSC; [N s/m], [N m s/rad] with impedance).
        pub kd: Gains = Gains::All(8.0),
        /// Motion selection S_m: 6 flags (0 or 1).
        pub motion_axes: Gains = Gains::Each(vec![1.0, 1.0, 0.0, 1.0, 1.0, 1.0]),
        /// "closed" or "open".
        pub force: ForceLaw = ForceLaw::Closed,
        /// Force selection S_f: 6 flags (0 or 1). Need not complement `motion_axes` (paper: "the axes need
        /// not be complementary").
        pub force_axes: Gains = Gains::Each(vec![0.0, 0.0, 1.0, 0.0, 0.0, 0.0]),
        /// Wrench error gain [dimensionless], 6 values or one number (closed-loop force only).
        pub kf: Gains = Gains::All(0.1),
        /// "geometric" or "analytic" Jacobian for the motion part (the force part always uses the geometric
        /// one).
        pub jacobian: JacobianKind = JacobianKind::Geometric,
    }
}

/// A controller config, selected by the TOML key `type` (see [`NAMES`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type")]
pub enum ControllerConfig {
    /// `type = "joint_space_ik"`
    #[serde(rename = "joint_space_ik")]
    JointSpaceIk(JointSpaceIkConfig),
    /// `type = "joint_space_id"`
    #[serde(rename = "joint_space_id")]
    JointSpaceId(JointSpaceIdConfig),
    /// `type = "task_space_impedance"`
    #[serde(rename = "task_space_impedance")]
    TaskSpaceImpedance(TaskSpaceImpedanceConfig),
    /// `type = "osc"` (or IsaacGymEnvs' name `"operational_space_motion"`)
    #[serde(rename = "osc", alias = "operational_space_motion")]
    Osc(OscConfig),
    /// `type = "open_loop_force"`
    #[serde(rename = "open_loop_force")]
    OpenLoopForce(OpenLoopForceConfig),
    /// `type = "closed_loop_force"`
    #[serde(rename = "closed_loop_force")]
    ClosedLoopForce(ClosedLoopForceConfig),
    /// `type = "hybrid_force_motion"`
    #[serde(rename = "hybrid_force_motion")]
    HybridForceMotion(HybridForceMotionConfig),
}

impl ControllerConfig {
    /// The registry name (`type`) of this config, one of [`NAMES`].
    pub fn name(&self) -> &'static str {
        match self {
            ControllerConfig::JointSpaceIk(_) => "joint_space_ik",
            ControllerConfig::JointSpaceId(_) => "joint_space_id",
            ControllerConfig::TaskSpaceImpedance(_) => "task_space_impedance",
            ControllerConfig::Osc(_) => "osc",
            ControllerConfig::OpenLoopForce(_) => "open_loop_force",
            ControllerConfig::ClosedLoopForce(_) => "closed_loop_force",
            ControllerConfig::HybridForceMotion(_) => "hybrid_force_motion",
        }
    }

    /// The default config of a controller by registry name (aliases accepted).
    pub fn default_for(name: &str) -> Result<Self> {
        Ok(match canonical_name(name).ok_or_else(|| ControllerError::UnknownType(name.to_string()))? {
            "joint_space_ik" => ControllerConfig::JointSpaceIk(Default::default()),
            "joint_space_id" => ControllerConfig::JointSpaceId(Default::default()),
            "task_space_impedance" => ControllerConfig::TaskSpaceImpedance(Default::default()),
            "osc" => ControllerConfig::Osc(Default::default()),
            "open_loop_force" => ControllerConfig::OpenLoopForce(Default::default()),
            "closed_loop_force" => ControllerConfig::ClosedLoopForce(Default::default()),
            "hybrid_force_motion" => ControllerConfig::HybridForceMotion(Default::default()),
            other => unreachable!("canonical_name returned unregistered `{other}`"),
        })
    }

    /// Reads a config from a TOML document whose top level is the controller table (`type = "..."`, gains...).
    ///
    /// The `type` is checked first so that an unknown one is reported as [`ControllerError::UnknownType`]
    /// with the valid names; everything else (unknown keys, wrong value types) is [`ControllerError::Parse`].
    pub fn from_toml_str(s: &str) -> Result<Self> {
        let table: toml::Table = toml::from_str(s).map_err(|e| ControllerError::Parse(e.to_string()))?;
        Self::from_toml_table(table)
    }

    /// As [`from_toml_str`](Self::from_toml_str), from an already parsed table (e.g. `[controller]` of a larger
    /// config).
    pub fn from_toml_table(table: toml::Table) -> Result<Self> {
        match table.get("type") {
            None => return Err(ControllerError::MissingType),
            Some(toml::Value::String(t)) if canonical_name(t).is_none() => {
                return Err(ControllerError::UnknownType(t.clone()))
            }
            Some(toml::Value::String(_)) => {}
            Some(other) => {
                return Err(ControllerError::Parse(format!(
                    "`type` must be a string, one of {}; got {other}",
                    NAMES.join(", ")
                )))
            }
        }
        toml::Value::Table(table).try_into().map_err(|e: toml::de::Error| ControllerError::Parse(e.to_string()))
    }
}

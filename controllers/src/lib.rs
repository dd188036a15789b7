//! factory-controllers: the robot controllers of Factory (Narang et al., "Factory: Fast Contact for Robotic
//! Assembly", RSS 2022, section IV-C and appendix D4), batched over worlds, on the CPU, in plain f32.
//!
//! Every controller acts on the fingertip frame (Factory's fingertip midpoint), writes torques for all `dof`
//! joints of every world, and shares three things around its law:
//!
//! - the fingers: `τ_f = gripper_kp·(q_target − q) − gripper_kd·q̇` (IsaacGymEnvs' gripper PD);
//! - gravity compensation: `+ g(q)` on the arm joints when `gravity_compensation` (default true);
//! - clamping: every joint to ±`torque_limit` (default 100, IsaacGymEnvs) and to `effort_limit` if given.
//!
//! | `type` | law (paper appendix D4) | module |
//! |---|---|---|
//! | `joint_space_ik` | eq. 1: `τ = kp·Δq − kd·q̇`, Δq by IK (pinv, trans, dls, svd) | [`joint_space`] |
//! | `joint_space_id` | eq. 2: `τ = M(kp·Δq − kd·q̇) + g` | [`joint_space`] |
//! | `task_space_impedance` | eq. 3: `τ = Jᵀ S_m (kp·e − kd·ẋ)` | [`task_space`] |
//! | `osc` | eq. 4: `τ = Jᵀ S_m Λ(kp·e − kd·ẋ) + g`, `Λ = (J M⁻¹ Jᵀ)⁻¹` | [`task_space`] |
//! | `open_loop_force` | eq. 5: `τ = Jᵀ S_f F_t` | [`task_space`] |
//! | `closed_loop_force` | eq. 6: `τ = Jᵀ S_f (F_t + kf·(F_t − F_c))` | [`task_space`] |
//! | `hybrid_force_motion` | eq. 7: OSC or impedance on S_m + open- or closed-loop force on S_f | [`task_space`] |
//!
//! The conventions (pose error, the analytic Jacobian, where selection and Λ apply, the IK methods, the
//! default gains) come from IsaacGymEnvs' `tasks/factory/factory_control.py` and the Factory task YAMLs,
//! re-derived and written anew here; [`rotation`] has the derivation of the analytic Jacobian's rate map.
//!
//! The robot's quantities (Jacobian, mass matrix, gravity torques, fingertip pose and twist) come in as plain
//! arrays in an [`ArmBatch`]; this crate does no kinematics or dynamics of its own. The dense linear algebra
//! ([`linalg`]) is small, fixed-size and allocation-free so it can move to a GPU kernel unchanged.
//!
//! ```
//! use factory_controllers::{build, ArmBatch, ControllerConfig, Targets};
//! let cfg = ControllerConfig::from_toml_str(r#"
//!     type = "osc"
//!     kp = [1, 1, 1, 1, 1, 200]
//!     motion_axes = [0, 0, 1, 0, 0, 1]
//!     gripper_kp = 100
//!     gripper_kd = 1
//! "#)?;
//! let ctrl = build(&cfg, 9, 7)?;
//! let mut arm = ArmBatch::zeros(4, 9, 7);
//! for w in 0..4 {
//!     for i in 0..9 {
//!         arm.mass_matrix[w * 81 + i * 9 + i] = 1.0;
//!     }
//!     for r in 0..6 {
//!         arm.ee_jacobian[w * 54 + r * 9 + r] = 1.0;
//!     }
//! }
//! let targets = Targets::hold(&arm);
//! let mut tau = vec![0.0; 4 * 9];
//! ctrl.compute(&arm, &targets, &mut tau);
//! assert!(tau.iter().all(|t| *t == 0.0)); // at the target, at rest, no gravity: no torque
//! # Ok::<(), factory_controllers::ControllerError>(())
//! ```

// Index loops and `!(x > y)` are deliberate: the kernels are written to port line by line to WGSL, and the
// negated comparisons are how NaN is sent down the safe branch.
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]
// Units and shapes are written in brackets ("[m]", "[world_count * dof]") as in the rest of the workspace;
// rustdoc would read them as links. Turn this off to check the real links (all resolved when this was written).
#![allow(rustdoc::broken_intra_doc_links)]

mod articulation;
mod batch;
mod common;
pub mod config;
mod error;
pub mod joint_space;
pub mod linalg;
mod registry;
pub mod rotation;
pub mod task_space;
pub mod task_space_gpu;

pub use batch::{ArmBatch, Targets};
pub use config::{
    ClosedLoopForceConfig, CommonSettings, ControllerConfig, ForceLaw, Gains, HybridForceMotionConfig, IkMethod,
    JointSpaceIdConfig, JointSpaceIkConfig, MotionLaw, OpenLoopForceConfig, OscConfig, TaskSpaceImpedanceConfig,
};
pub use error::{ControllerError, Result};
pub use joint_space::{IkSolver, JointSpaceController};
pub use registry::{build, canonical_name, ALIASES, NAMES};
pub use rotation::JacobianKind;
pub use task_space::TaskSpaceController;
pub use task_space_gpu::TaskSpaceGpu;

/// Largest arm (joints with a Jacobian column) the fixed-size linear algebra supports.
pub const MAX_ARM_DOF: usize = linalg::MAX_N;

/// A batched robot controller: one law, every world, one call.
///
/// Implementations are stateless between calls (the P/PD laws here need no integrator state), so one instance
/// serves any number of worlds; `compute` loops over worlds on the calling thread.
pub trait Controller: Send + Sync {
    /// The registry name (one of [`NAMES`]).
    fn name(&self) -> &'static str;

    /// Degrees of freedom per world the controller was built for.
    fn dof(&self) -> usize;

    /// Arm joints among them (the rest are gripper fingers).
    fn arm_dof(&self) -> usize;

    /// Whether the controller reads the wrench targets (`Targets::ee_wrench`) and measurements; a policy's
    /// force/torque actions matter only then (IsaacGymEnvs uses them only when doing force control).
    fn does_force_control(&self) -> bool {
        false
    }

    /// Whether the controller tracks the pose targets (`Targets::ee_pos`, `Targets::ee_quat`).
    fn does_motion_control(&self) -> bool {
        true
    }

    /// Writes joint torques [N m, N] for every world, shape [world_count * dof] (all dof, fingers included).
    ///
    /// # Panics
    /// If the batch's `dof`/`arm_dof` differ from the controller's, or a buffer has the wrong length (the
    /// message names it).
    fn compute(&self, arm: &ArmBatch, targets: &Targets, joint_tau: &mut [f32]);

    /// Hook: the controller as a task-space law, which has a device kernel ([`TaskSpaceGpu`]); None (the
    /// default) for the others.
    fn as_task_space(&self) -> Option<&TaskSpaceController> {
        None
    }
}

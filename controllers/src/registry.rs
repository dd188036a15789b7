//! The explicit controller registry: names, aliases and [`build`].

use crate::config::ControllerConfig;
use crate::error::Result;
use crate::joint_space::JointSpaceController;
use crate::task_space::TaskSpaceController;
use crate::Controller;

/// The registered controllers' `type` names, in the paper's order (appendix D4 eqs. 1-7).
pub const NAMES: &[&str] = &[
    "joint_space_ik",
    "joint_space_id",
    "task_space_impedance",
    "osc",
    "open_loop_force",
    "closed_loop_force",
    "hybrid_force_motion",
];

/// Other accepted `type` names and the registered name each stands for (IsaacGymEnvs' `ctrl_type` spelling).
pub const ALIASES: &[(&str, &str)] = &[("operational_space_motion", "osc")];

/// The registered name for `name` (itself or the target of an alias), or None if unknown.
pub fn canonical_name(name: &str) -> Option<&'static str> {
    NAMES.iter().copied().find(|n| *n == name).or_else(|| ALIASES.iter().find(|(a, _)| *a == name).map(|(_, n)| *n))
}

/// Builds the controller a config describes, for a robot with `dof` joints of which the first `arm_dof` are the
/// arm (the rest gripper fingers). Checks every vector's length (naming the config field), gains >= 0 and
/// finite, axis flags 0 or 1, and `1 <= arm_dof <= MAX_ARM_DOF`.
pub fn build(cfg: &ControllerConfig, dof: usize, arm_dof: usize) -> Result<Box<dyn Controller>> {
    Ok(match cfg {
        ControllerConfig::JointSpaceIk(c) => Box::new(JointSpaceController::ik(c, dof, arm_dof)?),
        ControllerConfig::JointSpaceId(c) => Box::new(JointSpaceController::id(c, dof, arm_dof)?),
        ControllerConfig::TaskSpaceImpedance(c) => Box::new(TaskSpaceController::impedance(c, dof, arm_dof)?),
        ControllerConfig::Osc(c) => Box::new(TaskSpaceController::osc(c, dof, arm_dof)?),
        ControllerConfig::OpenLoopForce(c) => Box::new(TaskSpaceController::open_loop_force(c, dof, arm_dof)?),
        ControllerConfig::ClosedLoopForce(c) => Box::new(TaskSpaceController::closed_loop_force(c, dof, arm_dof)?),
        ControllerConfig::HybridForceMotion(c) => Box::new(TaskSpaceController::hybrid(c, dof, arm_dof)?),
    })
}

//! Joint-space controllers: inverse differential kinematics (paper eq. 1) and inverse dynamics (eq. 2).
//!
//! Both turn the 6-D fingertip error e into a joint error Δq with an IK method on the arm's 6 x arm_dof
//! Jacobian (geometric or analytic), then apply joint-space PD:
//!
//! ```text
//! eq. 1 (IK):  τ_arm = kp·Δq − kd·q̇                      (+ g if gravity_compensation)
//! eq. 2 (ID):  τ_arm = M_arm·(kp·Δq − kd·q̇) + b + g      (b, Coriolis/centrifugal, ignored as the paper does:
//!                                                          "small joint velocities during assembly")
//! ```
//!
//! M_arm is the arm block of the mass matrix (the fingers are driven by their own PD). The IK methods follow
//! IsaacGymEnvs' `factory_control._get_delta_dof_pos` (see [`IkMethod`]).

use crate::batch::{ArmBatch, Targets};
use crate::common::{arm_jacobian, arm_mass, nonneg_gains, task_state, Common};
use crate::config::{IkMethod, JointSpaceIdConfig, JointSpaceIkConfig};
use crate::error::{ControllerError, Result};
use crate::linalg::{mat_t_vec, mat_vec, solve_spd, svd_6xn, MAX_N};
use crate::rotation::JacobianKind;
use crate::Controller;

/// An IK method with its parameters: maps a 6-D task error to a joint error.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IkSolver {
    /// The method.
    pub method: IkMethod,
    /// λ of damped least squares.
    pub dls_lambda: f32,
    /// Singular-value cutoff of the adaptive SVD method.
    pub svd_min_singular_value: f32,
}

impl Default for IkSolver {
    fn default() -> Self {
        IkSolver { method: IkMethod::Dls, dls_lambda: 0.1, svd_min_singular_value: 1e-5 }
    }
}

impl IkSolver {
    /// Δq (first `n` entries) for the task error `e` through the 6 x n row-major Jacobian `j` (n <= 9).
    pub fn delta_q(&self, j: &[f32], n: usize, e: &[f32; 6]) -> [f32; MAX_N] {
        let mut dq = [0.0f32; MAX_N];
        match self.method {
            IkMethod::Trans => mat_t_vec(j, 6, n, e, &mut dq),
            IkMethod::Dls => {
                // (J Jᵀ + λ² I) y = e, Δq = Jᵀ y: a 6x6 SPD solve however many joints the arm has.
                let mut a = [0.0f32; 36];
                for r in 0..6 {
                    for c in 0..=r {
                        let mut s = 0.0f32;
                        for k in 0..n {
                            s += j[r * n + k] * j[c * n + k];
                        }
                        a[r * 6 + c] = s;
                        a[c * 6 + r] = s;
                    }
                    a[r * 6 + r] += self.dls_lambda * self.dls_lambda;
                }
                let mut y = *e;
                solve_spd(&a, 6, &mut y);
                mat_t_vec(j, 6, n, &y, &mut dq);
            }
            IkMethod::Pinv => {
                let svd = svd_6xn(j, n);
                dq = svd.solve(e, svd.default_pinv_cutoff());
            }
            IkMethod::Svd => {
                let svd = svd_6xn(j, n);
                dq = svd.solve(e, self.svd_min_singular_value);
            }
        }
        dq
    }
}

/// Joint-space IK (eq. 1) or ID (eq. 2) controller; built by [`crate::build`] from a [`JointSpaceIkConfig`] or
/// [`JointSpaceIdConfig`].
#[derive(Debug, Clone)]
pub struct JointSpaceController {
    name: &'static str,
    common: Common,
    kp: Vec<f32>,
    kd: Vec<f32>,
    ik: IkSolver,
    jacobian: JacobianKind,
    /// Premultiply by M_arm (ID) or not (IK).
    inertial: bool,
}

fn ik_solver(method: IkMethod, dls_lambda: f32, svd_min: f32) -> Result<IkSolver> {
    if !(dls_lambda.is_finite() && dls_lambda >= 0.0) {
        return Err(ControllerError::InvalidValue {
            field: "dls_lambda",
            reason: format!("must be finite and >= 0, got {dls_lambda}"),
        });
    }
    if !(svd_min.is_finite() && svd_min >= 0.0) {
        return Err(ControllerError::InvalidValue {
            field: "svd_min_singular_value",
            reason: format!("must be finite and >= 0, got {svd_min}"),
        });
    }
    Ok(IkSolver { method, dls_lambda, svd_min_singular_value: svd_min })
}

impl JointSpaceController {
    /// Joint-space inverse differential kinematics (eq. 1).
    pub fn ik(cfg: &JointSpaceIkConfig, dof: usize, arm_dof: usize) -> Result<Self> {
        let common = Common::new(&cfg.common(), dof, arm_dof)?;
        Ok(JointSpaceController {
            name: "joint_space_ik",
            kp: nonneg_gains(&cfg.kp, "kp", arm_dof)?,
            kd: nonneg_gains(&cfg.kd, "kd", arm_dof)?,
            ik: ik_solver(cfg.ik_method, cfg.dls_lambda, cfg.svd_min_singular_value)?,
            jacobian: cfg.jacobian,
            inertial: false,
            common,
        })
    }

    /// Joint-space inverse dynamics (eq. 2).
    pub fn id(cfg: &JointSpaceIdConfig, dof: usize, arm_dof: usize) -> Result<Self> {
        let common = Common::new(&cfg.common(), dof, arm_dof)?;
        Ok(JointSpaceController {
            name: "joint_space_id",
            kp: nonneg_gains(&cfg.kp, "kp", arm_dof)?,
            kd: nonneg_gains(&cfg.kd, "kd", arm_dof)?,
            ik: ik_solver(cfg.ik_method, cfg.dls_lambda, cfg.svd_min_singular_value)?,
            jacobian: cfg.jacobian,
            inertial: true,
            common,
        })
    }

    /// The IK method in use.
    pub fn ik_solver(&self) -> &IkSolver {
        &self.ik
    }

    /// World `w`'s joint error Δq (first `arm_dof` entries): the task error through the IK method.
    pub fn delta_q(&self, arm: &ArmBatch, targets: &Targets, w: usize) -> [f32; MAX_N] {
        let mut j = arm_jacobian(arm, w);
        let (e, _) = task_state(arm, targets, w, self.jacobian, &mut j);
        self.ik.delta_q(&j, arm.arm_dof, &e)
    }
}

impl Controller for JointSpaceController {
    fn name(&self) -> &'static str {
        self.name
    }

    fn dof(&self) -> usize {
        self.common.dof
    }

    fn arm_dof(&self) -> usize {
        self.common.arm_dof
    }

    fn compute(&self, arm: &ArmBatch, targets: &Targets, joint_tau: &mut [f32]) {
        self.common.check_call(self.name, arm, targets, joint_tau);
        let (d, na) = (arm.dof, arm.arm_dof);
        for w in 0..arm.world_count {
            let dq = self.delta_q(arm, targets, w);
            let qd = &arm.joint_qd[w * d..w * d + na];
            let mut a = [0.0f32; MAX_N];
            for i in 0..na {
                a[i] = self.kp[i] * dq[i] - self.kd[i] * qd[i];
            }
            let tau = &mut joint_tau[w * d..(w + 1) * d];
            if self.inertial {
                let m = arm_mass(arm, w);
                mat_vec(&m, na, na, &a, &mut tau[..na]);
            } else {
                tau[..na].copy_from_slice(&a[..na]);
            }
            self.common.finish(w, arm, targets, tau);
        }
    }
}

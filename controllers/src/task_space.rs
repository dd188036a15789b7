//! Task-space controllers: impedance (paper eq. 3), operational-space motion (eq. 4), open-loop force (eq. 5),
//! closed-loop P force (eq. 6) and hybrid force-motion (eq. 7), all as one law with optional parts:
//!
//! ```text
//! motion:  f = kp∘e − kd∘ẋ                      impedance (eq. 3)
//!          f = Λ (kp∘e − kd∘ẋ),  Λ = (J M⁻¹ Jᵀ)⁻¹  OSC (eq. 4; the paper writes M for Λ)
//!          F_m = S_m f
//! force:   F_f = S_f F_t                         open loop (eq. 5)
//!          F_f = S_f (F_t + kf∘(F_t − F_c))      closed loop (eq. 6)
//! torque:  τ_arm = J_mᵀ F_m + J_gᵀ F_f (+ g)      hybrid (eq. 7) when both parts are present
//! ```
//!
//! J is the arm's 6 x arm_dof block and M the arm block of the mass matrix (IsaacGymEnvs does the same). The
//! selection is applied after Λ, as in IsaacGymEnvs' `compute_dof_torque`, so that a deselected axis gets no
//! motion wrench at all (Λ couples axes: selecting before it would still push along deselected axes, which
//! would fight the force part of the hybrid law). Coriolis and
//! centrifugal terms b are ignored as the paper does. With the analytic Jacobian the motion part uses `J_a`
//! (its wrench is conjugate to axis-angle rates) and the force part keeps the geometric J (the target wrench
//! is a physical one); IsaacGymEnvs uses one Jacobian for both, which is the same in the default geometric
//! case.
//!
//! F_c is [`ArmBatch::ee_wrench`], the wrench the fingertips apply (IsaacGymEnvs: `−(F_left + F_right)`, zero
//! torque).

use crate::batch::{ArmBatch, Targets};
use crate::common::{arm_jacobian, arm_mass, axes, task_gains, task_state, Common};
use crate::config::{
    ClosedLoopForceConfig, ForceLaw, HybridForceMotionConfig, MotionLaw, OpenLoopForceConfig, OscConfig,
    TaskSpaceImpedanceConfig,
};
use crate::error::Result;
use crate::linalg::{cholesky_factor, cholesky_solve_factored, mat_t_vec, solve_spd6, MAX_N};
use crate::rotation::JacobianKind;
use crate::Controller;

/// The motion part of a task-space law.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionPart {
    /// Task stiffness per axis.
    pub kp: [f32; 6],
    /// Task damping per axis.
    pub kd: [f32; 6],
    /// S_m: 1 on motion-controlled axes, 0 elsewhere.
    pub axes: [f32; 6],
    /// Scale by the task-space inertia Λ (OSC) or not (impedance).
    pub inertial: bool,
    /// Geometric or analytic Jacobian.
    pub jacobian: JacobianKind,
}

/// The force part of a task-space law.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForcePart {
    /// S_f: 1 on force-controlled axes, 0 elsewhere.
    pub axes: [f32; 6],
    /// `Some(kf)`: closed loop; `None`: open loop.
    pub kf: Option<[f32; 6]>,
}

/// A task-space controller: impedance, OSC, open-/closed-loop force or hybrid, depending on its parts. Built by
/// [`crate::build`].
#[derive(Debug, Clone)]
pub struct TaskSpaceController {
    name: &'static str,
    common: Common,
    motion: Option<MotionPart>,
    force: Option<ForcePart>,
}

impl TaskSpaceController {
    /// Task-space impedance (eq. 3).
    pub fn impedance(cfg: &TaskSpaceImpedanceConfig, dof: usize, arm_dof: usize) -> Result<Self> {
        Ok(TaskSpaceController {
            name: "task_space_impedance",
            common: Common::new(&cfg.common(), dof, arm_dof)?,
            motion: Some(MotionPart {
                kp: task_gains(&cfg.kp, "kp")?,
                kd: task_gains(&cfg.kd, "kd")?,
                axes: axes(&cfg.motion_axes, "motion_axes")?,
                inertial: false,
                jacobian: cfg.jacobian,
            }),
            force: None,
        })
    }

    /// Operational-space motion control (eq. 4).
    pub fn osc(cfg: &OscConfig, dof: usize, arm_dof: usize) -> Result<Self> {
        Ok(TaskSpaceController {
            name: "osc",
            common: Common::new(&cfg.common(), dof, arm_dof)?,
            motion: Some(MotionPart {
                kp: task_gains(&cfg.kp, "kp")?,
                kd: task_gains(&cfg.kd, "kd")?,
                axes: axes(&cfg.motion_axes, "motion_axes")?,
                inertial: true,
                jacobian: cfg.jacobian,
            }),
            force: None,
        })
    }

    /// Open-loop force control (eq. 5).
    pub fn open_loop_force(cfg: &OpenLoopForceConfig, dof: usize, arm_dof: usize) -> Result<Self> {
        Ok(TaskSpaceController {
            name: "open_loop_force",
            common: Common::new(&cfg.common(), dof, arm_dof)?,
            motion: None,
            force: Some(ForcePart { axes: axes(&cfg.force_axes, "force_axes")?, kf: None }),
        })
    }

    /// Closed-loop P force control (eq. 6).
    pub fn closed_loop_force(cfg: &ClosedLoopForceConfig, dof: usize, arm_dof: usize) -> Result<Self> {
        Ok(TaskSpaceController {
            name: "closed_loop_force",
            common: Common::new(&cfg.common(), dof, arm_dof)?,
            motion: None,
            force: Some(ForcePart { axes: axes(&cfg.force_axes, "force_axes")?, kf: Some(task_gains(&cfg.kf, "kf")?) }),
        })
    }

    /// Hybrid force-motion control (eq. 7).
    pub fn hybrid(cfg: &HybridForceMotionConfig, dof: usize, arm_dof: usize) -> Result<Self> {
        Ok(TaskSpaceController {
            name: "hybrid_force_motion",
            common: Common::new(&cfg.common(), dof, arm_dof)?,
            motion: Some(MotionPart {
                kp: task_gains(&cfg.kp, "kp")?,
                kd: task_gains(&cfg.kd, "kd")?,
                axes: axes(&cfg.motion_axes, "motion_axes")?,
                inertial: cfg.motion == MotionLaw::Osc,
                jacobian: cfg.jacobian,
            }),
            force: Some(ForcePart {
                axes: axes(&cfg.force_axes, "force_axes")?,
                kf: match cfg.force {
                    ForceLaw::Closed => Some(task_gains(&cfg.kf, "kf")?),
                    ForceLaw::Open => None,
                },
            }),
        })
    }

    /// The motion part, if any.
    pub fn motion(&self) -> Option<&MotionPart> {
        self.motion.as_ref()
    }

    /// The force part, if any.
    pub fn force(&self) -> Option<&ForcePart> {
        self.force.as_ref()
    }

    /// What it does around its law (the finger PD, gravity compensation, limits).
    pub(crate) fn common(&self) -> &Common {
        &self.common
    }

    /// World `w`'s arm torques (first `arm_dof` entries of `tau`) before gravity, fingers and clamping.
    fn arm_torque(&self, arm: &ArmBatch, targets: &Targets, w: usize, tau: &mut [f32]) {
        let na = arm.arm_dof;
        let jg = arm_jacobian(arm, w);
        tau[..na].fill(0.0);
        let mut part = [0.0f32; MAX_N];
        if let Some(m) = &self.motion {
            let mut j = jg;
            let (e, xd) = task_state(arm, targets, w, m.jacobian, &mut j);
            let mut f = [0.0f32; 6];
            for i in 0..6 {
                f[i] = m.kp[i] * e[i] - m.kd[i] * xd[i];
            }
            if m.inertial {
                f = task_inertia_times(&j, &arm_mass(arm, w), na, f);
            }
            for i in 0..6 {
                f[i] *= m.axes[i];
            }
            mat_t_vec(&j, 6, na, &f, &mut part);
            for i in 0..na {
                tau[i] += part[i];
            }
        }
        if let Some(fp) = &self.force {
            let ft = targets.ee_wrench[w];
            let fc = arm.ee_wrench[w];
            let mut f = [0.0f32; 6];
            for i in 0..6 {
                let closed = match &fp.kf {
                    Some(kf) => kf[i] * (ft[i] - fc[i]),
                    None => 0.0,
                };
                f[i] = fp.axes[i] * (ft[i] + closed);
            }
            mat_t_vec(&jg, 6, na, &f, &mut part);
            for i in 0..na {
                tau[i] += part[i];
            }
        }
    }
}

/// `Λ f = (J M⁻¹ Jᵀ)⁻¹ f` for the 6 x n Jacobian `j` and n x n SPD `m`, without forming either inverse: one
/// Cholesky of M, six triangular solves for `M⁻¹ Jᵀ`, then a regularised 6x6 SPD solve (see
/// [`crate::linalg::SPD6_REGULARISER`]: it keeps Λ finite at singular arm configurations).
pub fn task_inertia_times(j: &[f32], m: &[f32], n: usize, f: [f32; 6]) -> [f32; 6] {
    let mut l = [0.0f32; MAX_N * MAX_N];
    l[..n * n].copy_from_slice(&m[..n * n]);
    cholesky_factor(&mut l, n);
    // x_r = M⁻¹ (row r of J)ᵀ, so A[r][c] = J_c · x_r.
    let mut x = [[0.0f32; MAX_N]; 6];
    for (r, xr) in x.iter_mut().enumerate() {
        xr[..n].copy_from_slice(&j[r * n..(r + 1) * n]);
        cholesky_solve_factored(&l, n, xr);
    }
    let mut a = [0.0f32; 36];
    for r in 0..6 {
        for c in 0..=r {
            let mut s = 0.0f32;
            for k in 0..n {
                s += j[c * n + k] * x[r][k];
            }
            a[r * 6 + c] = s;
            a[c * 6 + r] = s;
        }
    }
    let mut y = f;
    solve_spd6(&a, &mut y);
    y
}

impl Controller for TaskSpaceController {
    fn name(&self) -> &'static str {
        self.name
    }

    fn dof(&self) -> usize {
        self.common.dof
    }

    fn arm_dof(&self) -> usize {
        self.common.arm_dof
    }

    fn does_force_control(&self) -> bool {
        self.force.is_some()
    }

    fn does_motion_control(&self) -> bool {
        self.motion.is_some()
    }

    fn compute(&self, arm: &ArmBatch, targets: &Targets, joint_tau: &mut [f32]) {
        self.common.check_call(self.name, arm, targets, joint_tau);
        let d = arm.dof;
        for w in 0..arm.world_count {
            let tau = &mut joint_tau[w * d..(w + 1) * d];
            self.arm_torque(arm, targets, w, tau);
            self.common.finish(w, arm, targets, tau);
        }
    }

    fn as_task_space(&self) -> Option<&TaskSpaceController> {
        Some(self)
    }
}

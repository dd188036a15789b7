//! The seven control laws checked against their equations (paper appendix D4) on synthetic robots: random SPD
//! mass matrices, random Jacobians, random states. The reference side is computed here in f64 with its own
//! Gaussian elimination, independent of the crate's linear algebra.
#![allow(clippy::needless_range_loop)]

use factory_controllers::config::*;
use factory_controllers::rotation::{axis_angle_from_quat, axis_angle_rate_map_inverse, pose_error};
use factory_controllers::{build, ArmBatch, Controller, ControllerConfig, JacobianKind, JointSpaceController, Targets};
use glam::{Quat, Vec3};

const DOF: usize = 9;
const NA: usize = 7;
const W: usize = 3;
const BIG: f32 = 1e9;

struct Rng(u64);
impl Rng {
    fn new(seed: u64) -> Self {
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }
    /// Uniform in [-1, 1).
    fn next(&mut self) -> f32 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let x = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D);
        ((x >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
    }
    fn vec3(&mut self) -> Vec3 {
        Vec3::new(self.next(), self.next(), self.next())
    }
    fn quat(&mut self) -> Quat {
        Quat::from_xyzw(self.next(), self.next(), self.next(), self.next()).normalize()
    }
}

/// Worlds with a fully coupled random SPD 9x9 M, a random 6x9 J, random joint state, fingertip pose and twist,
/// zero gravity, and random targets near the current pose.
fn random_batch(seed: u64) -> (ArmBatch, Targets) {
    let mut rng = Rng::new(seed);
    let mut arm = ArmBatch::zeros(W, DOF, NA);
    for w in 0..W {
        let mut b = [0.0f32; DOF * DOF];
        b.iter_mut().for_each(|x| *x = rng.next());
        for i in 0..DOF {
            for j in 0..DOF {
                let s: f32 = (0..DOF).map(|k| b[i * DOF + k] * b[j * DOF + k]).sum();
                arm.mass_matrix[w * DOF * DOF + i * DOF + j] = 0.3 * s + if i == j { 1.0 } else { 0.0 };
            }
        }
        // Diagonally dominant so the arm is away from singularities (cond J ~ 3): the checks below are of the
        // laws, not of how f32 copes with a near-singular arm.
        for r in 0..6 {
            for c in 0..DOF {
                arm.ee_jacobian[w * 6 * DOF + r * DOF + c] = rng.next() + if r == c { 2.0 } else { 0.0 };
            }
        }
        arm.joint_q[w * DOF..(w + 1) * DOF].iter_mut().for_each(|x| *x = rng.next());
        arm.joint_qd[w * DOF..(w + 1) * DOF].iter_mut().for_each(|x| *x = rng.next());
        arm.ee_pos[w] = rng.vec3();
        arm.ee_quat[w] = rng.quat();
        arm.ee_linvel[w] = rng.vec3() * 0.3;
        arm.ee_angvel[w] = rng.vec3() * 0.5;
        arm.ee_wrench[w] = std::array::from_fn(|_| rng.next() * 5.0);
    }
    let mut t = Targets::zeros(W, DOF - NA);
    for w in 0..W {
        t.ee_pos[w] = arm.ee_pos[w] + rng.vec3() * 0.05;
        t.ee_quat[w] = Quat::from_scaled_axis(rng.vec3() * 0.2) * arm.ee_quat[w];
        t.ee_wrench[w] = std::array::from_fn(|_| rng.next() * 10.0);
        t.gripper_q[w * 2] = 0.02 + 0.01 * rng.next();
        t.gripper_q[w * 2 + 1] = 0.02 + 0.01 * rng.next();
    }
    (arm, t)
}

fn compute(ctrl: &dyn Controller, arm: &ArmBatch, t: &Targets) -> Vec<f32> {
    let mut tau = vec![f32::NAN; arm.world_count * arm.dof];
    ctrl.compute(arm, t, &mut tau);
    tau
}

/// f64 Gaussian elimination with partial pivoting: solves A x = b, A n x n row-major.
fn solve64(a: &[f64], b: &[f64]) -> Vec<f64> {
    let n = b.len();
    let mut m: Vec<Vec<f64>> = (0..n).map(|i| a[i * n..(i + 1) * n].to_vec()).collect();
    let mut x = b.to_vec();
    for c in 0..n {
        let p = (c..n).max_by(|&i, &j| m[i][c].abs().total_cmp(&m[j][c].abs())).unwrap();
        m.swap(c, p);
        x.swap(c, p);
        for r in c + 1..n {
            let f = m[r][c] / m[c][c];
            for k in c..n {
                m[r][k] -= f * m[c][k];
            }
            x[r] -= f * x[c];
        }
    }
    for r in (0..n).rev() {
        let s: f64 = (r + 1..n).map(|k| m[r][k] * x[k]).sum();
        x[r] = (x[r] - s) / m[r][r];
    }
    x
}

fn arm_j64(arm: &ArmBatch, w: usize) -> Vec<f64> {
    let mut j = vec![0.0; 6 * NA];
    for r in 0..6 {
        for c in 0..NA {
            j[r * NA + c] = arm.ee_jacobian[w * 6 * DOF + r * DOF + c] as f64;
        }
    }
    j
}

fn arm_m64(arm: &ArmBatch, w: usize) -> Vec<f64> {
    let mut m = vec![0.0; NA * NA];
    for r in 0..NA {
        for c in 0..NA {
            m[r * NA + c] = arm.mass_matrix[w * DOF * DOF + r * DOF + c] as f64;
        }
    }
    m
}

fn tau_arm64(tau: &[f32], w: usize) -> Vec<f64> {
    tau[w * DOF..w * DOF + NA].iter().map(|&x| x as f64).collect()
}

/// Task error and twist of world w (geometric).
fn e_xd(arm: &ArmBatch, t: &Targets, w: usize) -> ([f32; 6], [f32; 6]) {
    let e = pose_error(t.ee_pos[w], t.ee_quat[w], arm.ee_pos[w], arm.ee_quat[w], JacobianKind::Geometric);
    let (v, o) = (arm.ee_linvel[w], arm.ee_angvel[w]);
    (e, [v.x, v.y, v.z, o.x, o.y, o.z])
}

/// J M⁻¹ τ (the task acceleration the arm torques produce, b and g aside), in f64.
fn task_accel(arm: &ArmBatch, tau: &[f32], w: usize) -> Vec<f64> {
    let j = arm_j64(arm, w);
    let qdd = solve64(&arm_m64(arm, w), &tau_arm64(tau, w));
    (0..6).map(|r| (0..NA).map(|c| j[r * NA + c] * qdd[c]).sum()).collect()
}

/// The task wrench F with τ_arm = Jᵀ F, recovered by least squares F = (J Jᵀ)⁻¹ J τ (J has full row rank).
fn task_wrench(arm: &ArmBatch, tau: &[f32], w: usize) -> Vec<f64> {
    let j = arm_j64(arm, w);
    let t = tau_arm64(tau, w);
    let mut jjt = vec![0.0; 36];
    for r in 0..6 {
        for c in 0..6 {
            jjt[r * 6 + c] = (0..NA).map(|k| j[r * NA + k] * j[c * NA + k]).sum();
        }
    }
    let jt: Vec<f64> = (0..6).map(|r| (0..NA).map(|k| j[r * NA + k] * t[k]).sum()).collect();
    solve64(&jjt, &jt)
}

fn rel_err(a: &[f64], b: &[f64]) -> f64 {
    let num = a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>().sqrt();
    let den = b.iter().map(|y| y * y).sum::<f64>().sqrt().max(1e-12);
    num / den
}

fn no_limits_osc(kp: Gains, kd: Gains, axes: Gains) -> OscConfig {
    OscConfig { kp, kd, motion_axes: axes, torque_limit: BIG, gravity_compensation: false, ..Default::default() }
}

#[test]
fn osc_produces_the_commanded_task_acceleration() {
    let (arm, t) = random_batch(1);
    let kp = vec![30.0, 20.0, 40.0, 5.0, 8.0, 12.0];
    let kd = vec![6.0, 4.0, 9.0, 1.0, 2.0, 3.0];
    let cfg = ControllerConfig::Osc(no_limits_osc(kp.clone().into(), kd.clone().into(), Gains::All(1.0)));
    let ctrl = build(&cfg, DOF, NA).unwrap();
    assert_eq!(ctrl.name(), "osc");
    let tau = compute(ctrl.as_ref(), &arm, &t);
    for w in 0..W {
        let (e, xd) = e_xd(&arm, &t, w);
        let cmd: Vec<f64> = (0..6).map(|i| (kp[i] * e[i] - kd[i] * xd[i]) as f64).collect();
        let acc = task_accel(&arm, &tau, w);
        let err = rel_err(&acc, &cmd);
        assert!(err < 1e-4, "world {w}: J M⁻¹ τ = {acc:?}, commanded {cmd:?} (rel err {err:e})");
    }
}

#[test]
fn osc_selection_zeroes_the_wrench_on_deselected_axes() {
    let (arm, t) = random_batch(2);
    let kp = vec![30.0, 20.0, 40.0, 5.0, 8.0, 12.0];
    let kd = vec![6.0, 4.0, 9.0, 1.0, 2.0, 3.0];
    let z_only = Gains::Each(vec![0.0, 0.0, 1.0, 0.0, 0.0, 0.0]);
    let ctrl =
        build(&ControllerConfig::Osc(no_limits_osc(kp.clone().into(), kd.clone().into(), z_only)), DOF, NA).unwrap();
    let all = build(&ControllerConfig::Osc(no_limits_osc(kp.into(), kd.into(), Gains::All(1.0))), DOF, NA).unwrap();
    let tau = compute(ctrl.as_ref(), &arm, &t);
    let tau_all = compute(all.as_ref(), &arm, &t);
    for w in 0..W {
        let f = task_wrench(&arm, &tau, w);
        let f_all = task_wrench(&arm, &tau_all, w);
        assert!(f[2].abs() > 1e-3, "world {w}: no z wrench {f:?}");
        // The z entry is the z entry of the full Λ(kp e − kd ẋ); the others are zero.
        assert!((f[2] - f_all[2]).abs() < 1e-4 * f_all[2].abs().max(1.0), "world {w}: {} vs {}", f[2], f_all[2]);
        for i in [0, 1, 3, 4, 5] {
            assert!(f[i].abs() < 1e-4 * f[2].abs(), "world {w}: wrench {f:?} not zero on axis {i}");
            // ...where Λ does couple the axes (so this could fail if selection came before Λ).
            assert!(f_all[i].abs() > 1e-3, "world {w}: axis {i} of the full wrench is ~0: {f_all:?}");
        }
    }
}

#[test]
fn joint_space_id_produces_the_commanded_joint_acceleration() {
    let (arm, t) = random_batch(3);
    let kp = vec![40.0, 35.0, 30.0, 25.0, 20.0, 15.0, 10.0];
    let kd = vec![8.0, 7.0, 6.0, 5.0, 4.0, 3.0, 2.0];
    let common = |c: &mut JointSpaceIdConfig| {
        c.torque_limit = BIG;
        c.gravity_compensation = false;
    };
    let mut cfg = JointSpaceIdConfig {
        kp: kp.clone().into(),
        kd: kd.clone().into(),
        ik_method: IkMethod::Pinv,
        ..Default::default()
    };
    common(&mut cfg);
    let id = JointSpaceController::id(&cfg, DOF, NA).unwrap();
    let tau = compute(&id, &arm, &t);
    for w in 0..W {
        let dq = id.delta_q(&arm, &t, w);
        let qdd = solve64(&arm_m64(&arm, w), &tau_arm64(&tau, w));
        let cmd: Vec<f64> = (0..NA).map(|i| (kp[i] * dq[i] - kd[i] * arm.joint_qd[w * DOF + i]) as f64).collect();
        let err = rel_err(&qdd, &cmd);
        assert!(err < 1e-4, "world {w}: M⁻¹τ {qdd:?} vs {cmd:?}");
        // With pinv on a full-rank 6x7 J, Δq reproduces the task error: J Δq = e.
        let (e, _) = e_xd(&arm, &t, w);
        let j = arm_j64(&arm, w);
        let jdq: Vec<f64> = (0..6).map(|r| (0..NA).map(|c| j[r * NA + c] * dq[c] as f64).sum()).collect();
        let e64: Vec<f64> = e.iter().map(|&x| x as f64).collect();
        assert!(rel_err(&jdq, &e64) < 1e-4, "J Δq {jdq:?} vs e {e64:?}");
    }
    // ID = M_arm · IK with the same gains and IK method.
    let ik = JointSpaceController::ik(
        &JointSpaceIkConfig {
            kp: kp.into(),
            kd: kd.into(),
            ik_method: IkMethod::Pinv,
            torque_limit: BIG,
            gravity_compensation: false,
            ..Default::default()
        },
        DOF,
        NA,
    )
    .unwrap();
    let tau_ik = compute(&ik, &arm, &t);
    for w in 0..W {
        let m = arm_m64(&arm, w);
        let ik64 = tau_arm64(&tau_ik, w);
        let expect: Vec<f64> = (0..NA).map(|r| (0..NA).map(|c| m[r * NA + c] * ik64[c]).sum()).collect();
        assert!(rel_err(&tau_arm64(&tau, w), &expect) < 1e-5);
    }
}

#[test]
fn open_loop_force_is_jacobian_transpose_of_selected_target() {
    let (arm, t) = random_batch(4);
    let axes = vec![1.0, 0.0, 1.0, 0.0, 0.0, 1.0];
    let cfg = OpenLoopForceConfig { force_axes: axes.clone().into(), torque_limit: BIG, ..Default::default() };
    let mut cfg_nog = cfg.clone();
    cfg_nog.gravity_compensation = false;
    let ctrl = build(&ControllerConfig::OpenLoopForce(cfg_nog), DOF, NA).unwrap();
    assert!(ctrl.does_force_control() && !ctrl.does_motion_control());
    let tau = compute(ctrl.as_ref(), &arm, &t);
    for w in 0..W {
        for c in 0..NA {
            let expect: f32 =
                (0..6).map(|r| arm.ee_jacobian[w * 6 * DOF + r * DOF + c] * axes[r] * t.ee_wrench[w][r]).sum();
            assert!((tau[w * DOF + c] - expect).abs() <= 1e-5 * (1.0 + expect.abs()), "world {w} joint {c}");
        }
    }
    // The default config is z force only.
    assert_eq!(OpenLoopForceConfig::default().force_axes, Gains::Each(vec![0.0, 0.0, 1.0, 0.0, 0.0, 0.0]));
}

#[test]
fn closed_loop_force_matches_its_equation_and_reduces_to_open_loop() {
    let (mut arm, t) = random_batch(5);
    let kf = vec![0.1, 0.2, 0.3, 0.4, 0.5, 0.6];
    let axes = vec![1.0, 1.0, 1.0, 0.0, 1.0, 1.0];
    let closed = build(
        &ControllerConfig::ClosedLoopForce(ClosedLoopForceConfig {
            force_axes: axes.clone().into(),
            kf: kf.clone().into(),
            torque_limit: BIG,
            gravity_compensation: false,
            ..Default::default()
        }),
        DOF,
        NA,
    )
    .unwrap();
    let open = build(
        &ControllerConfig::OpenLoopForce(OpenLoopForceConfig {
            force_axes: axes.clone().into(),
            torque_limit: BIG,
            gravity_compensation: false,
            ..Default::default()
        }),
        DOF,
        NA,
    )
    .unwrap();
    // Measured ≠ target: τ = Jᵀ S_f (F_t + kf (F_t − F_c)).
    let tau = compute(closed.as_ref(), &arm, &t);
    let tau_open = compute(open.as_ref(), &arm, &t);
    for w in 0..W {
        let f: Vec<f32> =
            (0..6).map(|i| axes[i] * (t.ee_wrench[w][i] + kf[i] * (t.ee_wrench[w][i] - arm.ee_wrench[w][i]))).collect();
        for c in 0..NA {
            let expect: f32 = (0..6).map(|r| arm.ee_jacobian[w * 6 * DOF + r * DOF + c] * f[r]).sum();
            assert!((tau[w * DOF + c] - expect).abs() <= 1e-5 * (1.0 + expect.abs()));
        }
        assert!(
            (0..NA).any(|c| (tau[w * DOF + c] - tau_open[w * DOF + c]).abs() > 1e-2),
            "closed loop ignored the force error"
        );
    }
    // Measured = target: identical to open loop.
    arm.ee_wrench = t.ee_wrench.clone();
    assert_eq!(compute(closed.as_ref(), &arm, &t), compute(open.as_ref(), &arm, &t));
}

#[test]
fn hybrid_is_motion_part_plus_force_part() {
    let (arm, t) = random_batch(6);
    let kp = Gains::Each(vec![30.0, 20.0, 40.0, 5.0, 8.0, 12.0]);
    let kd = Gains::Each(vec![6.0, 4.0, 9.0, 1.0, 2.0, 3.0]);
    let m_axes = Gains::Each(vec![1.0, 1.0, 0.0, 1.0, 1.0, 1.0]);
    let f_axes = Gains::Each(vec![0.0, 0.0, 1.0, 0.0, 0.0, 0.0]);
    let kf = Gains::All(0.3);
    for (motion, force) in
        [(MotionLaw::Osc, ForceLaw::Closed), (MotionLaw::Impedance, ForceLaw::Open), (MotionLaw::Osc, ForceLaw::Open)]
    {
        let hybrid = build(
            &ControllerConfig::HybridForceMotion(HybridForceMotionConfig {
                motion,
                kp: kp.clone(),
                kd: kd.clone(),
                motion_axes: m_axes.clone(),
                force,
                force_axes: f_axes.clone(),
                kf: kf.clone(),
                torque_limit: BIG,
                gravity_compensation: false,
                ..Default::default()
            }),
            DOF,
            NA,
        )
        .unwrap();
        assert!(hybrid.does_force_control() && hybrid.does_motion_control());
        let motion_cfg = match motion {
            MotionLaw::Osc => ControllerConfig::Osc(no_limits_osc(kp.clone(), kd.clone(), m_axes.clone())),
            MotionLaw::Impedance => ControllerConfig::TaskSpaceImpedance(TaskSpaceImpedanceConfig {
                kp: kp.clone(),
                kd: kd.clone(),
                motion_axes: m_axes.clone(),
                torque_limit: BIG,
                gravity_compensation: false,
                ..Default::default()
            }),
        };
        let force_cfg = match force {
            ForceLaw::Closed => ControllerConfig::ClosedLoopForce(ClosedLoopForceConfig {
                force_axes: f_axes.clone(),
                kf: kf.clone(),
                torque_limit: BIG,
                gravity_compensation: false,
                ..Default::default()
            }),
            ForceLaw::Open => ControllerConfig::OpenLoopForce(OpenLoopForceConfig {
                force_axes: f_axes.clone(),
                torque_limit: BIG,
                gravity_compensation: false,
                ..Default::default()
            }),
        };
        let th = compute(hybrid.as_ref(), &arm, &t);
        let tm = compute(build(&motion_cfg, DOF, NA).unwrap().as_ref(), &arm, &t);
        let tf = compute(build(&force_cfg, DOF, NA).unwrap().as_ref(), &arm, &t);
        for w in 0..W {
            for c in 0..NA {
                let (h, s) = (th[w * DOF + c], tm[w * DOF + c] + tf[w * DOF + c]);
                assert!(
                    (h - s).abs() <= 1e-5 * (1.0 + s.abs()),
                    "{motion:?}/{force:?} world {w} joint {c}: {h} vs {s}"
                );
            }
            assert!((0..NA).any(|c| tf[w * DOF + c].abs() > 1e-2) && (0..NA).any(|c| tm[w * DOF + c].abs() > 1e-2));
        }
    }
}

#[test]
fn impedance_is_jacobian_transpose_of_task_pd() {
    let (arm, t) = random_batch(7);
    let kp = vec![30.0, 20.0, 40.0, 5.0, 8.0, 12.0];
    let kd = vec![6.0, 4.0, 9.0, 1.0, 2.0, 3.0];
    let axes = vec![1.0, 0.0, 1.0, 1.0, 0.0, 1.0];
    let ctrl = build(
        &ControllerConfig::TaskSpaceImpedance(TaskSpaceImpedanceConfig {
            kp: kp.clone().into(),
            kd: kd.clone().into(),
            motion_axes: axes.clone().into(),
            torque_limit: BIG,
            gravity_compensation: false,
            ..Default::default()
        }),
        DOF,
        NA,
    )
    .unwrap();
    let tau = compute(ctrl.as_ref(), &arm, &t);
    for w in 0..W {
        let (e, xd) = e_xd(&arm, &t, w);
        let f: Vec<f64> = (0..6).map(|i| (axes[i] * (kp[i] * e[i] - kd[i] * xd[i])) as f64).collect();
        let got = task_wrench(&arm, &tau, w);
        assert!(rel_err(&got, &f) < 1e-4, "world {w}: {got:?} vs {f:?}");
    }
}

/// At the identity orientation E(0)⁻¹ = I and φ_t − 0 = axis-angle(q_t · 1⁻¹): analytic and geometric agree. Away
/// from it they differ, and the analytic law is J_aᵀ(kp(φ_t − φ_c) − kd E⁻¹ω).
#[test]
fn analytic_jacobian_law() {
    let (mut arm, t) = random_batch(8);
    let make = |jacobian| {
        build(
            &ControllerConfig::TaskSpaceImpedance(TaskSpaceImpedanceConfig {
                kp: Gains::All(20.0),
                kd: Gains::All(3.0),
                jacobian,
                torque_limit: BIG,
                gravity_compensation: false,
                ..Default::default()
            }),
            DOF,
            NA,
        )
        .unwrap()
    };
    let (geo, ana) = (make(JacobianKind::Geometric), make(JacobianKind::Analytic));
    let tau_g = compute(geo.as_ref(), &arm, &t);
    let tau_a = compute(ana.as_ref(), &arm, &t);
    for w in 0..W {
        let phi_c = axis_angle_from_quat(arm.ee_quat[w]);
        let einv = axis_angle_rate_map_inverse(phi_c);
        let dphi = axis_angle_from_quat(t.ee_quat[w]) - phi_c;
        let rate = einv * arm.ee_angvel[w];
        let dp = t.ee_pos[w] - arm.ee_pos[w];
        let f = [
            20.0 * dp.x - 3.0 * arm.ee_linvel[w].x,
            20.0 * dp.y - 3.0 * arm.ee_linvel[w].y,
            20.0 * dp.z - 3.0 * arm.ee_linvel[w].z,
            20.0 * dphi.x - 3.0 * rate.x,
            20.0 * dphi.y - 3.0 * rate.y,
            20.0 * dphi.z - 3.0 * rate.z,
        ];
        for c in 0..NA {
            let jc = |r: usize| arm.ee_jacobian[w * 6 * DOF + r * DOF + c];
            let ang = einv * Vec3::new(jc(3), jc(4), jc(5));
            let col = [jc(0), jc(1), jc(2), ang.x, ang.y, ang.z];
            let expect: f32 = (0..6).map(|r| col[r] * f[r]).sum();
            assert!((tau_a[w * DOF + c] - expect).abs() < 1e-4 * (1.0 + expect.abs()));
        }
        assert!((0..NA).any(|c| (tau_a[w * DOF + c] - tau_g[w * DOF + c]).abs() > 1e-2), "world {w}: no difference");
    }
    // Identity current orientation: the two agree.
    arm.ee_quat.iter_mut().for_each(|q| *q = Quat::IDENTITY);
    let tau_g = compute(geo.as_ref(), &arm, &t);
    let tau_a = compute(ana.as_ref(), &arm, &t);
    for (a, g) in tau_a.iter().zip(&tau_g) {
        assert!((a - g).abs() < 1e-4 * (1.0 + g.abs()), "{a} vs {g}");
    }
}

#[test]
fn gravity_is_added_once_and_only_when_enabled() {
    let (mut arm, t) = random_batch(9);
    let mut rng = Rng::new(99);
    let (arm0, g) = {
        let a0 = arm.clone();
        arm.gravity_torque.iter_mut().for_each(|x| *x = 10.0 * rng.next());
        (a0, arm.gravity_torque.clone())
    };
    for name in factory_controllers::NAMES {
        for flag in [true, false] {
            let mut cfg = ControllerConfig::default_for(name).unwrap();
            // Lift the clamp so the difference is exactly g.
            match &mut cfg {
                ControllerConfig::JointSpaceIk(c) => (c.torque_limit, c.gravity_compensation) = (BIG, flag),
                ControllerConfig::JointSpaceId(c) => (c.torque_limit, c.gravity_compensation) = (BIG, flag),
                ControllerConfig::TaskSpaceImpedance(c) => (c.torque_limit, c.gravity_compensation) = (BIG, flag),
                ControllerConfig::Osc(c) => (c.torque_limit, c.gravity_compensation) = (BIG, flag),
                ControllerConfig::OpenLoopForce(c) => (c.torque_limit, c.gravity_compensation) = (BIG, flag),
                ControllerConfig::ClosedLoopForce(c) => (c.torque_limit, c.gravity_compensation) = (BIG, flag),
                ControllerConfig::HybridForceMotion(c) => (c.torque_limit, c.gravity_compensation) = (BIG, flag),
            }
            let ctrl = build(&cfg, DOF, NA).unwrap();
            let with_g = compute(ctrl.as_ref(), &arm, &t);
            let without = compute(ctrl.as_ref(), &arm0, &t);
            for w in 0..W {
                for j in 0..DOF {
                    let i = w * DOF + j;
                    let expect = if flag && j < NA { g[i] } else { 0.0 };
                    let diff = with_g[i] - without[i];
                    assert!(
                        (diff - expect).abs() < 1e-4 * (1.0 + without[i].abs()),
                        "{name} flag {flag} joint {j}: {diff} vs {expect}"
                    );
                }
            }
        }
    }
}

#[test]
fn gripper_pd_and_torque_clamping() {
    let (arm, t) = random_batch(10);
    let cfg = ControllerConfig::TaskSpaceImpedance(TaskSpaceImpedanceConfig {
        kp: Gains::All(1e6),
        kd: Gains::All(0.0),
        gripper_kp: Gains::Each(vec![100.0, 200.0]),
        gripper_kd: Gains::Each(vec![1.0, 3.0]),
        torque_limit: 50.0,
        effort_limit: Some(vec![87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0, 1000.0, 1000.0]),
        gravity_compensation: false,
        ..Default::default()
    });
    let ctrl = build(&cfg, DOF, NA).unwrap();
    let tau = compute(ctrl.as_ref(), &arm, &t);
    let mut saturated = 0;
    for w in 0..W {
        for j in 0..NA {
            let lim = if j < 4 { 50.0 } else { 12.0 };
            let x = tau[w * DOF + j];
            assert!(x.abs() <= lim, "world {w} joint {j}: {x} beyond {lim}");
            saturated += (x.abs() == lim) as usize;
        }
        for f in 0..2 {
            let j = NA + f;
            let (kp, kd) = ([100.0, 200.0][f], [1.0, 3.0][f]);
            let expect = (kp * (t.gripper_q[w * 2 + f] - arm.joint_q[w * DOF + j]) - kd * arm.joint_qd[w * DOF + j])
                .clamp(-50.0, 50.0);
            assert!((tau[w * DOF + j] - expect).abs() < 1e-5, "finger {f}: {} vs {expect}", tau[w * DOF + j]);
        }
    }
    // A stiffness of 1e6 on errors of ~0.05 saturates almost every arm joint.
    assert!(saturated >= W * NA - 2, "only {saturated} saturated");
}

#[test]
fn ik_methods() {
    use factory_controllers::linalg::svd_6xn;
    use factory_controllers::IkSolver;
    let mut rng = Rng::new(12);
    // Well conditioned: J = [I6 | small random column] + small noise.
    let mut j = [0.0f32; 42];
    for r in 0..6 {
        for c in 0..7 {
            j[r * 7 + c] = if r == c { 1.0 } else { 0.2 * rng.next() };
        }
    }
    let e = [0.01, -0.02, 0.03, 0.1, -0.05, 0.2];
    let jdq = |dq: &[f32]| -> Vec<f32> { (0..6).map(|r| (0..7).map(|c| j[r * 7 + c] * dq[c]).sum()).collect() };
    let close = |a: &[f32], b: &[f32], tol: f32| a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol);

    let pinv = IkSolver { method: IkMethod::Pinv, ..Default::default() }.delta_q(&j, 7, &e);
    assert!(close(&jdq(&pinv), &e, 1e-5), "pinv: J dq = {:?}", jdq(&pinv));
    let dls0 = IkSolver { method: IkMethod::Dls, dls_lambda: 1e-3, ..Default::default() }.delta_q(&j, 7, &e);
    assert!(close(&jdq(&dls0), &e, 1e-4), "dls λ→0: J dq = {:?}", jdq(&dls0));
    assert!(close(&dls0[..7], &pinv[..7], 1e-4), "dls λ→0 is the minimum-norm solution, as pinv");
    // With λ = 0.1, DLS still satisfies Jᵀ(JJᵀ + λ²I)⁻¹ e = (JᵀJ + λ²I)⁻¹ Jᵀ e (the push-through identity), but
    // no longer J dq = e.
    let dls = IkSolver::default().delta_q(&j, 7, &e);
    let mut jtj = vec![0.0f64; 49];
    for a in 0..7 {
        for b in 0..7 {
            jtj[a * 7 + b] = (0..6).map(|r| j[r * 7 + a] as f64 * j[r * 7 + b] as f64).sum::<f64>()
                + if a == b { 0.01 } else { 0.0 };
        }
    }
    let jte: Vec<f64> = (0..7).map(|c| (0..6).map(|r| j[r * 7 + c] as f64 * e[r] as f64).sum()).collect();
    let other = solve64(&jtj, &jte);
    for c in 0..7 {
        assert!((dls[c] as f64 - other[c]).abs() < 1e-5, "dls identity, joint {c}: {} vs {}", dls[c], other[c]);
    }
    assert!(!close(&jdq(&dls), &e, 1e-3), "λ = 0.1 should visibly damp");
    // Transpose: exactly Jᵀ e.
    let tr = IkSolver { method: IkMethod::Trans, ..Default::default() }.delta_q(&j, 7, &e);
    for c in 0..7 {
        let expect: f32 = (0..6).map(|r| j[r * 7 + c] * e[r]).sum();
        assert!((tr[c] - expect).abs() < 1e-7);
    }

    // Adaptive SVD drops a singular value below its 1e-5 threshold; pinv's relative cutoff (~1e-6 here) keeps
    // it. Build J = Σ s_k u_k v_kᵀ with s = (2, 1.5, 1, 0.8, 0.5, 5e-6), U and V from SVDs of random matrices.
    let mut a = [0.0f32; 42];
    a.iter_mut().for_each(|x| *x = rng.next());
    let basis = svd_6xn(&a, 7);
    let s = [2.0, 1.5, 1.0, 0.8, 0.5, 5e-6];
    let mut jt = [0.0f32; 42];
    for r in 0..6 {
        for c in 0..7 {
            jt[r * 7 + c] = (0..6).map(|k| basis.u[r * 6 + k] * s[k] * basis.v[c * 6 + k]).sum();
        }
    }
    // e = u_0 + u_5: the exact pseudoinverse answer is v_0/2 + v_5/5e-6.
    let e: [f32; 6] = std::array::from_fn(|r| basis.u[r * 6] + basis.u[r * 6 + 5]);
    let svd = IkSolver { method: IkMethod::Svd, ..Default::default() }.delta_q(&jt, 7, &e);
    for c in 0..7 {
        let expect = basis.v[c * 6] / 2.0;
        assert!((svd[c] - expect).abs() < 1e-3, "svd joint {c}: {} vs {expect}", svd[c]);
    }
    let p = IkSolver { method: IkMethod::Pinv, ..Default::default() }.delta_q(&jt, 7, &e);
    let norm = p.iter().map(|x| x * x).sum::<f32>().sqrt();
    assert!(norm > 1e4, "pinv kept the 5e-6 singular value, |dq| should be ~2e5, got {norm}");
}

#[test]
fn worlds_are_independent() {
    let (arm, t) = random_batch(13);
    let ctrl = build(&ControllerConfig::default_for("hybrid_force_motion").unwrap(), DOF, NA).unwrap();
    let all = compute(ctrl.as_ref(), &arm, &t);
    for w in 0..W {
        let mut one = ArmBatch::zeros(1, DOF, NA);
        one.joint_q.copy_from_slice(&arm.joint_q[w * DOF..(w + 1) * DOF]);
        one.joint_qd.copy_from_slice(&arm.joint_qd[w * DOF..(w + 1) * DOF]);
        one.ee_jacobian.copy_from_slice(&arm.ee_jacobian[w * 6 * DOF..(w + 1) * 6 * DOF]);
        one.mass_matrix.copy_from_slice(&arm.mass_matrix[w * DOF * DOF..(w + 1) * DOF * DOF]);
        one.gravity_torque.copy_from_slice(&arm.gravity_torque[w * DOF..(w + 1) * DOF]);
        (one.ee_pos[0], one.ee_quat[0], one.ee_linvel[0], one.ee_angvel[0], one.ee_wrench[0]) =
            (arm.ee_pos[w], arm.ee_quat[w], arm.ee_linvel[w], arm.ee_angvel[w], arm.ee_wrench[w]);
        let tt = Targets {
            ee_pos: vec![t.ee_pos[w]],
            ee_quat: vec![t.ee_quat[w]],
            ee_wrench: vec![t.ee_wrench[w]],
            gripper_q: t.gripper_q[w * 2..w * 2 + 2].to_vec(),
        };
        assert_eq!(compute(ctrl.as_ref(), &one, &tt), all[w * DOF..(w + 1) * DOF]);
    }
}

#[test]
fn holding_pose_at_rest_gives_zero_torque_for_every_motion_controller() {
    let (mut arm, _) = random_batch(14);
    arm.joint_qd.iter_mut().for_each(|x| *x = 0.0);
    arm.ee_linvel.iter_mut().for_each(|x| *x = Vec3::ZERO);
    arm.ee_angvel.iter_mut().for_each(|x| *x = Vec3::ZERO);
    let t = Targets::hold(&arm);
    for name in ["joint_space_ik", "joint_space_id", "task_space_impedance", "osc"] {
        let ctrl = build(&ControllerConfig::default_for(name).unwrap(), DOF, NA).unwrap();
        let tau = compute(ctrl.as_ref(), &arm, &t);
        assert!(tau.iter().all(|x| x.abs() < 1e-5), "{name}: {tau:?}");
    }
}

#[test]
#[should_panic(expected = "Targets.gripper_q")]
fn wrong_target_shape_panics_naming_the_buffer() {
    let (arm, mut t) = random_batch(15);
    t.gripper_q.pop();
    let ctrl = build(&ControllerConfig::default_for("osc").unwrap(), DOF, NA).unwrap();
    compute(ctrl.as_ref(), &arm, &t);
}

#[test]
#[should_panic(expected = "built for dof")]
fn wrong_dof_panics() {
    let (arm, t) = random_batch(16);
    let ctrl = build(&ControllerConfig::default_for("osc").unwrap(), 8, 6).unwrap();
    compute(ctrl.as_ref(), &arm, &t);
}

#[test]
fn osc_at_a_singularity_stays_finite_and_clamped() {
    let (mut arm, t) = random_batch(17);
    for w in 0..W {
        // Rows 0 and 1 equal: J loses rank, J M⁻¹ Jᵀ is singular.
        let (a, b) = arm.ee_jacobian.split_at_mut(w * 6 * DOF + DOF);
        b[..DOF].copy_from_slice(&a[w * 6 * DOF..w * 6 * DOF + DOF]);
    }
    for name in ["osc", "hybrid_force_motion", "joint_space_id", "joint_space_ik"] {
        let ctrl = build(&ControllerConfig::default_for(name).unwrap(), DOF, NA).unwrap();
        let tau = compute(ctrl.as_ref(), &arm, &t);
        assert!(tau.iter().all(|x| x.is_finite() && x.abs() <= 100.0), "{name}: {tau:?}");
    }
}

/// Closed loop on a synthetic arm: M q̈ = τ − g with constant M and g, fingertip position `p = p0 + J_v q`
/// and orientation `exp(J_w q)` (so the geometric Jacobian is `[J_v; E(φ) J_w]`, configuration dependent).
/// Every motion controller must bring the fingertip to a target 5 cm and ~15° away; a sign error in the
/// pose error, the velocity or the analytic map would diverge or stall instead.
#[test]
fn motion_controllers_converge_in_closed_loop() {
    use factory_controllers::rotation::axis_angle_rate_map;
    let (base, _) = random_batch(18);
    let mut rng = Rng::new(181);
    // Fingers of 50 g, not inertially coupled to the arm (a random M would give them kilograms and a lightly
    // damped mode under the default finger PD, which is not what this test is about).
    let mut mass = base.mass_matrix[..DOF * DOF].to_vec();
    for r in 0..DOF {
        for c in 0..DOF {
            if (r >= NA || c >= NA) && r != c {
                mass[r * DOF + c] = 0.0;
            }
        }
    }
    mass[NA * DOF + NA] = 0.05;
    mass[(NA + 1) * DOF + NA + 1] = 0.05;
    let m64: Vec<f64> = mass.iter().map(|&x| x as f64).collect();
    let g: Vec<f32> = (0..DOF).map(|j| if j < NA { 5.0 * rng.next() } else { 0.0 }).collect();
    let jv: Vec<f32> = base.ee_jacobian[..3 * DOF].to_vec();
    let jw: Vec<f32> = base.ee_jacobian[3 * DOF..6 * DOF].iter().map(|x| 0.5 * x).collect();
    let p0 = Vec3::new(0.5, 0.0, 0.4);
    let kin = |q: &[f32]| -> (Vec3, Vec3) {
        let lin = |rows: &[f32], r: usize| (0..NA).map(|c| rows[r * DOF + c] * q[c]).sum::<f32>();
        (p0 + Vec3::new(lin(&jv, 0), lin(&jv, 1), lin(&jv, 2)), Vec3::new(lin(&jw, 0), lin(&jw, 1), lin(&jw, 2)))
    };
    let q0: Vec<f32> = (0..DOF).map(|j| if j < NA { 0.1 * rng.next() } else { 0.02 }).collect();
    let (p_start, phi_start) = kin(&q0);
    let mut t = Targets::zeros(1, 2);
    t.ee_pos[0] = p_start + Vec3::new(0.05, -0.03, 0.04);
    t.ee_quat[0] = Quat::from_scaled_axis(Vec3::new(0.15, -0.2, 0.1)) * Quat::from_scaled_axis(phi_start);
    t.gripper_q = vec![0.03, 0.03];

    let osc = |jacobian| {
        ControllerConfig::Osc(OscConfig { kp: Gains::All(100.0), kd: Gains::All(20.0), jacobian, ..Default::default() })
    };
    let configs = [
        ControllerConfig::JointSpaceIk(JointSpaceIkConfig {
            kp: Gains::All(100.0),
            kd: Gains::All(20.0),
            ..Default::default()
        }),
        ControllerConfig::JointSpaceId(JointSpaceIdConfig {
            kp: Gains::All(100.0),
            kd: Gains::All(20.0),
            ik_method: IkMethod::Pinv,
            ..Default::default()
        }),
        ControllerConfig::TaskSpaceImpedance(TaskSpaceImpedanceConfig {
            kp: Gains::All(100.0),
            kd: Gains::All(20.0),
            ..Default::default()
        }),
        osc(JacobianKind::Geometric),
        osc(JacobianKind::Analytic),
    ];
    for cfg in configs {
        let ctrl = build(&cfg, DOF, NA).unwrap();
        let mut arm = ArmBatch::zeros(1, DOF, NA);
        arm.mass_matrix.copy_from_slice(&mass);
        arm.gravity_torque.copy_from_slice(&g);
        let (mut q, mut qd) = (q0.clone(), vec![0.0f32; DOF]);
        let dt = 1e-3;
        let mut tau = vec![0.0f32; DOF];
        for _ in 0..4000 {
            let (p, phi) = kin(&q);
            let e = axis_angle_rate_map(phi);
            arm.joint_q.copy_from_slice(&q);
            arm.joint_qd.copy_from_slice(&qd);
            arm.ee_pos[0] = p;
            arm.ee_quat[0] = Quat::from_scaled_axis(phi);
            for c in 0..DOF {
                let jwc = e * Vec3::new(jw[c], jw[DOF + c], jw[2 * DOF + c]);
                let col = [jv[c], jv[DOF + c], jv[2 * DOF + c], jwc.x, jwc.y, jwc.z];
                for r in 0..6 {
                    arm.ee_jacobian[r * DOF + c] = if c < NA { col[r] } else { 0.0 };
                }
            }
            let v: [f32; 6] = std::array::from_fn(|r| (0..DOF).map(|c| arm.ee_jacobian[r * DOF + c] * qd[c]).sum());
            arm.ee_linvel[0] = Vec3::new(v[0], v[1], v[2]);
            arm.ee_angvel[0] = Vec3::new(v[3], v[4], v[5]);
            ctrl.compute(&arm, &t, &mut tau);
            let rhs: Vec<f64> = (0..DOF).map(|j| (tau[j] - g[j]) as f64).collect();
            let qdd = solve64(&m64, &rhs);
            for j in 0..DOF {
                qd[j] += dt * qdd[j] as f32;
                q[j] += dt * qd[j];
            }
        }
        let (p, phi) = kin(&q);
        let e = pose_error(t.ee_pos[0], t.ee_quat[0], p, Quat::from_scaled_axis(phi), JacobianKind::Geometric);
        let (ep, er) = (Vec3::new(e[0], e[1], e[2]).length(), Vec3::new(e[3], e[4], e[5]).length());
        assert!(ep < 1e-3 && er < 1e-3, "{}: final error {ep} m, {er} rad", cfg.name());
        assert!(
            (q[NA] - 0.03).abs() < 1e-3 && (q[NA + 1] - 0.03).abs() < 1e-3,
            "{}: fingers {:?}",
            cfg.name(),
            &q[NA..]
        );
    }
}

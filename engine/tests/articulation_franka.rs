//! The Franka Panda articulation (assets/franka/franka_panda.urdf) against independent references: Franka's
//! published modified-DH table (forward kinematics), finite differences of that DH chain (Jacobians), the
//! equation of motion (mass matrix, gravity, simulated response), and holding still under gravity
//! compensation.

use factory_engine::articulation::dynamics::{
    forward_kinematics, frame_pose, inverse_dynamics, mass_matrix, point_jacobian, step_cpu, world_dynamics,
};
use factory_engine::articulation::{ArticulationControl, ArticulationModel, ArticulationState};
use factory_engine::rng::SplitMix64;
use factory_engine::urdf::load_urdf;
use glam::{DMat4, DVec3, Quat, Vec3};
use std::path::PathBuf;

fn franka() -> ArticulationModel {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../assets/franka/franka_panda.urdf");
    let urdf = load_urdf(&path).expect("the Franka URDF loads");
    let mut m = ArticulationModel::from_urdf(&urdf, (Vec3::ZERO, Quat::IDENTITY), Vec3::new(0.0, 0.0, -9.81))
        .expect("the Franka URDF is an articulation");
    // IsaacGymEnvs' Factory gives every Franka joint 0.01 armature (factory_base.py's asset options).
    m.set_armature(0.01);
    m
}

/// Franka's published modified-DH (Craig) table, FCI documentation "Robot and interface specifications":
/// (a [m], d [m], alpha [rad]) of joints 1-7 and the flange.
const DH: [(f64, f64, f64); 8] = [
    (0.0, 0.333, 0.0),
    (0.0, 0.0, -std::f64::consts::FRAC_PI_2),
    (0.0, 0.316, std::f64::consts::FRAC_PI_2),
    (0.0825, 0.0, std::f64::consts::FRAC_PI_2),
    (-0.0825, 0.384, -std::f64::consts::FRAC_PI_2),
    (0.0, 0.0, std::f64::consts::FRAC_PI_2),
    (0.088, 0.0, std::f64::consts::FRAC_PI_2),
    (0.0, 0.107, 0.0),
];

/// The flange frame by the DH chain in f64: T_i = RotX(alpha) TransX(a) RotZ(theta) TransZ(d).
fn dh_frames(q: &[f64]) -> Vec<DMat4> {
    let mut t = DMat4::IDENTITY;
    let mut out = Vec::new();
    for (i, &(a, d, alpha)) in DH.iter().enumerate() {
        let theta = if i < 7 { q[i] } else { 0.0 };
        t = t
            * DMat4::from_rotation_x(alpha)
            * DMat4::from_translation(DVec3::new(a, 0.0, 0.0))
            * DMat4::from_rotation_z(theta)
            * DMat4::from_translation(DVec3::new(0.0, 0.0, d));
        out.push(t);
    }
    out
}

/// The fingertip-centred frame by DH: flange, the hand's -45 degrees about z, then 0.112071 m along z
/// (Factory: hand 0.0584 + finger 0.044867 + half the 0.017608 pad).
fn dh_fingertip(q: &[f64]) -> DMat4 {
    dh_frames(q)[7]
        * DMat4::from_rotation_z(-std::f64::consts::FRAC_PI_4)
        * DMat4::from_translation(DVec3::new(0.0, 0.0, 0.112071))
}

fn random_q(model: &ArticulationModel, rng: &mut SplitMix64) -> Vec<f32> {
    (0..model.dof_count())
        .map(|d| {
            let (lo, hi) = (model.dof_lower[d].max(-2.8), model.dof_upper[d].min(2.8));
            lo + (hi - lo) * rng.unit()
        })
        .collect()
}

#[test]
fn franka_has_seven_arm_joints_two_fingers_and_joint_seven_unlimited() {
    let m = franka();
    assert_eq!(m.dof_count(), 9, "{:?}", m.dof_name);
    assert!(m.dof_upper[6].is_infinite() && m.dof_lower[6].is_infinite(), "joint 7 is continuous (Factory)");
    for f in 7..9 {
        assert_eq!((m.dof_lower[f], m.dof_upper[f]), (0.0, 0.04), "finger {f}");
    }
    assert_eq!(&m.dof_effort_limit[..7], &[87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0]);
    assert!(m.frame("panda_fingertip_centered").is_some());
}

#[test]
fn forward_kinematics_matches_the_dh_table_at_random_joint_angles() {
    let m = franka();
    let tip = m.frame("panda_fingertip_centered").unwrap();
    let flange = m.link_index("panda_link8").unwrap();
    let mut rng = SplitMix64(21);
    let mut poses = vec![(Vec3::ZERO, Quat::IDENTITY); m.link_count()];
    let mut worst = (0.0f64, 0.0f64);
    for _ in 0..200 {
        let q = random_q(&m, &mut rng);
        forward_kinematics(&m, &q, &mut poses);
        let q64: Vec<f64> = q.iter().map(|&x| x as f64).collect();
        let frames = dh_frames(&q64);
        for (link, t) in [(m.link_index("panda_link4").unwrap(), frames[3]), (flange, frames[7])] {
            let (p, r) = poses[link as usize];
            worst.0 = worst.0.max((p.as_dvec3() - t.w_axis.truncate()).length());
            worst.1 = worst.1.max(
                (glam::DMat3::from_quat(r.as_dquat()) - glam::DMat3::from_mat4(t))
                    .abs()
                    .to_cols_array()
                    .iter()
                    .cloned()
                    .fold(0.0, f64::max),
            );
        }
        let (p, r) = frame_pose(&poses, tip.link, tip.offset);
        let t = dh_fingertip(&q64);
        worst.0 = worst.0.max((p.as_dvec3() - t.w_axis.truncate()).length());
        worst.1 = worst.1.max(
            (glam::DMat3::from_quat(r.as_dquat()) - glam::DMat3::from_mat4(t))
                .abs()
                .to_cols_array()
                .iter()
                .cloned()
                .fold(0.0, f64::max),
        );
    }
    // f32 through ten joints: a few micrometres.
    assert!(worst.0 < 5e-6, "position error {} m", worst.0);
    assert!(worst.1 < 5e-6, "rotation matrix error {}", worst.1);
}

#[test]
fn fingertip_jacobian_matches_finite_differences_of_the_dh_chain() {
    let m = franka();
    let tip = m.frame("panda_fingertip_centered").unwrap();
    let n = m.dof_count();
    let mut rng = SplitMix64(7);
    let mut poses = vec![(Vec3::ZERO, Quat::IDENTITY); m.link_count()];
    let mut jac = vec![0.0f32; 6 * n];
    let mut worst = 0.0f64;
    for _ in 0..50 {
        let q = random_q(&m, &mut rng);
        forward_kinematics(&m, &q, &mut poses);
        let (p, _) = frame_pose(&poses, tip.link, tip.offset);
        point_jacobian(&m, &poses, tip.link, p, &mut jac);
        let q64: Vec<f64> = q.iter().map(|&x| x as f64).collect();
        let eps = 1e-6;
        for d in 0..7 {
            let (mut qp, mut qm) = (q64.clone(), q64.clone());
            qp[d] += eps;
            qm[d] -= eps;
            let (tp, tm) = (dh_fingertip(&qp), dh_fingertip(&qm));
            let v = (tp.w_axis.truncate() - tm.w_axis.truncate()) / (2.0 * eps);
            // Angular velocity from dR/dq R^T (its skew part).
            let r = glam::DMat3::from_mat4(dh_fingertip(&q64));
            let dr = (glam::DMat3::from_mat4(tp) - glam::DMat3::from_mat4(tm)) * (1.0 / (2.0 * eps));
            let s = dr * r.transpose();
            let w = DVec3::new(s.y_axis.z, s.z_axis.x, s.x_axis.y);
            for k in 0..3 {
                worst = worst.max((jac[k * n + d] as f64 - v[k]).abs());
                worst = worst.max((jac[(3 + k) * n + d] as f64 - w[k]).abs());
            }
        }
        // The fingers do not move the fingertip-centred frame (it rides on the hand).
        for d in 7..9 {
            assert!((0..6).all(|k| jac[k * n + d] == 0.0));
        }
    }
    assert!(worst < 1e-4, "Jacobian vs finite differences: {worst}");
}

#[test]
fn mass_matrix_is_symmetric_positive_definite_and_matches_inverse_dynamics() {
    let m = franka();
    let n = m.dof_count();
    let mut rng = SplitMix64(3);
    let mut poses = vec![(Vec3::ZERO, Quat::IDENTITY); m.link_count()];
    let mut mm = vec![0.0f32; n * n];
    for _ in 0..50 {
        let q = random_q(&m, &mut rng);
        forward_kinematics(&m, &q, &mut poses);
        mass_matrix(&m, &poses, &mut mm);
        for i in 0..n {
            for j in 0..n {
                assert!((mm[i * n + j] - mm[j * n + i]).abs() < 1e-5, "M not symmetric at ({i},{j})");
            }
        }
        let mut f = mm.clone();
        let mut b = vec![1.0f32; n];
        assert!(factory_engine::articulation::dynamics::cholesky_solve(n, &mut f, &mut b), "M not positive definite");
        // Column j of M from Newton-Euler with a unit acceleration of joint j (no velocity, no gravity),
        // plus the armature the RNEA leaves out.
        for j in 0..n {
            let mut qdd = vec![0.0f32; n];
            qdd[j] = 1.0;
            let mut tau = vec![0.0f32; n];
            inverse_dynamics(&m, &poses, &vec![0.0; n], &qdd, false, &mut tau);
            tau[j] += m.dof_armature[j];
            for i in 0..n {
                assert!(
                    (tau[i] - mm[i * n + j]).abs() < 1e-4 * (1.0 + mm[j * n + j].abs()),
                    "M[{i}][{j}]: {} vs {}",
                    mm[i * n + j],
                    tau[i]
                );
            }
        }
    }
}

/// Apply tau = M qdd* + c + g for a chosen qdd* and take one short step: the joints accelerate by qdd*.
#[test]
fn simulated_response_follows_tau_equals_m_qdd_plus_bias() {
    let m = franka();
    let n = m.dof_count();
    let tip = m.frame("panda_fingertip_centered").unwrap();
    let mut rng = SplitMix64(11);
    let mut worst = 0.0f32;
    for _ in 0..20 {
        let mut q = random_q(&m, &mut rng);
        // Away from the position limits so no stop interferes.
        q[7] = 0.02;
        q[8] = 0.02;
        let qd: Vec<f32> = (0..n).map(|_| 0.4 * (rng.unit() - 0.5)).collect();
        let qdd: Vec<f32> = (0..n).map(|_| 2.0 * (rng.unit() - 0.5)).collect();
        let dynm = world_dynamics(&m, &q, &qd, &tip);
        let tau: Vec<f32> = (0..n)
            .map(|i| {
                (0..n).map(|j| dynm.mass_matrix[i * n + j] * qdd[j]).sum::<f32>()
                    + dynm.coriolis_torque[i]
                    + dynm.gravity_torque[i]
            })
            .collect();
        let mut state = ArticulationState { joint_q: q.clone(), joint_qd: qd.clone() };
        let control = ArticulationControl { joint_tau: tau, ..Default::default() };
        let h = 1e-3f32;
        step_cpu(&m, &mut state, &control, h, 1);
        for d in 0..n {
            let acc = (state.joint_qd[d] - qd[d]) / h;
            worst = worst.max((acc - qdd[d]).abs());
        }
    }
    // f32 velocities differenced over 1 ms: about 1e-3 rad/s^2 of rounding.
    assert!(worst < 2e-2, "acceleration error {worst} rad/s^2");
}

/// With tau = g(q) every step (gravity compensation), an arm at rest in a bent pose stays put: the
/// fingertip moves < 1 mm in 5 s at 60 Hz with 2 substeps (Factory's dt and substeps).
#[test]
fn arm_holds_its_pose_under_gravity_compensation() {
    let m = franka();
    let n = m.dof_count();
    let tip = m.frame("panda_fingertip_centered").unwrap();
    // Factory's Screw reset pose (IsaacGymEnvs' FactoryTaskNutBoltScrew.yaml), fingers half open.
    let q0 = [1.5178e-3, -0.19651, -1.4364e-3, -1.9761, -2.7717e-4, 1.7796, 0.78556, 0.02, 0.02];
    let mut state = ArticulationState::replicate(&q0, 4);
    let start = world_dynamics(&m, &q0, &[0.0; 9], &tip).frame_pose.0;
    for _ in 0..300 {
        let mut tau = Vec::with_capacity(4 * n);
        for w in 0..4 {
            let d = world_dynamics(&m, &state.joint_q[w * n..(w + 1) * n], &state.joint_qd[w * n..(w + 1) * n], &tip);
            tau.extend_from_slice(&d.gravity_torque);
        }
        let diverged =
            step_cpu(&m, &mut state, &ArticulationControl { joint_tau: tau, ..Default::default() }, 1.0 / 60.0, 2);
        assert!(diverged.iter().all(|d| !d));
    }
    for w in 0..4 {
        let end = world_dynamics(&m, &state.joint_q[w * n..(w + 1) * n], &[0.0; 9], &tip).frame_pose.0;
        let drift = (end - start).length();
        assert!(drift < 1e-3, "world {w}: fingertip drifted {drift} m");
    }
    // And without compensation the same arm falls: the check can fail.
    let mut fall = ArticulationState::replicate(&q0, 1);
    for _ in 0..60 {
        step_cpu(&m, &mut fall, &ArticulationControl::default(), 1.0 / 60.0, 2);
    }
    let end = world_dynamics(&m, &fall.joint_q, &[0.0; 9], &tip).frame_pose.0;
    assert!((end - start).length() > 0.05, "an uncompensated arm should sag: moved {}", (end - start).length());
}

/// Bad input: a joint type an articulation cannot take, or a mimic coupling, is refused naming the joint
/// and the file.
#[test]
fn unsupported_joint_types_are_refused_naming_the_joint_and_file() {
    use factory_engine::urdf::parse_urdf;
    let doc = |joint: &str| {
        format!(
            r#"<robot name="r"><link name="a"/><link name="b"/><link name="c"/>
            <joint name="j1" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>
              <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
            {joint}</robot>"#
        )
    };
    let path = std::path::Path::new("robots/bad.urdf");
    for (joint, name, what) in [
        (r#"<joint name="free" type="floating"><parent link="b"/><child link="c"/></joint>"#, "free", "floating"),
        (
            r#"<joint name="slide" type="planar"><parent link="b"/><child link="c"/><axis xyz="0 0 1"/></joint>"#,
            "slide",
            "planar",
        ),
        (
            r#"<joint name="twin" type="revolute"><parent link="b"/><child link="c"/><axis xyz="0 0 1"/>
               <limit lower="-1" upper="1" effort="1" velocity="1"/><mimic joint="j1"/></joint>"#,
            "twin",
            "mimics",
        ),
    ] {
        let urdf = parse_urdf(&doc(joint), path, std::path::Path::new(".")).unwrap();
        let err =
            ArticulationModel::from_urdf(&urdf, (Vec3::ZERO, Quat::IDENTITY), Vec3::ZERO).unwrap_err().to_string();
        assert!(err.contains(name) && err.contains(what) && err.contains("bad.urdf"), "{err}");
    }
}

/// The analytic Jacobian maps joint velocities to the rate of the fingertip's rotation vector: against
/// finite differences of the DH chain's axis-angle (away from the 180-degree flip of the shortest arc).
#[test]
fn analytic_jacobian_matches_finite_differences_of_the_rotation_vector() {
    use factory_engine::articulation::dynamics::analytic_jacobian;
    use factory_engine::articulation::rotation::axis_angle_from_quat;
    let m = franka();
    let tip = m.frame("panda_fingertip_centered").unwrap();
    let n = m.dof_count();
    let mut rng = SplitMix64(5);
    let mut poses = vec![(Vec3::ZERO, Quat::IDENTITY); m.link_count()];
    let (mut jg, mut ja) = (vec![0.0f32; 6 * n], vec![0.0f32; 6 * n]);
    let mut worst = 0.0f64;
    let mut checked = 0;
    while checked < 30 {
        let q = random_q(&m, &mut rng);
        forward_kinematics(&m, &q, &mut poses);
        let (p, r) = frame_pose(&poses, tip.link, tip.offset);
        if axis_angle_from_quat(r).length() > 2.8 {
            continue;
        }
        checked += 1;
        point_jacobian(&m, &poses, tip.link, p, &mut jg);
        analytic_jacobian(&jg, n, r, &mut ja);
        let q64: Vec<f64> = q.iter().map(|&x| x as f64).collect();
        let phi = |q: &[f64]| {
            let t = dh_fingertip(q);
            let quat = glam::DQuat::from_mat3(&glam::DMat3::from_mat4(t));
            let (v, w) = if quat.w < 0.0 { (-quat.xyz(), -quat.w) } else { (quat.xyz(), quat.w) };
            let s = v.length();
            if s < 1e-12 {
                DVec3::ZERO
            } else {
                v * (2.0 * s.atan2(w) / s)
            }
        };
        let eps = 1e-6;
        for d in 0..7 {
            let (mut qp, mut qm) = (q64.clone(), q64.clone());
            qp[d] += eps;
            qm[d] -= eps;
            let rate = (phi(&qp) - phi(&qm)) / (2.0 * eps);
            for k in 0..3 {
                worst = worst.max((ja[(3 + k) * n + d] as f64 - rate[k]).abs());
                assert_eq!(ja[k * n + d], jg[k * n + d], "the linear rows are the geometric ones");
            }
        }
    }
    assert!(worst < 1e-3, "analytic Jacobian vs finite differences: {worst}");
}

//! The articulation's kinematics and dynamics on the host, one world at a time (the plain-Rust reference
//! the GPU kernel is checked against), and batched helpers over worlds (rayon).
//!
//! Per world, all in the world frame:
//! - [`forward_kinematics`]: link poses from joint positions, root first.
//! - [`point_jacobian`]: the geometric Jacobian of a point on a link, rows (vx, vy, vz, wx, wy, wz): a
//!   revolute joint with world axis a through o contributes (a x (p - o); a), a prismatic one (a; 0).
//! - [`mass_matrix`]: M = sum over links of m Jc^T Jc + Jw^T I Jw (Jc the Jacobian of the link's centre of
//!   mass, I its world inertia; Siciliano et al. 2009, eq. 7.32), plus the armature on the diagonal.
//! - [`inverse_dynamics`]: the recursive Newton-Euler algorithm (Featherstone 2008, table 5.1, here with
//!   world-frame vectors instead of spatial algebra): a forward pass propagates angular velocity and
//!   acceleration and the acceleration of each link origin from the base, a backward pass accumulates the
//!   force and moment each link's subtree needs, and a joint's torque is the moment (revolute) or force
//!   (prismatic) along its axis. Gravity enters as a base acceleration of -g. With qdd = 0 it gives
//!   c(q, qd) + g(q); with qd = qdd = 0, g(q).

use super::{ArticulationControl, ArticulationModel, ArticulationState, JointKind, NO_DOF, NO_LINK};
use glam::{Mat3, Quat, Vec3};
use rayon::prelude::*;

/// A pose: position [m], rotation.
pub type Pose = (Vec3, Quat);

/// Link poses in the world frame for joint positions `q` (shape [dof_count]); `out` has link_count entries.
pub fn forward_kinematics(model: &ArticulationModel, q: &[f32], out: &mut [Pose]) {
    for l in 0..model.link_count() {
        let (o, r) = model.link_origin[l];
        // The joint frame in the parent at position 0, then the joint's own motion in that frame.
        let (local_p, local_r) = match (model.link_joint[l], model.link_dof[l]) {
            (JointKind::Revolute, d) if d != NO_DOF => {
                (o, r * Quat::from_axis_angle(model.link_axis[l], q[d as usize]))
            }
            (JointKind::Prismatic, d) if d != NO_DOF => (o + r * (model.link_axis[l] * q[d as usize]), r),
            _ => (o, r),
        };
        let parent = model.link_parent[l];
        out[l] = if parent == NO_LINK {
            (local_p, local_r)
        } else {
            let (pp, pr) = out[parent as usize];
            (pp + pr * local_p, (pr * local_r).normalize())
        };
    }
}

/// The world pose of a frame `offset` on `link`, given the link poses.
pub fn frame_pose(poses: &[Pose], link: u32, offset: Pose) -> Pose {
    let (p, r) = poses[link as usize];
    (p + r * offset.0, r * offset.1)
}

/// Calls `f(dof, axis_world, axis_origin_world, kind)` for every degree of freedom that moves `link`,
/// from the link to the root.
fn for_each_ancestor_dof(
    model: &ArticulationModel,
    poses: &[Pose],
    link: u32,
    mut f: impl FnMut(usize, Vec3, Vec3, JointKind),
) {
    let mut l = link;
    while l != NO_LINK {
        let d = model.link_dof[l as usize];
        if d != NO_DOF {
            let (o, r) = poses[l as usize];
            f(d as usize, r * model.link_axis[l as usize], o, model.link_joint[l as usize]);
        }
        l = model.link_parent[l as usize];
    }
}

/// Geometric Jacobian of the world point `point` [m] moving with `link`: `out` is 6 x dof_count,
/// row-major, rows (vx, vy, vz, wx, wy, wz); columns of joints that do not move the link are zero.
pub fn point_jacobian(model: &ArticulationModel, poses: &[Pose], link: u32, point: Vec3, out: &mut [f32]) {
    let n = model.dof_count();
    out[..6 * n].iter_mut().for_each(|x| *x = 0.0);
    for_each_ancestor_dof(model, poses, link, |d, a, o, kind| {
        let (v, w) = match kind {
            JointKind::Prismatic => (a, Vec3::ZERO),
            _ => (a.cross(point - o), a),
        };
        for k in 0..3 {
            out[k * n + d] = v[k];
            out[(3 + k) * n + d] = w[k];
        }
    });
}

/// The analytic Jacobian of a frame from its geometric one (both 6 x dof_count row-major): rows (vx, vy,
/// vz, dphi/dt) with phi the rotation vector (axis-angle, shortest arc) of the frame's orientation `quat`,
/// J_a = blockdiag(I, E(phi)^-1) J_g (Siciliano et al. 2009, sec. 3.6; E in [`super::rotation`]).
pub fn analytic_jacobian(geometric: &[f32], n: usize, quat: Quat, out: &mut [f32]) {
    let e_inv = super::rotation::axis_angle_rate_map_inverse(super::rotation::axis_angle_from_quat(quat));
    out[..3 * n].copy_from_slice(&geometric[..3 * n]);
    for d in 0..n {
        let w = Vec3::new(geometric[3 * n + d], geometric[4 * n + d], geometric[5 * n + d]);
        let r = e_inv * w;
        for k in 0..3 {
            out[(3 + k) * n + d] = r[k];
        }
    }
}

/// Joint-space mass matrix at the link poses `poses`, dof_count x dof_count row-major, with the
/// armature on its diagonal.
pub fn mass_matrix(model: &ArticulationModel, poses: &[Pose], out: &mut [f32]) {
    let n = model.dof_count();
    out[..n * n].iter_mut().for_each(|x| *x = 0.0);
    // Column vectors of the COM Jacobian (linear part; angular part) for the dofs moving this link.
    let mut cols: Vec<(usize, Vec3, Vec3)> = Vec::with_capacity(n);
    for l in 0..model.link_count() {
        let m = model.link_mass[l];
        if m <= 0.0 {
            continue;
        }
        let (p, r) = poses[l];
        let c = p + r * model.link_com[l];
        let rm = Mat3::from_quat(r);
        let inertia = rm * model.link_inertia[l] * rm.transpose();
        cols.clear();
        for_each_ancestor_dof(model, poses, l as u32, |d, a, o, kind| {
            cols.push(match kind {
                JointKind::Prismatic => (d, a, Vec3::ZERO),
                _ => (d, a.cross(c - o), a),
            });
        });
        for &(i, vi, wi) in &cols {
            let iwi = inertia * wi;
            for &(j, vj, wj) in &cols {
                out[i * n + j] += m * vi.dot(vj) + iwi.dot(wj);
            }
        }
    }
    for d in 0..n {
        out[d * n + d] += model.dof_armature[d];
    }
}

/// Joint torques [N m or N] that produce accelerations `qdd` at velocities `qd` (both shape
/// [dof_count]; `qdd` may be empty for zero) at the link poses `poses`, with gravity when `with_gravity`:
/// tau = M qdd + c(q, qd) [+ g(q)], armature and damping excluded (recursive Newton-Euler, module doc).
pub fn inverse_dynamics(
    model: &ArticulationModel,
    poses: &[Pose],
    qd: &[f32],
    qdd: &[f32],
    with_gravity: bool,
    tau: &mut [f32],
) {
    let nl = model.link_count();
    // Forward pass: angular velocity w, angular acceleration al, linear acceleration of the link origin a.
    let mut w = vec![Vec3::ZERO; nl];
    let mut al = vec![Vec3::ZERO; nl];
    let mut a = vec![Vec3::ZERO; nl];
    let base_acc = if with_gravity { -model.gravity } else { Vec3::ZERO };
    for l in 0..nl {
        let parent = model.link_parent[l];
        let (o, r) = poses[l];
        let (wp, alp, ap, op) = if parent == NO_LINK {
            (Vec3::ZERO, Vec3::ZERO, base_acc, o)
        } else {
            let p = parent as usize;
            (w[p], al[p], a[p], poses[p].0)
        };
        let rel = o - op;
        let mut wl = wp;
        let mut all = alp;
        let mut acc = ap + alp.cross(rel) + wp.cross(wp.cross(rel));
        let d = model.link_dof[l];
        if d != NO_DOF {
            let axis = r * model.link_axis[l];
            let v = qd[d as usize];
            let acc_d = qdd.get(d as usize).copied().unwrap_or(0.0);
            match model.link_joint[l] {
                JointKind::Revolute => {
                    wl = wp + axis * v;
                    all = alp + wp.cross(axis * v) + axis * acc_d;
                }
                JointKind::Prismatic => {
                    acc += axis * acc_d + 2.0 * wp.cross(axis * v);
                }
                JointKind::Fixed => {}
            }
        }
        w[l] = wl;
        al[l] = all;
        a[l] = acc;
    }
    // Backward pass: force f and moment n about the link origin that the link's subtree needs.
    let mut f = vec![Vec3::ZERO; nl];
    let mut nm = vec![Vec3::ZERO; nl];
    for l in (0..nl).rev() {
        let (o, r) = poses[l];
        let m = model.link_mass[l];
        if m > 0.0 {
            let rm = Mat3::from_quat(r);
            let inertia = rm * model.link_inertia[l] * rm.transpose();
            let rc = r * model.link_com[l];
            let ac = a[l] + al[l].cross(rc) + w[l].cross(w[l].cross(rc));
            let fc = m * ac;
            f[l] += fc;
            nm[l] += inertia * al[l] + w[l].cross(inertia * w[l]) + rc.cross(fc);
        }
        let parent = model.link_parent[l];
        if parent != NO_LINK {
            let p = parent as usize;
            let (fl, nl_) = (f[l], nm[l]);
            f[p] += fl;
            nm[p] += nl_ + (o - poses[p].0).cross(fl);
        }
        let d = model.link_dof[l];
        if d != NO_DOF {
            let axis = r * model.link_axis[l];
            tau[d as usize] = match model.link_joint[l] {
                JointKind::Prismatic => axis.dot(f[l]),
                _ => axis.dot(nm[l]),
            };
        }
    }
}

/// In-place Cholesky factorisation a = L L^T of the SPD matrix `a` (n x n row-major; only its lower
/// triangle is read, and L is left there; the strict upper triangle is left as it was). Returns false if a
/// pivot was not positive (not numerically positive definite, or NaN): that pivot is then floored at
/// 1e-12 max|diag a| so the factor stays usable (it solves a nearby SPD system) instead of making NaNs.
pub fn cholesky_factor(n: usize, a: &mut [f32]) -> bool {
    let scale = (0..n).map(|i| a[i * n + i].abs()).fold(0.0f32, f32::max);
    let floor = if scale > 0.0 { scale * 1e-12 } else { 1e-30 };
    let mut ok = true;
    for j in 0..n {
        let mut d = a[j * n + j];
        for k in 0..j {
            d -= a[j * n + k] * a[j * n + k];
        }
        // `!(d > floor)` also catches NaN.
        if !(d > floor) {
            ok = false;
            d = floor;
        }
        let ljj = d.sqrt();
        a[j * n + j] = ljj;
        for i in j + 1..n {
            let mut s = a[i * n + j];
            for k in 0..j {
                s -= a[i * n + k] * a[j * n + k];
            }
            a[i * n + j] = s / ljj;
        }
    }
    ok
}

/// Solves L L^T x = b in place with the factor of [`cholesky_factor`].
pub fn cholesky_substitute(n: usize, l: &[f32], b: &mut [f32]) {
    for i in 0..n {
        let mut s = b[i];
        for k in 0..i {
            s -= l[i * n + k] * b[k];
        }
        b[i] = s / l[i * n + i];
    }
    for i in (0..n).rev() {
        let mut s = b[i];
        for k in i + 1..n {
            s -= l[k * n + i] * b[k];
        }
        b[i] = s / l[i * n + i];
    }
}

/// Factorises and solves the SPD system `a x = b` in place (`b` becomes x). Returns false if `a` is not
/// positive definite.
pub fn cholesky_solve(n: usize, a: &mut [f32], b: &mut [f32]) -> bool {
    if !cholesky_factor(n, a) {
        return false;
    }
    cholesky_substitute(n, a, b);
    true
}

/// One world's quantities at one instant, for controllers and tasks.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct WorldDynamics {
    /// Link poses, shape [link_count].
    pub link_pose: Vec<Pose>,
    /// The frame's pose.
    pub frame_pose: Pose,
    /// The frame's linear [m/s] and angular [rad/s] velocity.
    pub frame_linvel: Vec3,
    pub frame_angvel: Vec3,
    /// Geometric Jacobian of the frame, 6 x dof_count row-major.
    pub jacobian: Vec<f32>,
    /// Mass matrix with armature, dof_count x dof_count row-major.
    pub mass_matrix: Vec<f32>,
    /// g(q): joint torques that hold the articulation still against gravity, shape [dof_count].
    pub gravity_torque: Vec<f32>,
    /// c(q, qd): Coriolis and centrifugal torques, shape [dof_count].
    pub coriolis_torque: Vec<f32>,
}

/// Everything a controller needs of one world: link poses, the frame's pose, velocity and Jacobian, M,
/// g and c, at joint state (`q`, `qd`).
pub fn world_dynamics(model: &ArticulationModel, q: &[f32], qd: &[f32], frame: &super::Frame) -> WorldDynamics {
    let n = model.dof_count();
    let mut out = WorldDynamics {
        link_pose: vec![(Vec3::ZERO, Quat::IDENTITY); model.link_count()],
        jacobian: vec![0.0; 6 * n],
        mass_matrix: vec![0.0; n * n],
        gravity_torque: vec![0.0; n],
        coriolis_torque: vec![0.0; n],
        ..Default::default()
    };
    forward_kinematics(model, q, &mut out.link_pose);
    out.frame_pose = frame_pose(&out.link_pose, frame.link, frame.offset);
    point_jacobian(model, &out.link_pose, frame.link, out.frame_pose.0, &mut out.jacobian);
    let mut twist = [0.0f32; 6];
    for (k, t) in twist.iter_mut().enumerate() {
        *t = (0..n).map(|d| out.jacobian[k * n + d] * qd[d]).sum();
    }
    out.frame_linvel = Vec3::new(twist[0], twist[1], twist[2]);
    out.frame_angvel = Vec3::new(twist[3], twist[4], twist[5]);
    mass_matrix(model, &out.link_pose, &mut out.mass_matrix);
    inverse_dynamics(model, &out.link_pose, &vec![0.0; n], &[], true, &mut out.gravity_torque);
    inverse_dynamics(model, &out.link_pose, qd, &[], false, &mut out.coriolis_torque);
    out
}

/// [`world_dynamics`] for every world of `state`, in parallel.
pub fn world_dynamics_batch(
    model: &ArticulationModel,
    state: &ArticulationState,
    frame: &super::Frame,
) -> Vec<WorldDynamics> {
    let n = model.dof_count();
    state
        .joint_q
        .par_chunks(n)
        .zip(state.joint_qd.par_chunks(n))
        .map(|(q, qd)| world_dynamics(model, q, qd, frame))
        .collect()
}

/// The first half of a substep of length `h` for one world (link poses `poses` at the substep's start):
/// with M, c + g at those poses,
///
///   (M + h (D + Kd)) qdd = clamp(tau + Kp (q_t - q) - Kd qd, effort) - c - g - D qd,
///
/// `qd` becomes qd + h qdd, the velocity before any contact. `factor` receives the Cholesky factor of
/// M + h (D + Kd) (the joint-space inertia contact impulses act through this substep). Damping (D: joint
/// damping, Kd: drive damping) is implicit, so a stiff damper cannot destabilise the step; the drive's
/// effort counts against the effort limit, the passive damping does not. Returns false (and leaves `qd`)
/// for a chain without mass.
#[allow(clippy::too_many_arguments)]
pub fn free_velocity(
    model: &ArticulationModel,
    poses: &[Pose],
    q: &[f32],
    qd: &mut [f32],
    tau: &[f32],
    target_q: &[f32],
    h: f32,
    factor: &mut [f32],
) -> bool {
    let n = model.dof_count();
    let mut bias = vec![0.0f32; n];
    mass_matrix(model, poses, factor);
    inverse_dynamics(model, poses, qd, &[], true, &mut bias);
    let mut rhs = vec![0.0f32; n];
    for d in 0..n {
        let kd = model.dof_drive_damping[d];
        let mut actuator = tau.get(d).copied().unwrap_or(0.0);
        let driven = !target_q.is_empty();
        if driven {
            actuator += model.dof_drive_stiffness[d] * (target_q[d] - q[d]) - kd * qd[d];
        }
        let limit = model.dof_effort_limit[d];
        rhs[d] = actuator.clamp(-limit, limit) - bias[d] - model.dof_damping[d] * qd[d];
        factor[d * n + d] += h * (model.dof_damping[d] + if driven { kd } else { 0.0 });
    }
    if !cholesky_factor(n, factor) {
        return false;
    }
    cholesky_substitute(n, factor, &mut rhs);
    for d in 0..n {
        qd[d] += h * rhs[d];
    }
    true
}

/// The second half of a substep: clamps `qd` to the velocity limits, moves q by h qd, and puts a joint
/// that passed a position limit back on it with its velocity into the limit removed.
pub fn integrate_positions(model: &ArticulationModel, q: &mut [f32], qd: &mut [f32], h: f32) {
    for d in 0..model.dof_count() {
        let vmax = model.dof_velocity_limit[d];
        qd[d] = qd[d].clamp(-vmax, vmax);
        q[d] += h * qd[d];
        if q[d] < model.dof_lower[d] {
            q[d] = model.dof_lower[d];
            qd[d] = qd[d].max(0.0);
        } else if q[d] > model.dof_upper[d] {
            q[d] = model.dof_upper[d];
            qd[d] = qd[d].min(0.0);
        }
    }
}

/// Advances one world's joints by `dt` in `substeps` semi-implicit Euler steps under the torques `tau`
/// and drive targets `target_q` (each shape [dof_count] or empty), without contacts: per substep
/// [`free_velocity`] then [`integrate_positions`].
pub fn step_world(
    model: &ArticulationModel,
    q: &mut [f32],
    qd: &mut [f32],
    tau: &[f32],
    target_q: &[f32],
    dt: f32,
    substeps: u32,
) {
    let n = model.dof_count();
    let h = dt / substeps.max(1) as f32;
    let mut poses = vec![(Vec3::ZERO, Quat::IDENTITY); model.link_count()];
    let mut factor = vec![0.0f32; n * n];
    for _ in 0..substeps.max(1) {
        forward_kinematics(model, q, &mut poses);
        if free_velocity(model, &poses, q, qd, tau, target_q, h, &mut factor) {
            integrate_positions(model, q, qd, h);
        }
    }
}

/// How the links that touch things respond to contact impulses during one substep: the contact solver
/// sees each such link as a body whose twist (velocity of its centre of mass, angular velocity) is
/// J_s qd, and an impulse Phi_t (force, torque about the centre of mass of link t) changes it by
/// K_st Phi_t with K_st = J_s A^-1 J_t^T, A = M + h (D + Kd) the substep's joint-space inertia (the
/// operational-space inverse inertia of the links, Khatib 1987). The joints then move with
/// qd = qd_free + sum_t A^-1 J_t^T Phi_t.
#[derive(Clone, Debug)]
pub struct ContactResponse {
    /// The links, in slot order.
    pub links: Vec<u32>,
    /// Per slot, the twist Jacobian at the link's centre of mass, 6 x dof row-major.
    pub jacobian: Vec<Vec<f32>>,
    /// Per slot, A^-1 J^T, dof x 6 row-major.
    pub inv_inertia_jt: Vec<Vec<f32>>,
    /// K_st for slots s, t at index s * slots + t, 6 x 6 row-major.
    pub k: Vec<[f32; 36]>,
}

impl ContactResponse {
    /// The response of `links` at link poses `poses`, with `factor` the Cholesky factor of A.
    pub fn new(model: &ArticulationModel, poses: &[Pose], factor: &[f32], links: &[u32]) -> Self {
        let n = model.dof_count();
        let mut jacobian = Vec::with_capacity(links.len());
        let mut inv_inertia_jt = Vec::with_capacity(links.len());
        for &l in links {
            let (p, r) = poses[l as usize];
            let mut j = vec![0.0f32; 6 * n];
            point_jacobian(model, poses, l, p + r * model.link_com[l as usize], &mut j);
            let mut y = vec![0.0f32; n * 6];
            let mut col = vec![0.0f32; n];
            for k in 0..6 {
                col.copy_from_slice(&j[k * n..(k + 1) * n]);
                cholesky_substitute(n, factor, &mut col);
                for d in 0..n {
                    y[d * 6 + k] = col[d];
                }
            }
            jacobian.push(j);
            inv_inertia_jt.push(y);
        }
        let slots = links.len();
        let mut k = vec![[0.0f32; 36]; slots * slots];
        for s in 0..slots {
            for t in 0..slots {
                let kst = &mut k[s * slots + t];
                for i in 0..6 {
                    for c in 0..6 {
                        kst[i * 6 + c] = (0..n).map(|d| jacobian[s][i * n + d] * inv_inertia_jt[t][d * 6 + c]).sum();
                    }
                }
            }
        }
        ContactResponse { links: links.to_vec(), jacobian, inv_inertia_jt, k }
    }

    /// Twist of slot `s` (velocity of the centre of mass [m/s], angular velocity [rad/s]) at joint
    /// velocities `qd`.
    pub fn twist(&self, s: usize, qd: &[f32]) -> [Vec3; 2] {
        let n = qd.len();
        let row = |k: usize| (0..n).map(|d| self.jacobian[s][k * n + d] * qd[d]).sum::<f32>();
        [Vec3::new(row(0), row(1), row(2)), Vec3::new(row(3), row(4), row(5))]
    }

    /// K_st phi: the twist change of slot `s` for the spatial impulse `phi` (force [N s], torque about
    /// the centre of mass [N m s]) on slot `t`.
    pub fn response(&self, s: usize, t: usize, phi: [Vec3; 2]) -> [Vec3; 2] {
        let k = &self.k[s * self.links.len() + t];
        let x = [phi[0].x, phi[0].y, phi[0].z, phi[1].x, phi[1].y, phi[1].z];
        let row = |i: usize| (0..6).map(|c| k[i * 6 + c] * x[c]).sum::<f32>();
        [Vec3::new(row(0), row(1), row(2)), Vec3::new(row(3), row(4), row(5))]
    }

    /// Adds sum_t A^-1 J_t^T phi_t to `qd` (the joint velocity change from the slots' impulses).
    pub fn apply_impulses(&self, phi: &[[Vec3; 2]], qd: &mut [f32]) {
        for (t, p) in phi.iter().enumerate() {
            let x = [p[0].x, p[0].y, p[0].z, p[1].x, p[1].y, p[1].z];
            for (d, v) in qd.iter_mut().enumerate() {
                *v += (0..6).map(|c| self.inv_inertia_jt[t][d * 6 + c] * x[c]).sum::<f32>();
            }
        }
    }
}

/// [`step_world`] for every world of `state` under `control`, in parallel. Stepping does not fail: a
/// world whose state turns non-finite is reported (true in the returned flags) for the caller to reset.
pub fn step_cpu(
    model: &ArticulationModel,
    state: &mut ArticulationState,
    control: &ArticulationControl,
    dt: f32,
    substeps: u32,
) -> Vec<bool> {
    let n = model.dof_count();
    let per_world =
        |v: &[f32], w: usize| -> Vec<f32> { v.get(w * n..(w + 1) * n).map(<[f32]>::to_vec).unwrap_or_default() };
    state
        .joint_q
        .par_chunks_mut(n)
        .zip(state.joint_qd.par_chunks_mut(n))
        .enumerate()
        .map(|(w, (q, qd))| {
            step_world(
                model,
                q,
                qd,
                &per_world(&control.joint_tau, w),
                &per_world(&control.joint_target_q, w),
                dt,
                substeps,
            );
            !(q.iter().chain(qd.iter()).all(|x| x.is_finite()))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::articulation::{ArticulationModel, JointKind, NO_DOF, NO_LINK};

    /// Two links swinging about y, each a point mass at its tip (lengths l1, l2, masses m1, m2), fixed at the
    /// origin; gravity -z. q = 0 hangs both links along -z... here the links lie along +x at q = 0.
    fn double_pendulum(l1: f32, l2: f32, m1: f32, m2: f32) -> ArticulationModel {
        let tiny = Mat3::ZERO;
        ArticulationModel {
            name: "double pendulum".into(),
            link_name: vec!["base".into(), "upper".into(), "lower".into()],
            link_parent: vec![NO_LINK, 0, 1],
            link_joint: vec![JointKind::Fixed, JointKind::Revolute, JointKind::Revolute],
            link_dof: vec![NO_DOF, 0, 1],
            link_origin: vec![
                (Vec3::ZERO, Quat::IDENTITY),
                (Vec3::ZERO, Quat::IDENTITY),
                (Vec3::new(l1, 0.0, 0.0), Quat::IDENTITY),
            ],
            link_axis: vec![Vec3::Y, Vec3::Y, Vec3::Y],
            link_mass: vec![0.0, m1, m2],
            link_com: vec![Vec3::ZERO, Vec3::new(l1, 0.0, 0.0), Vec3::new(l2, 0.0, 0.0)],
            link_inertia: vec![tiny, tiny, tiny],
            dof_name: vec!["j1".into(), "j2".into()],
            dof_link: vec![1, 2],
            dof_lower: vec![f32::NEG_INFINITY; 2],
            dof_upper: vec![f32::INFINITY; 2],
            dof_velocity_limit: vec![f32::INFINITY; 2],
            dof_effort_limit: vec![f32::INFINITY; 2],
            dof_damping: vec![0.0; 2],
            dof_armature: vec![0.0; 2],
            dof_drive_stiffness: vec![0.0; 2],
            dof_drive_damping: vec![0.0; 2],
            frames: vec![],
            gravity: Vec3::new(0.0, 0.0, -9.81),
        }
    }

    /// The textbook planar double pendulum with point masses (e.g. Spong, Hutchinson, Vidyasagar, "Robot
    /// Modeling and Control", 2006, section 7.4 with zero link inertias): with angles measured in the
    /// plane, M11 = m1 l1^2 + m2 (l1^2 + l2^2 + 2 l1 l2 cos q2), M12 = m2 (l2^2 + l1 l2 cos q2), M22 = m2 l2^2;
    /// c1 = -m2 l1 l2 sin q2 (2 q1' q2' + q2'^2), c2 = m2 l1 l2 sin q2 q1'^2.
    /// Rotation about +y by q takes +x towards -z, so the planar angle from +x is -q; M is unchanged by
    /// the sign flip and c, g flip sign with it.
    #[test]
    fn double_pendulum_matches_the_textbook_equations_of_motion() {
        let (l1, l2, m1, m2) = (0.7f32, 0.4f32, 1.3f32, 0.6f32);
        let model = double_pendulum(l1, l2, m1, m2);
        let g = 9.81f32;
        for &(q1, q2, v1, v2) in &[(0.3f32, -0.8f32, 1.1f32, -0.4f32), (-1.2, 2.0, -0.3, 2.2), (0.0, 0.0, 0.5, 0.5)] {
            let mut poses = vec![(Vec3::ZERO, Quat::IDENTITY); 3];
            forward_kinematics(&model, &[q1, q2], &mut poses);
            let mut m = [0.0f32; 4];
            mass_matrix(&model, &poses, &mut m);
            let c2 = q2.cos();
            let m11 = m1 * l1 * l1 + m2 * (l1 * l1 + l2 * l2 + 2.0 * l1 * l2 * c2);
            let m12 = m2 * (l2 * l2 + l1 * l2 * c2);
            let m22 = m2 * l2 * l2;
            for (got, want) in m.iter().zip([m11, m12, m12, m22]) {
                assert!((got - want).abs() < 1e-5 * m11, "M {m:?} vs {:?}", [m11, m12, m12, m22]);
            }
            // Planar angles th = -q: gravity torque dV/dth with V = g (m1 l1 sin th1 + m2 (l1 sin th1 + l2
            // sin(th1 + th2))) (height of a tip at angle th from +x is l sin th), mapped back: tau_q = -tau_th.
            let (t1, t2) = (-q1, -q2);
            let gth1 = g * (m1 * l1 * t1.cos() + m2 * (l1 * t1.cos() + l2 * (t1 + t2).cos()));
            let gth2 = g * m2 * l2 * (t1 + t2).cos();
            let mut gt = [0.0f32; 2];
            inverse_dynamics(&model, &poses, &[0.0, 0.0], &[], true, &mut gt);
            assert!((gt[0] + gth1).abs() < 1e-4 && (gt[1] + gth2).abs() < 1e-4, "g {gt:?} vs {:?}", [-gth1, -gth2]);
            let (w1, w2) = (-v1, -v2);
            let h = m2 * l1 * l2 * t2.sin();
            let cth = [-h * (2.0 * w1 * w2 + w2 * w2), h * w1 * w1];
            let mut ct = [0.0f32; 2];
            inverse_dynamics(&model, &poses, &[v1, v2], &[], false, &mut ct);
            assert!(
                (ct[0] + cth[0]).abs() < 1e-4 && (ct[1] + cth[1]).abs() < 1e-4,
                "c {ct:?} vs {:?}",
                [-cth[0], -cth[1]]
            );
        }
    }

    #[test]
    fn inverse_dynamics_is_linear_in_acceleration_through_the_mass_matrix() {
        let model = double_pendulum(0.5, 0.3, 2.0, 0.7);
        let mut poses = vec![(Vec3::ZERO, Quat::IDENTITY); 3];
        forward_kinematics(&model, &[0.4, 1.0], &mut poses);
        let mut m = [0.0f32; 4];
        mass_matrix(&model, &poses, &mut m);
        let (qd, qdd) = ([0.3f32, -1.2f32], [2.0f32, -0.5f32]);
        let mut full = [0.0f32; 2];
        let mut bias = [0.0f32; 2];
        inverse_dynamics(&model, &poses, &qd, &qdd, true, &mut full);
        inverse_dynamics(&model, &poses, &qd, &[], true, &mut bias);
        for i in 0..2 {
            let mq = m[i * 2] * qdd[0] + m[i * 2 + 1] * qdd[1];
            assert!((full[i] - bias[i] - mq).abs() < 1e-5, "row {i}: {} vs {}", full[i] - bias[i], mq);
        }
    }

    #[test]
    fn cholesky_solves_an_spd_system_and_refuses_an_indefinite_one() {
        let a = [4.0f32, 2.0, 0.6, 2.0, 5.0, 1.0, 0.6, 1.0, 3.0];
        let x = [1.0f32, -2.0, 0.5];
        let mut b: Vec<f32> = (0..3).map(|i| (0..3).map(|j| a[i * 3 + j] * x[j]).sum()).collect();
        let mut f = a;
        assert!(cholesky_solve(3, &mut f, &mut b));
        for i in 0..3 {
            assert!((b[i] - x[i]).abs() < 1e-5, "{b:?}");
        }
        let mut bad = [1.0f32, 2.0, 2.0, 1.0];
        assert!(!cholesky_solve(2, &mut bad, &mut [1.0, 1.0]));
    }

    /// A frictionless pendulum released from rest keeps its energy: semi-implicit Euler is symplectic, so
    /// the energy oscillates within O(h) of its start and does not grow.
    #[test]
    fn free_double_pendulum_keeps_its_energy() {
        let (l1, l2, m1, m2) = (0.5f32, 0.4f32, 1.0f32, 0.8f32);
        let model = double_pendulum(l1, l2, m1, m2);
        let (mut q, mut qd) = ([0.3f32, 0.5f32], [0.0f32, 0.0f32]);
        let energy = |q: &[f32], qd: &[f32]| -> f32 {
            let mut poses = vec![(Vec3::ZERO, Quat::IDENTITY); 3];
            forward_kinematics(&model, q, &mut poses);
            let mut m = [0.0f32; 4];
            mass_matrix(&model, &poses, &mut m);
            let ke = 0.5 * (qd[0] * (m[0] * qd[0] + m[1] * qd[1]) + qd[1] * (m[2] * qd[0] + m[3] * qd[1]));
            let pe: f32 =
                (1..3).map(|l| model.link_mass[l] * 9.81 * (poses[l].0 + poses[l].1 * model.link_com[l]).z).sum();
            ke + pe
        };
        let e0 = energy(&q, &qd);
        let mut worst = 0.0f32;
        for _ in 0..600 {
            step_world(&model, &mut q, &mut qd, &[], &[], 1.0 / 60.0, 8);
            worst = worst.max((energy(&q, &qd) - e0).abs());
        }
        // Scale: the potential energy range of the swing, about (m1 + m2) g (l1 + l2) = 15.9 J.
        assert!(worst < 0.05 * 15.9, "energy wandered by {worst} J from {e0} J");
    }
}

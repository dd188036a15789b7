//! The CPU step ([`step_cpu`], [`step_cpu_articulated`]): every world in parallel and each exactly as
//! alone: the frame's rows from the world's reduced contacts, warm-started from last frame's, then per
//! substep the velocities, the position sweeps, the positions and the velocity sweeps (module doc of
//! [`super`]), with the articulation's joints moved by the impulses its link bodies took.

use super::model::{xf, BodyModel, BodyState, Control, SolverConfig};
use super::rows::{Row, StepVelocities, SubstepInputs};
use super::sweep::{solve_rows, RowIdleTest};
use super::warm_start::{take_over, WarmStart, WARM_DISTANCE};
use crate::articulation::{dynamics, ArticulationControl, ArticulationModel, ArticulationState};
use crate::contact::model::{FlatModel, NO_BODY};
use crate::contact::{ContactsHost, TransformGpu};
use glam::{Quat, Vec3, Vec4};
use rayon::prelude::*;

/// Advances every world by one frame of `cfg.dt` with the contacts generated at the frame's start.
/// `flat` is the contact model the contacts came from (its pairs give the bodies, shape poses, SDFs and
/// friction coefficients; `NO_BODY` = the static world). `control` adds external wrenches (may be empty).
/// Returns, per world, whether it stayed finite and below `max_speed` (a diverged world is left as is, for
/// the caller to reset; other worlds are unaffected).
pub fn step_cpu(
    model: &BodyModel,
    state: &mut BodyState,
    contacts: &ContactsHost,
    flat: &FlatModel,
    cfg: &SolverConfig,
    control: &Control,
    warm: &mut WarmStart,
) -> Vec<bool> {
    step_cpu_articulated(model, state, contacts, flat, cfg, control, warm, None)
}

/// A world's articulation for [`step_cpu_articulated`]: the model every world shares, every world's joint
/// state (advanced by the step) and the joint torques and drive targets held over the frame.
pub struct ArticulationStep<'a> {
    pub model: &'a ArticulationModel,
    pub state: &'a mut ArticulationState,
    pub control: &'a ArticulationControl,
}

/// [`step_cpu`] with an articulation in every world whose links are bodies of `model`
/// ([`BodyModel::add_articulated`]): the joints and the bodies are solved together (mixed coordinates).
/// Per substep the articulation's velocity before contact comes from the joint torques
/// ([`dynamics::free_velocity`]); the contact rows see each link body through its twist and the
/// joint-space inertia ([`dynamics::ContactResponse`]), so a finger squeezing a nut feels the arm's inertia
/// and its drives, not an infinite mass; the joints then move with the impulses the rows applied, and the
/// link bodies' poses follow by forward kinematics. External wrenches on link bodies are ignored (push on
/// the joints instead). Returns per world whether it stayed finite and within `max_speed` (joint
/// velocities included).
#[allow(clippy::too_many_arguments)]
pub fn step_cpu_articulated(
    model: &BodyModel,
    state: &mut BodyState,
    contacts: &ContactsHost,
    flat: &FlatModel,
    cfg: &SolverConfig,
    control: &Control,
    warm: &mut WarmStart,
    art: Option<ArticulationStep>,
) -> Vec<bool> {
    step_cpu_articulated_with(model, state, contacts, flat, cfg, control, warm, art, PatchSweep::Block)
}

/// How [`step_cpu_articulated`] runs a patch's repeated passes within a sweep (`patch_iters`,
/// `link_patch_iters`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PatchSweep {
    /// On the patch's Delassus matrix, where every row has its articulated-substep cache (the default; see
    /// `solve_patch_block`).
    #[default]
    Block,
    /// Row by row through the bodies' velocities, every pass (what solver.wgsl and articulated.wgsl do):
    /// the reference the blocks are tested against.
    Rows,
}

/// [`step_cpu_articulated`] with the patches' passes run as `sweep` says.
#[allow(clippy::too_many_arguments)]
pub fn step_cpu_articulated_with(
    model: &BodyModel,
    state: &mut BodyState,
    contacts: &ContactsHost,
    flat: &FlatModel,
    cfg: &SolverConfig,
    control: &Control,
    warm: &mut WarmStart,
    mut art: Option<ArticulationStep>,
    sweep: PatchSweep,
) -> Vec<bool> {
    let nb = model.body_count();
    // Link bodies in slot order, and each body's slot.
    let link_bodies: Vec<usize> = (0..nb).filter(|&i| model.link(i).is_some()).collect();
    let links: Vec<u32> = link_bodies.iter().map(|&i| model.link(i).unwrap()).collect();
    let mut slot = vec![None; nb + 1];
    for (s, &i) in link_bodies.iter().enumerate() {
        slot[i] = Some(s);
    }
    assert!(link_bodies.is_empty() || art.is_some(), "a model with articulated bodies needs its articulation");
    let world_count = state.body_q.len() / nb.max(1);
    warm.rows.resize(world_count, Vec::new());
    let inputs = FrameInputs {
        model,
        state,
        contacts,
        flat,
        cfg,
        control,
        warm,
        art: art.as_ref().map(|a| (a.model, &*a.state, a.control)),
        link_bodies: &link_bodies,
        links: &links,
        slot: &slot,
        h: cfg.dt / cfg.substeps as f32,
        sweep,
    };
    // Worlds are independent: stepped in parallel, each exactly as alone (results do not depend on the
    // thread count).
    let outs: Vec<WorldStepOutput> = (0..world_count).into_par_iter().map(|w| step_world(&inputs, w)).collect();
    let mut ok = Vec::with_capacity(world_count);
    for (w, out) in outs.into_iter().enumerate() {
        warm.rows[w] = out.rows;
        state.body_q[w * nb..(w + 1) * nb].copy_from_slice(&out.body_q);
        state.body_qd[w * nb..(w + 1) * nb].copy_from_slice(&out.body_qd);
        if let (Some(a), Some((q, qd))) = (art.as_mut(), out.joints) {
            let n = a.model.dof_count();
            a.state.joint_q[w * n..(w + 1) * n].copy_from_slice(&q);
            a.state.joint_qd[w * n..(w + 1) * n].copy_from_slice(&qd);
        }
        ok.push(out.ok);
    }
    ok
}

/// What every world of one [`step_cpu_articulated_with`] reads: its arguments, the articulation's link
/// bodies and the substep length.
struct FrameInputs<'a> {
    model: &'a BodyModel,
    state: &'a BodyState,
    contacts: &'a ContactsHost,
    flat: &'a FlatModel,
    cfg: &'a SolverConfig,
    control: &'a Control,
    /// Last frame's rows.
    warm: &'a WarmStart,
    /// The articulation's model, every world's joint state and the joint control.
    art: Option<(&'a ArticulationModel, &'a ArticulationState, &'a ArticulationControl)>,
    /// The link bodies in slot order, the link each is, and each body's slot (shape [body_count + 1]).
    link_bodies: &'a [usize],
    links: &'a [u32],
    slot: &'a [Option<usize>],
    /// Substep length [s].
    h: f32,
    sweep: PatchSweep,
}

/// One world's joint positions, velocities, torques and drive targets during a step.
type WorldJoints = (Vec<f32>, Vec<f32>, Vec<f32>, Vec<f32>);

/// One frame of world `w`: its rows, then the substeps.
fn step_world(f: &FrameInputs, w: usize) -> WorldStepOutput {
    let (model, cfg, h, nb) = (f.model, f.cfg, f.h, f.model.body_count());
    let (link_bodies, links) = (f.link_bodies, f.links);
    let base = w * nb;
    // Index nb stands for the static world (infinite mass, identity pose).
    let mut pos: Vec<(Vec3, Quat)> = (0..nb).map(|i| xf(&f.state.body_q[base + i])).collect();
    pos.push((Vec3::ZERO, Quat::IDENTITY));
    let mut vel =
        StepVelocities { v: f.state.body_qd[base..base + nb].to_vec(), phi: vec![[Vec3::ZERO; 2]; links.len()] };
    vel.v.push([Vec3::ZERO; 2]);
    // This world's joints, and the link poses they give (used for the frame's rows: the caller keeps
    // the link bodies' poses in the state at the joints' forward kinematics).
    let mut joints = f.art.map(|(am, ast, actl)| {
        let n = am.dof_count();
        let w_slice = |v: &[f32]| v.get(w * n..(w + 1) * n).map(<[f32]>::to_vec).unwrap_or_default();
        let q = ast.joint_q[w * n..(w + 1) * n].to_vec();
        let qd = ast.joint_qd[w * n..(w + 1) * n].to_vec();
        (q, qd, w_slice(&actl.joint_tau), w_slice(&actl.joint_target_q))
    });
    let mut link_pose = f.art.map(|(am, _, _)| vec![(Vec3::ZERO, Quat::IDENTITY); am.link_count()]);
    if let (Some((am, _, _)), Some((q, _, _, _)), Some(lp)) = (f.art, joints.as_ref(), link_pose.as_mut()) {
        dynamics::forward_kinematics(am, q, lp);
        for (s, &i) in link_bodies.iter().enumerate() {
            pos[i] = lp[links[s] as usize];
        }
    }
    let mut ctx = SubstepInputs { flat: f.flat, model, cfg, h, links: None, slot: f.slot, link_bodies };
    let mut rows = frame_rows(f, w, &pos);
    // Each link patch's Delassus matrix for the substep's sweeps (solve_rows).
    let mut blocks = (f.sweep == PatchSweep::Block).then(Vec::new);
    // Each row's normal test for the sweeps (solve_rows), rebuilt with the rows' caches.
    let mut idle = vec![RowIdleTest::default(); rows.len()];
    for _ in 0..cfg.substeps {
        // The articulation's velocity before contact, and how its links answer impulses this substep.
        if let (Some((am, _, _)), Some((q, qd, tau, target)), Some(lp)) = (f.art, joints.as_mut(), link_pose.as_mut()) {
            let n = am.dof_count();
            let mut factor = vec![0.0f32; n * n];
            dynamics::forward_kinematics(am, q, lp);
            if dynamics::free_velocity(am, lp, q, qd, tau, target, h, &mut factor) {
                let resp = dynamics::ContactResponse::new(am, lp, &factor, links);
                for (s, &i) in link_bodies.iter().enumerate() {
                    vel.v[i] = resp.twist(s, qd);
                }
                ctx.links = Some(resp);
            }
            vel.phi.iter_mut().for_each(|p| *p = [Vec3::ZERO; 2]);
        }
        integrate_velocities(&ctx, f.control, base, &pos, &mut vel);
        // Warm start: the previous substep's impulses (or the matched row's of last frame) along the
        // normal each row was solved with. The sweeps then correct them: a row's impulses are those of
        // the current substep (accumulated and clamped per substep).
        for r in rows.iter() {
            if let Some(n) = r.normal {
                let t1 = n.any_orthonormal_vector();
                let imp = r.lambda_n * n + r.lambda_t[0] * t1 + r.lambda_t[1] * n.cross(t1);
                ctx.apply(r, &ctx.lever(r, &pos, n), &mut vel, imp);
            }
        }
        // The poses stand still during the sweeps, so each row's separation and normal are sampled in
        // the first sweep and reused by the others (sampled again once the bodies have moved).
        for it in 0..cfg.pos_iters {
            solve_rows(&ctx, &mut rows, &mut idle, &pos, &mut vel, true, it == 0, blocks.as_mut());
        }
        integrate_positions(&ctx, &mut pos, &vel);
        // The joints move with the impulses the position sweeps applied; the links follow.
        if let (Some((am, _, _)), Some((q, qd, _, _)), Some(lp), Some(resp)) =
            (f.art, joints.as_mut(), link_pose.as_mut(), ctx.links.as_ref())
        {
            resp.apply_impulses(&vel.phi, qd);
            dynamics::integrate_positions(am, q, qd, h);
            dynamics::forward_kinematics(am, q, lp);
            vel.phi.iter_mut().for_each(|p| *p = [Vec3::ZERO; 2]);
            for (s, &i) in link_bodies.iter().enumerate() {
                pos[i] = lp[links[s] as usize];
                // The substep's Jacobians serve the velocity sweeps too (the poses moved by h qd).
                vel.v[i] = resp.twist(s, qd);
            }
        }
        for it in 0..cfg.vel_iters {
            solve_rows(&ctx, &mut rows, &mut idle, &pos, &mut vel, false, it == 0, blocks.as_mut());
        }
        if let (Some((_, qd, _, _)), Some(resp)) = (joints.as_mut(), ctx.links.as_ref()) {
            resp.apply_impulses(&vel.phi, qd);
            vel.phi.iter_mut().for_each(|p| *p = [Vec3::ZERO; 2]);
            for (s, &i) in link_bodies.iter().enumerate() {
                vel.v[i] = resp.twist(s, qd);
            }
        }
    }
    finish_world(cfg, nb, rows, pos, vel, joints)
}

/// World `w`'s rows from its reduced contacts, anchored in the bodies' frames at the poses `pos` (index
/// body_count: the static world), each warm-started from last frame's row of the same contact.
fn frame_rows(f: &FrameInputs, w: usize, pos: &[(Vec3, Quat)]) -> Vec<Row> {
    let (flat, nb) = (f.flat, f.model.body_count());
    let pair_count = flat.pairs.len();
    let body = |b: u32| if b == NO_BODY { nb } else { b as usize };
    let mut rows = Vec::new();
    for p in 0..pair_count {
        let (a, b) = (body(flat.pairs[p].body_a), body(flat.pairs[p].body_b));
        let tol = WARM_DISTANCE * flat.pairs[p].contact_offset;
        for (i, patch) in f.contacts.patches[w * pair_count + p].iter().enumerate() {
            let old = f.warm.patch_rows(w, p, i);
            for c in &patch.contacts {
                let ((pa, qa), (pb, qb)) = (pos[a], pos[b]);
                let mut row = Row {
                    a,
                    b,
                    pair: p,
                    patch: i,
                    anchor_a: qa.inverse() * (c.point + flat.pairs[p].radius * patch.normal - pa),
                    mu: flat.pairs[p].friction,
                    lambda_n: 0.0,
                    lambda_t: [0.0; 2],
                    normal: None,
                    sep: 0.0,
                    point_b: qb.inverse() * (c.point - pb),
                    cache: None,
                };
                take_over(&mut row, old, patch.normal, tol);
                rows.push(row);
            }
        }
    }
    rows
}

/// A substep's gravity and external wrenches on the velocities of the bodies with mass (`ctx.h` long;
/// `base`: the world's first body in `control`).
fn integrate_velocities(
    ctx: &SubstepInputs,
    control: &Control,
    base: usize,
    pos: &[(Vec3, Quat)],
    vel: &mut StepVelocities,
) {
    let (model, h) = (ctx.model, ctx.h);
    for (i, v) in vel.v.iter_mut().enumerate().take(model.body_count()) {
        if ctx.inv_m(i) > 0.0 {
            let [f, tau] = control.wrench(base + i);
            v[0] += (model.gravity + ctx.inv_m(i) * f) * h;
            // The world inverse inertia only where a torque acts (solver.wgsl alike).
            if tau != Vec3::ZERO {
                v[1] += ctx.inv_i_world(i, pos[i].1) * tau * h;
            }
        }
    }
}

/// A substep's motion of the bodies with mass and the kinematic ones at their velocities (link bodies
/// follow their joints instead).
fn integrate_positions(ctx: &SubstepInputs, pos: &mut [(Vec3, Quat)], vel: &StepVelocities) {
    let (model, h) = (ctx.model, ctx.h);
    for (i, pose) in pos.iter_mut().enumerate().take(model.body_count()) {
        if (ctx.inv_m(i) > 0.0 || model.is_kinematic(i)) && ctx.slot[i].is_none() {
            let (p, q) = *pose;
            let c = p + q * ctx.com(i);
            let c2 = c + vel.v[i][0] * h;
            let w = vel.v[i][1];
            let dq = Quat::from_xyzw(w.x, w.y, w.z, 0.0) * q * (0.5 * h);
            let q2 = Quat::from_vec4(Vec4::from(q) + Vec4::from(dq)).normalize();
            *pose = (c2 - q2 * ctx.com(i), q2);
        }
    }
}

/// What a world's step hands back, from its final rows, poses, velocities and joints; not ok where a body
/// or joint turned non-finite or faster than `cfg.max_speed`.
fn finish_world(
    cfg: &SolverConfig,
    nb: usize,
    rows: Vec<Row>,
    pos: Vec<(Vec3, Quat)>,
    mut vel: StepVelocities,
    joints: Option<WorldJoints>,
) -> WorldStepOutput {
    let mut ok = true;
    let mut body_q = Vec::with_capacity(nb);
    for (i, &(p, q)) in pos.iter().enumerate().take(nb) {
        body_q.push(TransformGpu::new(p, q));
        let finite = p.is_finite() && q.is_finite() && vel.v[i][0].is_finite() && vel.v[i][1].is_finite();
        if !finite || vel.v[i][0].length() > cfg.max_speed {
            ok = false;
        }
    }
    vel.v.truncate(nb);
    let joints = joints.map(|(q, qd, _, _)| {
        if !q.iter().chain(qd.iter()).all(|x| x.is_finite()) || qd.iter().any(|v| v.abs() > cfg.max_speed) {
            ok = false;
        }
        (q, qd)
    });
    WorldStepOutput { rows, body_q, body_qd: vel.v, joints, ok }
}

/// What one world's step hands back: its rows (next frame's warm start), bodies, joints and whether it
/// stayed finite and within the speed bound.
struct WorldStepOutput {
    rows: Vec<Row>,
    body_q: Vec<TransformGpu>,
    body_qd: Vec<[Vec3; 2]>,
    joints: Option<(Vec<f32>, Vec<f32>)>,
    ok: bool,
}

/// One frame of the CPU reference on contacts from `contacts` (the GPU kernels) at the state's poses: what
/// the tests compare the GPU solver with. Returns [`step_cpu`]'s per-world flags.
pub fn step_cpu_with_pipeline(
    gpu: &crate::gpu::GpuContext,
    contacts: &crate::contact::ContactPipeline,
    model: &BodyModel,
    state: &mut BodyState,
    cfg: &SolverConfig,
    control: &Control,
    warm: &mut WarmStart,
) -> Vec<bool> {
    contacts.write_body_q(gpu, &state.body_q);
    contacts.run(gpu);
    step_cpu(model, state, &contacts.read(gpu), &contacts.flat, cfg, control, warm)
}

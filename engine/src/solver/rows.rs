//! The contact rows of a CPU step and what updating one reads: a row is one reduced contact anchored in
//! its query body, with its impulses and, per substep, a cache of its lever arms, tangents and effective
//! masses ([`RowCache`]); [`SubstepInputs`] holds the bodies, settings and articulation response a row's update
//! reads, [`StepVelocities`] the velocities it changes.

use super::model::{BodyModel, SolverConfig};
use crate::articulation::dynamics;
use crate::contact::model::FlatModel;
use glam::{Mat3, Quat, Vec3};

/// One contact prepared for the solver.
#[derive(Clone, Copy, Debug)]
pub(super) struct Row {
    pub(super) a: usize,
    pub(super) b: usize,
    pub(super) pair: usize,
    /// Index of the patch within its pair (rows are matched across frames within a patch).
    pub(super) patch: usize,
    /// The query element's point (contact point + radius along the normal) in a's body frame [m].
    pub(super) anchor_a: Vec3,
    pub(super) mu: f32,
    /// Impulses of the current substep [N s].
    pub(super) lambda_n: f32,
    pub(super) lambda_t: [f32; 2],
    /// The normal the row was last sampled with, world frame (None before its first sample, or when the
    /// SDF had no gradient there).
    pub(super) normal: Option<Vec3>,
    /// The separation at that sample [m].
    pub(super) sep: f32,
    /// The contact point in b's body frame at the frame's start [m] (to match the row next frame).
    pub(super) point_b: Vec3,
    /// What the sweeps after a sample reuse: the lever arms and inverse inertias at the sampled normal,
    /// the tangents, and the inverse effective masses along the normal and the tangents (None until the
    /// row's first sample of the substep; the poses and the articulation's response stand still between
    /// samples, so these are the values each sweep would recompute, bitwise).
    pub(super) cache: Option<RowCache>,
}

/// What a row's sweeps reuse between samples ([`Row::cache`]).
#[derive(Clone, Copy, Debug)]
pub(super) struct RowCache {
    pub(super) lever: LeverArms,
    pub(super) tangents: [Vec3; 2],
    /// Inverse effective mass along the normal, tangent 1 and tangent 2 [1/kg].
    pub(super) k: [f32; 3],
    /// In an articulated substep: what a unit impulse along the normal, tangent 1 and tangent 2 does to
    /// every body it moves, and the angular parts of the velocity Jacobians (None: no articulation, or
    /// more link bodies than [`LINK_DIR_BODIES`] holds; those go through [`SubstepInputs::apply`], as solver.wgsl).
    pub(super) link: Option<[RowDirection; 3]>,
}

/// The most bodies one [`RowDirection`] moves: the row's two rigid sides and the articulation's link bodies.
pub(super) const LINK_DIR_BODIES: usize = 4;

/// The velocity change a unit impulse along one direction of a row on an articulation link makes: the
/// row's rigid bodies through their mass and inertia, and every link body through the substep's K blocks
/// (an impulse on one finger moves the arm, so the other finger too). [`SubstepInputs::apply`] computes the same
/// per impulse from the K blocks (a 6 x 6 product per link body and side); the finger pads' rows are swept
/// `link_patch_iters` times per sweep, and that product is about half of an articulated step when
/// recomputed per impulse. In an articulated step the rows between rigid bodies (the nut on the thread)
/// keep one too, with the direction's Jacobian and effective mass, which makes a Screw env step about a
/// quarter faster than recomputing lever products and dividing per impulse (docs/BENCHMARKS.md).
/// Rigid-only steps keep the lever form, which solver.wgsl mirrors.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct RowDirection {
    /// The direction d (world frame) and its angular Jacobians on a and b: ra x d and rb x d [m], so the
    /// relative velocity along d is (va - vb) . d + wa . (ra x d) - wb . (rb x d) (two dot products per
    /// side where the lever form takes a cross product more).
    pub(super) d: Vec3,
    pub(super) jac: [Vec3; 2],
    /// Effective mass along d [kg] (the inverse of the row's k, 0 where k is not positive): a product per
    /// impulse where the lever form divides.
    pub(super) mass: f32,
    /// (body, twist change [m/s, rad/s] per N s), the first `moved_len` used.
    pub(super) moved: [(u32, [Vec3; 2]); LINK_DIR_BODIES],
    pub(super) moved_len: u8,
    /// (articulation slot, spatial impulse [N s, N m s] per N s), the first `phi_len` used.
    pub(super) phi: [(u32, [Vec3; 2]); 2],
    pub(super) phi_len: u8,
}

impl RowDirection {
    /// The relative velocity of row sides `a` and `b` along the direction [m/s].
    #[inline]
    pub(super) fn rel(&self, vel: &StepVelocities, a: usize, b: usize) -> f32 {
        dir_rel(self.d, &self.jac, vel, a, b)
    }

    /// Applies `x` [N s] along the direction: the bodies' twists and the slots' spatial impulses.
    #[inline]
    pub(super) fn apply(&self, vel: &mut StepVelocities, x: f32) {
        for (body, dv) in &self.moved[..self.moved_len as usize] {
            let v = &mut vel.v[*body as usize];
            v[0] += dv[0] * x;
            v[1] += dv[1] * x;
        }
        for (slot, phi) in &self.phi[..self.phi_len as usize] {
            let p = &mut vel.phi[*slot as usize];
            p[0] += phi[0] * x;
            p[1] += phi[1] * x;
        }
    }
}

/// The relative velocity of row sides `a` and `b` along direction `d` with angular Jacobians `jac` [m/s]
/// ([`RowDirection::rel`], and [`RowIdleTest`]'s copy of the normal's, so that both test alike bitwise).
#[inline]
pub(super) fn dir_rel(d: Vec3, jac: &[Vec3; 2], vel: &StepVelocities, a: usize, b: usize) -> f32 {
    let (va, vb) = (&vel.v[a], &vel.v[b]);
    (va[0] - vb[0]).dot(d) + va[1].dot(jac[0]) - vb[1].dot(jac[1])
}

/// What every row of one world's step reads: the contact model, the bodies, the settings and the substep.
/// Body index `model.body_count()` is the static world (infinite mass, identity pose).
pub(super) struct SubstepInputs<'a> {
    pub(super) flat: &'a FlatModel,
    pub(super) model: &'a BodyModel,
    pub(super) cfg: &'a SolverConfig,
    /// Substep length [s].
    pub(super) h: f32,
    /// This substep's articulation response (None: no articulated bodies, or a massless chain).
    pub(super) links: Option<dynamics::ContactResponse>,
    /// Each body's articulation slot (index body_count, the static world, has none), shape [body_count + 1].
    pub(super) slot: &'a [Option<usize>],
    /// The body of each slot.
    pub(super) link_bodies: &'a [usize],
}

/// The bodies' velocities during a step (twist of the centre of mass: linear [m/s], angular [rad/s];
/// index body_count is the static world), and the spatial impulses (force [N s], torque about the centre
/// of mass [N m s]) applied to each articulation slot since its joints last took them.
pub(super) struct StepVelocities {
    pub(super) v: Vec<[Vec3; 2]>,
    pub(super) phi: Vec<[Vec3; 2]>,
}

impl SubstepInputs<'_> {
    pub(super) fn inv_m(&self, i: usize) -> f32 {
        self.model.body_inv_mass.get(i).copied().unwrap_or(0.0)
    }

    pub(super) fn com(&self, i: usize) -> Vec3 {
        self.model.body_com.get(i).copied().unwrap_or(Vec3::ZERO)
    }

    /// World-frame inverse inertia of body `i` at rotation `q` (zero for static and kinematic bodies).
    pub(super) fn inv_i_world(&self, i: usize, q: Quat) -> Mat3 {
        if self.inv_m(i) > 0.0 {
            let r = Mat3::from_quat(q);
            r * self.model.body_inv_inertia[i] * r.transpose()
        } else {
            Mat3::ZERO
        }
    }

    /// The row's lever arms and the bodies' world inverse inertias, for contact normal `n`.
    pub(super) fn lever(&self, r: &Row, pos: &[(Vec3, Quat)], n: Vec3) -> LeverArms {
        let ((pa, qa), (pb, qb)) = (pos[r.a], pos[r.b]);
        // The contact point on a's surface.
        let xa = pa + qa * r.anchor_a - self.flat.pairs[r.pair].radius * n;
        LeverArms {
            ra: xa - (pa + qa * self.com(r.a)),
            rb: xa - (pb + qb * self.com(r.b)),
            ia: self.inv_i_world(r.a, qa),
            ib: self.inv_i_world(r.b, qb),
        }
    }

    /// The spatial impulses (force, torque about the centre of mass) a unit `d` at the row's point puts on
    /// its bodies that are articulation links: (slot, impulse) for a, then b (which takes the opposite).
    fn link_impulses(&self, r: &Row, l: &LeverArms, d: Vec3) -> [Option<(usize, [Vec3; 2])>; 2] {
        [self.slot[r.a].map(|s| (s, [d, l.ra.cross(d)])), self.slot[r.b].map(|s| (s, [-d, -l.rb.cross(d)]))]
    }

    /// Inverse effective mass of the row along unit `d` [1/kg]: rigid bodies through their mass and
    /// inertia, articulation links through the substep's K blocks (cross terms included when both sides are
    /// links of the articulation).
    pub(super) fn eff(&self, r: &Row, l: &LeverArms, d: Vec3) -> f32 {
        let (ca, cb) = (l.ra.cross(d), l.rb.cross(d));
        // Zero for link bodies: their inverse mass and inertia are zero in the body model.
        let mut k = self.inv_m(r.a) + self.inv_m(r.b) + ca.dot(l.ia * ca) + cb.dot(l.ib * cb);
        if let Some(resp) = &self.links {
            let sides = self.link_impulses(r, l, d);
            for (s, us) in sides.iter().flatten() {
                for (t, ut) in sides.iter().flatten() {
                    let dv = resp.response(*s, *t, *ut);
                    k += us[0].dot(dv[0]) + us[1].dot(dv[1]);
                }
            }
        }
        k
    }

    /// The [`RowDirection`] of a row along unit `d` in an articulated substep, for rows between rigid bodies
    /// too (their impulses then skip [`SubstepInputs::apply`]'s per-impulse inertia products); None without an
    /// articulation response, or when the row touches a link and the articulation has more link bodies
    /// than a [`RowDirection`] holds.
    pub(super) fn link_dir(&self, r: &Row, l: &LeverArms, d: Vec3) -> Option<RowDirection> {
        let resp = self.links.as_ref()?;
        let sides = self.link_impulses(r, l, d);
        let on_link = sides.iter().any(Option::is_some);
        if on_link && self.link_bodies.len() + 2 > LINK_DIR_BODIES {
            return None;
        }
        let mut out = RowDirection { d, jac: [l.ra.cross(d), l.rb.cross(d)], ..RowDirection::default() };
        let mut push = |body: usize, dv: [Vec3; 2]| {
            out.moved[out.moved_len as usize] = (body as u32, dv);
            out.moved_len += 1;
        };
        if self.inv_m(r.a) > 0.0 {
            push(r.a, [self.inv_m(r.a) * d, l.ia * l.ra.cross(d)]);
        }
        if self.inv_m(r.b) > 0.0 {
            push(r.b, [-self.inv_m(r.b) * d, -(l.ib * l.rb.cross(d))]);
        }
        // A row between rigid bodies moves no link.
        let link_bodies = if on_link { self.link_bodies } else { &[] };
        for (s, &body) in link_bodies.iter().enumerate() {
            let mut dv = [Vec3::ZERO; 2];
            for (t, phi) in sides.iter().flatten() {
                let r = resp.response(s, *t, *phi);
                dv[0] += r[0];
                dv[1] += r[1];
            }
            push(body, dv);
        }
        for (t, phi) in sides.into_iter().flatten() {
            out.phi[out.phi_len as usize] = (t as u32, phi);
            out.phi_len += 1;
        }
        Some(out)
    }

    /// Applies impulse `imp` [N s] to a and its opposite to b.
    pub(super) fn apply(&self, r: &Row, l: &LeverArms, vel: &mut StepVelocities, imp: Vec3) {
        vel.v[r.a][0] += self.inv_m(r.a) * imp;
        vel.v[r.a][1] += l.ia * l.ra.cross(imp);
        vel.v[r.b][0] -= self.inv_m(r.b) * imp;
        vel.v[r.b][1] -= l.ib * l.rb.cross(imp);
        if let Some(resp) = &self.links {
            for (t, phi) in self.link_impulses(r, l, imp).into_iter().flatten() {
                vel.phi[t][0] += phi[0];
                vel.phi[t][1] += phi[1];
                // An impulse on one link moves every link of the articulation.
                for (s, &body) in self.link_bodies.iter().enumerate() {
                    let dv = resp.response(s, t, phi);
                    vel.v[body][0] += dv[0];
                    vel.v[body][1] += dv[1];
                }
            }
        }
    }
}

/// Lever arms from each body's centre of mass to a row's contact point [m] and the bodies' world-frame
/// inverse inertias [1/(kg m^2)] (zero for static and kinematic bodies).
#[derive(Clone, Copy, Debug)]
pub(super) struct LeverArms {
    pub(super) ra: Vec3,
    pub(super) rb: Vec3,
    pub(super) ia: Mat3,
    pub(super) ib: Mat3,
}

//! Rigid-body dynamics with a Gauss-Seidel contact solver (paper III-B: after contact reduction, a
//! Gauss-Seidel solver converges in 1 substep and ~16-20 iterations at dt = 1/60 s where Jacobi needs 8
//! substeps and 64 iterations).
//!
//! This module is the plain-Rust reference ([`step_cpu`]): one world after another, contacts in a fixed
//! order, so results are bitwise reproducible. The GPU kernels will mirror it (one invocation per world:
//! Gauss-Seidel is serial inside a world and parallel across worlds).
//!
//! Scheme, per substep of length h = dt / substeps (a TGS-style "soft step" in the spirit of PhysX TGS and
//! Box2D v3): (1) integrate velocities (gravity); (2) `pos_iters` Gauss-Seidel sweeps over the contacts
//! with a position bias; (3) integrate positions; (4) `vel_iters` sweeps without the penetration bias
//! (v_n >= 0 for touching contacts, restitution 0). A contact is the reduced contact's point anchored in
//! the query body; at every substep (positions) and after it (velocities) its separation s and normal n
//! are re-evaluated by sampling the SDF shape at the anchor's current position (the SDF is at hand, so no linearisation: a nut that turns 27
//! degrees in one 1/60 s frame would otherwise see its flank contacts, projected on frame-start tangent
//! planes, penetrate by ~0.4 mm and be pushed back). The normal velocity is driven to v_n >= -s/h when
//! separated (speculative: approach at most the gap) or to v_n >= min(-s/h, max_depenetration_velocity)
//! when penetrating.
//! Friction: Coulomb per contact, the two tangential impulses clamped to mu times the normal impulse (or,
//! with `friction_per_patch`, to mu times the patch's normal impulse per contact).
//! Accumulated impulses are clamped per substep (Catto 2005, "Iterative dynamics with temporal coherence").
//!
//! Warm starting: each substep starts by re-applying the previous substep's impulses, and each frame's
//! rows inherit impulses from last frame's: contacts are generated afresh every frame, so a row looks for
//! itself among the rows of the same patch of the same pair last frame (anchor on a and point on b within
//! a tenth of the contact offset, normals within ~10 deg) and takes over the closest one's impulses.
//! Without it, 20 sweeps left a 3-box stack sliding 1.0-1.2 mm in 5 s (80 sweeps were needed); with it the
//! stack moves 0.02-0.16 mm at 20 (engine/tests/solver_stability.rs).
//!
//! Patch iterations: a tall, narrow body (a 4 mm peg, 50 mm long, standing on its 3 mm bottom face)
//! rests on one patch whose contacts push almost alike (their lever arms differ by millimetres against a
//! 25 mm height), which makes the patch's tilting mode converge ~100 times slower than its lift under
//! Gauss-Seidel: at 2 x 16 sweeps the peg rocked at 0.2-0.5 rad/s and toppled off a table within 1.5 s.
//! Re-sweeping each patch alone `patch_iters` times per sweep (cheap: the geometry is already sampled)
//! solves the patch almost exactly: at 10 the peg stands still (measured 2026-11-22).
//!
//! PGS, not TGS, by measurement (2026-11-22, tests of engine/tests): a TGS variant (a position update
//! after every position sweep, PhysX TGS / Macklin et al. 2019 "Small steps in physics simulation", with
//! per-step impulses and warm starting) let a box resting on the table creep at 3.9e-2 mm/s (PGS: 2e-7)
//! and broke the depenetration-velocity bound, and only halved the stack's slide (0.56 mm); the
//! contact rows are anchored at the frame's start and re-sampled at every sweep, which is what TGS's
//! linearised separation buys elsewhere.

pub mod articulated;
pub mod gpu;

/// WGSL: `any_orthonormal(n)`, the contact rows' first tangent (glam's `any_orthonormal_vector`), for kernels
/// outside the engine that read the rows' impulses ([`articulated::RowsLayout`]).
pub const ANY_ORTHONORMAL_WGSL: &str = include_str!("orthonormal.wgsl");

use crate::articulation::{dynamics, ArticulationControl, ArticulationModel, ArticulationState};
use crate::contact::generate::{sdf_sample_cpu, Xf};
use crate::contact::model::{FlatModel, NO_BODY};
use crate::contact::{ContactsHost, TransformGpu};
use glam::{Mat3, Quat, Vec3, Vec4};
use rayon::prelude::*;

/// Static description of the bodies of one world (all worlds share it).
#[derive(Clone, Debug, Default)]
pub struct BodyModel {
    /// Inverse mass [1/kg], shape [body_count]; 0 for static bodies.
    pub body_inv_mass: Vec<f32>,
    /// Inverse inertia about the centre of mass in body axes [1/(kg m^2)], shape [body_count].
    pub body_inv_inertia: Vec<Mat3>,
    /// Centre of mass in the body frame [m], shape [body_count].
    pub body_com: Vec<Vec3>,
    /// Kinematic bodies move with the velocity in the state (no gravity, no contact impulses), shape
    /// [body_count] or shorter (missing entries: not kinematic).
    pub body_kinematic: Vec<bool>,
    /// The articulation link a body is ([`crate::articulation`]; its pose and velocity follow the joints,
    /// and contact impulses on it act through the articulation's joint-space inertia), shape [body_count]
    /// or shorter (missing entries and [`crate::articulation::NO_LINK`]: not a link).
    pub body_link: Vec<u32>,
    /// Gravity [m/s^2].
    pub gravity: Vec3,
}

impl BodyModel {
    pub fn body_count(&self) -> usize {
        self.body_inv_mass.len()
    }

    /// Adds a dynamic body of `mass` [kg], inertia about its COM `inertia` [kg m^2], COM `com` [m].
    pub fn add_dynamic(&mut self, mass: f32, inertia: Mat3, com: Vec3) -> u32 {
        self.body_inv_mass.push(1.0 / mass);
        self.body_inv_inertia.push(inertia.inverse());
        self.body_com.push(com);
        self.body_inv_mass.len() as u32 - 1
    }

    /// Whether body `i` is kinematic.
    pub fn is_kinematic(&self, i: usize) -> bool {
        self.body_kinematic.get(i).copied().unwrap_or(false)
    }

    /// Adds a kinematic body: infinite mass for contacts, moved by the velocity set in the state.
    pub fn add_kinematic(&mut self) -> u32 {
        let i = self.add_static();
        self.body_kinematic.resize(i as usize + 1, false);
        self.body_kinematic[i as usize] = true;
        i
    }

    /// Adds a body that is link `link` of the world's articulation, with its centre of mass `com` [m] in
    /// the link frame (the point its velocity is given at). Only [`step_cpu_articulated`] steps such
    /// bodies; the GPU solver refuses them.
    pub fn add_articulated(&mut self, link: u32, com: Vec3) -> u32 {
        let i = self.add_static();
        self.body_com[i as usize] = com;
        self.body_link.resize(i as usize + 1, crate::articulation::NO_LINK);
        self.body_link[i as usize] = link;
        i
    }

    /// The articulation link body `i` is, if it is one.
    pub fn link(&self, i: usize) -> Option<u32> {
        self.body_link.get(i).copied().filter(|&l| l != crate::articulation::NO_LINK)
    }

    /// Adds a static body (never moves).
    pub fn add_static(&mut self) -> u32 {
        self.body_inv_mass.push(0.0);
        self.body_inv_inertia.push(Mat3::ZERO);
        self.body_com.push(Vec3::ZERO);
        self.body_inv_mass.len() as u32 - 1
    }
}

/// Solver settings (the paper's Table II columns).
#[derive(Clone, Debug, PartialEq)]
pub struct SolverConfig {
    /// Frame time step [s].
    pub dt: f32,
    pub substeps: u32,
    /// Gauss-Seidel sweeps with position bias per substep.
    pub pos_iters: u32,
    /// Sweeps without penetration bias per substep.
    pub vel_iters: u32,
    /// Penetration is resolved no faster than this [m/s].
    pub max_depenetration_velocity: f32,
    /// Separation the solver keeps at rest [m].
    pub rest_offset: f32,
    /// A world whose body exceeds this speed [m/s] (or turns non-finite) is flagged as diverged.
    pub max_speed: f32,
    /// Gauss-Seidel passes over each patch's (up to 4) contacts per sweep, on the geometry sampled for the
    /// sweep (no SDF samples): a cheap inner solve of the patch. Plain Gauss-Seidel (1) converges slowly
    /// where a patch's contacts act almost alike, as on the small base of a tall body (module doc).
    pub patch_iters: u32,
    /// Gauss-Seidel passes per sweep over each patch that touches an articulation link (at least
    /// `patch_iters`; [`step_cpu_articulated`] only). A finger pad holding a 30 g nut against a 20 kg arm
    /// is a chain with a mass ratio near 1:100, which plain sweeps converge slowly: the pads crept down a
    /// nut pressed on its bolt. The rows are few (a pad's few contacts), and the passes after a sweep's
    /// first run on the patch's own Delassus matrix ([`PatchSweep::Block`]), so extra passes are cheap.
    pub link_patch_iters: u32,
    /// Coulomb friction per patch (the paper's III-B: "Coulomb friction per patch"): each contact may carry
    /// tangential impulse up to mu times an equal share of its patch's total normal impulse, so the patch
    /// as a whole obeys the cone and a contact that momentarily carries little load does not slip. Off:
    /// per contact (each contact's own cone), the measured default of the tests.
    pub friction_per_patch: bool,
}

impl Default for SolverConfig {
    fn default() -> Self {
        SolverConfig {
            dt: 1.0 / 60.0,
            substeps: 1,
            pos_iters: 20,
            vel_iters: 1,
            max_depenetration_velocity: 0.5,
            rest_offset: 0.0,
            max_speed: 100.0,
            patch_iters: 1,
            link_patch_iters: 1,
            friction_per_patch: false,
        }
    }
}

/// Per-step state of every world.
#[derive(Clone, Debug, PartialEq)]
pub struct BodyState {
    /// Body frame poses, shape [world_count * body_count].
    pub body_q: Vec<TransformGpu>,
    /// Linear velocity of the centre of mass [m/s] and angular velocity [rad/s], world frame,
    /// shape [world_count * body_count].
    pub body_qd: Vec<[Vec3; 2]>,
}

/// External wrenches on the bodies, held constant over a frame (the `Control` of the design: what a
/// controller or a test pushes with). Kinematic and static bodies ignore it, as they ignore gravity.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Control {
    /// Force through the centre of mass [N] and torque about it [N m], world frame,
    /// shape [world_count * body_count]; empty for no external wrench.
    pub body_f: Vec<[Vec3; 2]>,
}

impl Control {
    /// No wrench on any of `world_count * body_count` bodies.
    pub fn zeros(world_count: usize, body_count: usize) -> Self {
        Control { body_f: vec![[Vec3::ZERO; 2]; world_count * body_count] }
    }

    /// Adds `force` [N] acting at `point` [m] (both world frame) on body `body` of world `world`: the
    /// force plus its moment about the body's centre of mass at the state's pose.
    pub fn add_force_at(
        &mut self,
        model: &BodyModel,
        state: &BodyState,
        world: usize,
        body: usize,
        force: Vec3,
        point: Vec3,
    ) {
        let g = world * model.body_count() + body;
        let (p, q) = xf(&state.body_q[g]);
        let com = p + q * model.body_com[body];
        self.body_f[g][0] += force;
        self.body_f[g][1] += (point - com).cross(force);
    }

    /// The wrench on global body index `g` (zero where none is set).
    fn wrench(&self, g: usize) -> [Vec3; 2] {
        self.body_f.get(g).copied().unwrap_or([Vec3::ZERO; 2])
    }
}

/// One contact prepared for the solver.
#[derive(Clone, Copy, Debug)]
struct Row {
    a: usize,
    b: usize,
    pair: usize,
    /// Index of the patch within its pair (rows are matched across frames within a patch).
    patch: usize,
    /// The query element's point (contact point + radius along the normal) in a's body frame [m].
    anchor_a: Vec3,
    mu: f32,
    /// Impulses of the current substep [N s].
    lambda_n: f32,
    lambda_t: [f32; 2],
    /// The normal the row was last sampled with, world frame (None before its first sample, or when the
    /// SDF had no gradient there).
    normal: Option<Vec3>,
    /// The separation at that sample [m].
    sep: f32,
    /// The contact point in b's body frame at the frame's start [m] (to match the row next frame).
    point_b: Vec3,
    /// What the sweeps after a sample reuse: the lever arms and inverse inertias at the sampled normal,
    /// the tangents, and the inverse effective masses along the normal and the tangents (None until the
    /// row's first sample of the substep; the poses and the articulation's response stand still between
    /// samples, so these are the values each sweep would recompute, bitwise).
    cache: Option<RowCache>,
}

#[derive(Clone, Copy, Debug)]
struct RowCache {
    lever: Lever,
    tangents: [Vec3; 2],
    /// Inverse effective mass along the normal, tangent 1 and tangent 2 [1/kg].
    k: [f32; 3],
    /// In an articulated substep: what a unit impulse along the normal, tangent 1 and tangent 2 does to
    /// every body it moves, and the angular parts of the velocity Jacobians (None: no articulation, or
    /// more link bodies than [`LINK_DIR_BODIES`] holds; those go through [`Step::apply`], as solver.wgsl).
    link: Option<[LinkDir; 3]>,
}

/// The most bodies one [`LinkDir`] moves: the row's two rigid sides and the articulation's link bodies.
const LINK_DIR_BODIES: usize = 4;

/// The velocity change a unit impulse along one direction of a row on an articulation link makes: the
/// row's rigid bodies through their mass and inertia, and every link body through the substep's K blocks
/// (an impulse on one finger moves the arm, so the other finger too). [`Step::apply`] computes the same
/// per impulse from the K blocks (a 6 x 6 product per link body and side); the finger pads' rows are swept
/// `link_patch_iters` times per sweep, and that product was half of an articulated step (perf, 2026-12-04).
/// In an articulated step the rows between rigid bodies (the nut on the thread) keep one too, with the
/// direction's Jacobian and effective mass: a Screw env step 1.25-1.28x faster than recomputing lever
/// products and dividing per impulse (docs/BENCHMARKS.md, 2026-12-04). Rigid-only steps keep the lever
/// form, which solver.wgsl mirrors.
#[derive(Clone, Copy, Debug, Default)]
struct LinkDir {
    /// The direction d (world frame) and its angular Jacobians on a and b: ra x d and rb x d [m], so the
    /// relative velocity along d is (va - vb) . d + wa . (ra x d) - wb . (rb x d) (two dot products per
    /// side where the lever form takes a cross product more).
    d: Vec3,
    jac: [Vec3; 2],
    /// Effective mass along d [kg] (the inverse of the row's k, 0 where k is not positive): a product per
    /// impulse where the lever form divides.
    mass: f32,
    /// (body, twist change [m/s, rad/s] per N s), the first `moved_len` used.
    moved: [(u32, [Vec3; 2]); LINK_DIR_BODIES],
    moved_len: u8,
    /// (articulation slot, spatial impulse [N s, N m s] per N s), the first `phi_len` used.
    phi: [(u32, [Vec3; 2]); 2],
    phi_len: u8,
}

impl LinkDir {
    /// The relative velocity of row sides `a` and `b` along the direction [m/s].
    #[inline]
    fn rel(&self, vel: &Vels, a: usize, b: usize) -> f32 {
        dir_rel(self.d, &self.jac, vel, a, b)
    }

    /// Applies `x` [N s] along the direction: the bodies' twists and the slots' spatial impulses.
    #[inline]
    fn apply(&self, vel: &mut Vels, x: f32) {
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
/// ([`LinkDir::rel`], and [`Idle`]'s copy of the normal's, so that both test alike bitwise).
#[inline]
fn dir_rel(d: Vec3, jac: &[Vec3; 2], vel: &Vels, a: usize, b: usize) -> f32 {
    let (va, vb) = (&vel.v[a], &vel.v[b]);
    (va[0] - vb[0]).dot(d) + va[1].dot(jac[0]) - vb[1].dot(jac[1])
}

/// Warm-start match (solver.wgsl's WARM_DISTANCE, WARM_COS): a row takes over the impulses of the row in
/// the same slot last frame when that was the same contact: same pair, anchor on a and point on b within
/// this fraction of the pair's contact offset, and normals within acos(WARM_COS) (about 10 deg).
const WARM_DISTANCE: f32 = 0.1;
const WARM_COS: f32 = 0.985;

/// What one frame of [`step_cpu`] hands to the next: each world's rows with their last impulses (the CPU
/// twin of the rows the GPU solver keeps in its scratch buffer). Start from `Default` (no warm start).
#[derive(Clone, Debug, Default)]
pub struct WarmStart {
    rows: Vec<Vec<Row>>,
}

impl WarmStart {
    /// The total normal impulse [N s] the last substep of the last frame applied through the rows of pair
    /// `pair` in world `world` (divide by the substep length for the mean contact force [N]); 0 for a
    /// pair without rows.
    pub fn pair_normal_impulse(&self, world: usize, pair: usize) -> f32 {
        self.rows.get(world).map_or(0.0, |rows| rows.iter().filter(|r| r.pair == pair).map(|r| r.lambda_n).sum())
    }

    /// The total contact impulse vector [N s] (normal and friction) the last substep of the last frame
    /// applied to pair `pair`'s query body `a` in world `world` (world frame; the SDF body got the opposite).
    pub fn pair_impulse(&self, world: usize, pair: usize) -> Vec3 {
        self.rows.get(world).map_or(Vec3::ZERO, |rows| {
            rows.iter()
                .filter(|r| r.pair == pair)
                .filter_map(|r| {
                    r.normal.map(|n| {
                        let t1 = n.any_orthonormal_vector();
                        r.lambda_n * n + r.lambda_t[0] * t1 + r.lambda_t[1] * n.cross(t1)
                    })
                })
                .sum()
        })
    }

    /// The rows' state as bytes (what the next frame's match and warm start read; the per-substep caches
    /// are rebuilt), for checkpoints that must continue exactly.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut b = Vec::new();
        let mut put = |x: u32| b.extend_from_slice(&x.to_le_bytes());
        put(self.rows.len() as u32);
        for rows in &self.rows {
            put(rows.len() as u32);
            for r in rows {
                for i in [r.a, r.b, r.pair, r.patch] {
                    put(i as u32);
                }
                let n = r.normal.unwrap_or(Vec3::ZERO);
                let floats = [
                    r.anchor_a.x,
                    r.anchor_a.y,
                    r.anchor_a.z,
                    r.mu,
                    r.lambda_n,
                    r.lambda_t[0],
                    r.lambda_t[1],
                    n.x,
                    n.y,
                    n.z,
                    r.sep,
                    r.point_b.x,
                    r.point_b.y,
                    r.point_b.z,
                ];
                put(r.normal.is_some() as u32);
                for f in floats {
                    put(f.to_bits());
                }
            }
        }
        b
    }

    /// Reads what [`to_bytes`](Self::to_bytes) wrote; None if the bytes are not such a state.
    pub fn from_bytes(bytes: &[u8]) -> Option<Self> {
        let mut at = 0usize;
        let mut word = || -> Option<u32> {
            let w = u32::from_le_bytes(bytes.get(at..at + 4)?.try_into().ok()?);
            at += 4;
            Some(w)
        };
        let worlds = word()? as usize;
        let mut out = Vec::with_capacity(worlds.min(1 << 20));
        for _ in 0..worlds {
            let n = word()? as usize;
            let mut rows = Vec::with_capacity(n.min(1 << 20));
            for _ in 0..n {
                let (a, b, pair, patch) = (word()? as usize, word()? as usize, word()? as usize, word()? as usize);
                let has_normal = word()? != 0;
                let mut f = [0.0f32; 14];
                for x in &mut f {
                    *x = f32::from_bits(word()?);
                }
                rows.push(Row {
                    a,
                    b,
                    pair,
                    patch,
                    anchor_a: Vec3::new(f[0], f[1], f[2]),
                    mu: f[3],
                    lambda_n: f[4],
                    lambda_t: [f[5], f[6]],
                    normal: has_normal.then(|| Vec3::new(f[7], f[8], f[9])),
                    sep: f[10],
                    point_b: Vec3::new(f[11], f[12], f[13]),
                    cache: None,
                });
            }
            out.push(rows);
        }
        (at == bytes.len()).then_some(WarmStart { rows: out })
    }

    /// Forgets world `world`'s rows, so its next frame starts cold (after the world was reset: last
    /// frame's impulses belong to contacts that no longer exist).
    pub fn clear_world(&mut self, world: usize) {
        if let Some(rows) = self.rows.get_mut(world) {
            rows.clear();
        }
    }

    /// Renumbers the pairs of last frame's rows (`map`: old pair index -> new, None: the pair is gone and
    /// its rows are dropped), for callers whose pair list changes from frame to frame (crate::crowd).
    pub fn remap_pairs(&mut self, map: impl Fn(usize) -> Option<usize>) {
        for rows in &mut self.rows {
            rows.retain_mut(|r| match map(r.pair) {
                Some(p) => {
                    r.pair = p;
                    true
                }
                None => false,
            });
            // Stable: a patch's rows keep their slot order, which the match's tie-break follows.
            rows.sort_by_key(|r| (r.pair, r.patch));
        }
    }
}

fn xf(t: &TransformGpu) -> (Vec3, Quat) {
    (Vec3::new(t.p[0], t.p[1], t.p[2]), Quat::from_xyzw(t.q[0], t.q[1], t.q[2], t.q[3]))
}

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
    let pair_count = flat.pairs.len();
    let h = cfg.dt / cfg.substeps as f32;
    warm.rows.resize(world_count, Vec::new());
    let prev_rows = &warm.rows;
    let art_in = art.as_ref().map(|a| (a.model, &*a.state, a.control));
    // Worlds are independent: stepped in parallel, each exactly as alone (results do not depend on the
    // thread count).
    let outs: Vec<WorldOut> = (0..world_count)
        .into_par_iter()
        .map(|w| {
            let mut ok = true;
            let base = w * nb;
            // Index nb stands for the static world (infinite mass, identity pose).
            let mut pos: Vec<(Vec3, Quat)> = (0..nb).map(|i| xf(&state.body_q[base + i])).collect();
            pos.push((Vec3::ZERO, Quat::IDENTITY));
            let mut vel = Vels { v: state.body_qd[base..base + nb].to_vec(), phi: vec![[Vec3::ZERO; 2]; links.len()] };
            vel.v.push([Vec3::ZERO; 2]);
            // This world's joints, and the link poses they give (used for the frame's rows: the caller keeps
            // the link bodies' poses in the state at the joints' forward kinematics).
            let mut joints = art_in.map(|(am, ast, actl)| {
                let n = am.dof_count();
                let w_slice = |v: &[f32]| v.get(w * n..(w + 1) * n).map(<[f32]>::to_vec).unwrap_or_default();
                let q = ast.joint_q[w * n..(w + 1) * n].to_vec();
                let qd = ast.joint_qd[w * n..(w + 1) * n].to_vec();
                (q, qd, w_slice(&actl.joint_tau), w_slice(&actl.joint_target_q))
            });
            let mut link_pose = art_in.map(|(am, _, _)| vec![(Vec3::ZERO, Quat::IDENTITY); am.link_count()]);
            if let (Some((am, _, _)), Some((q, _, _, _)), Some(lp)) = (art_in, joints.as_ref(), link_pose.as_mut()) {
                dynamics::forward_kinematics(am, q, lp);
                for (s, &i) in link_bodies.iter().enumerate() {
                    pos[i] = lp[links[s] as usize];
                }
            }
            let mut ctx = Step { flat, model, cfg, h, links: None, slot: &slot, link_bodies: &link_bodies };
            let body = |b: u32| if b == NO_BODY { nb } else { b as usize };
            // Rows from the reduced contacts, anchored in the bodies' frames at generation time.
            let mut rows = Vec::new();
            for p in 0..pair_count {
                let (a, b) = (body(flat.pairs[p].body_a), body(flat.pairs[p].body_b));
                let tol = WARM_DISTANCE * flat.pairs[p].contact_offset;
                for (i, patch) in contacts.patches[w * pair_count + p].iter().enumerate() {
                    // Last frame's rows of the same patch (rows are sorted by (pair, patch), then slot).
                    let prev = &prev_rows[w];
                    let old = &prev[prev.partition_point(|o| (o.pair, o.patch) < (p, i))
                        ..prev.partition_point(|o| (o.pair, o.patch) <= (p, i))];
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
                        // Warm start: the closest of them that was the same contact hands over its impulses.
                        let mut best: Option<(f32, &Row)> = None;
                        for o in old {
                            let Some(n) = o.normal else { continue };
                            let d = o.anchor_a.distance(row.anchor_a);
                            if n.dot(patch.normal) >= WARM_COS
                                && d <= tol
                                && o.point_b.distance(row.point_b) <= tol
                                && best.is_none_or(|(bd, _)| d < bd)
                            {
                                best = Some((d, o));
                            }
                        }
                        if let Some((_, o)) = best {
                            (row.lambda_n, row.lambda_t, row.normal) = (o.lambda_n, o.lambda_t, o.normal);
                        }
                        rows.push(row);
                    }
                }
            }
            // Each link patch's Delassus matrix for the substep's sweeps (solve_rows).
            let mut blocks = (sweep == PatchSweep::Block).then(Vec::new);
            // Each row's normal test for the sweeps (solve_rows), rebuilt with the rows' caches.
            let mut idle = vec![Idle::default(); rows.len()];
            for _ in 0..cfg.substeps {
                // The articulation's velocity before contact, and how its links answer impulses this substep.
                if let (Some(a), Some((q, qd, tau, target)), Some(lp)) =
                    (art.as_ref(), joints.as_mut(), link_pose.as_mut())
                {
                    let n = a.model.dof_count();
                    let mut factor = vec![0.0f32; n * n];
                    dynamics::forward_kinematics(a.model, q, lp);
                    if dynamics::free_velocity(a.model, lp, q, qd, tau, target, h, &mut factor) {
                        let resp = dynamics::ContactResponse::new(a.model, lp, &factor, &links);
                        for (s, &i) in link_bodies.iter().enumerate() {
                            vel.v[i] = resp.twist(s, qd);
                        }
                        ctx.links = Some(resp);
                    }
                    vel.phi.iter_mut().for_each(|p| *p = [Vec3::ZERO; 2]);
                }
                for (i, v) in vel.v.iter_mut().enumerate().take(nb) {
                    if ctx.inv_m(i) > 0.0 {
                        let [f, tau] = control.wrench(base + i);
                        v[0] += (model.gravity + ctx.inv_m(i) * f) * h;
                        // The world inverse inertia only where a torque acts (solver.wgsl alike).
                        if tau != Vec3::ZERO {
                            v[1] += ctx.inv_i_world(i, pos[i].1) * tau * h;
                        }
                    }
                }
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
                for i in 0..nb {
                    if (ctx.inv_m(i) > 0.0 || model.is_kinematic(i)) && slot[i].is_none() {
                        let (p, q) = pos[i];
                        let c = p + q * ctx.com(i);
                        let c2 = c + vel.v[i][0] * h;
                        let w = vel.v[i][1];
                        let dq = Quat::from_xyzw(w.x, w.y, w.z, 0.0) * q * (0.5 * h);
                        let q2 = Quat::from_vec4(Vec4::from(q) + Vec4::from(dq)).normalize();
                        pos[i] = (c2 - q2 * ctx.com(i), q2);
                    }
                }
                // The joints move with the impulses the position sweeps applied; the links follow.
                if let (Some((am, _, _)), Some((q, qd, _, _)), Some(lp), Some(resp)) =
                    (art_in, joints.as_mut(), link_pose.as_mut(), ctx.links.as_ref())
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
            let mut body_q = Vec::with_capacity(nb);
            for i in 0..nb {
                let (p, q) = pos[i];
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
            WorldOut { rows, body_q, body_qd: vel.v, joints, ok }
        })
        .collect();
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

/// What one world's step hands back: its rows (next frame's warm start), bodies, joints and whether it
/// stayed finite and within the speed bound.
struct WorldOut {
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

/// What every row of one world's step reads: the contact model, the bodies, the settings and the substep.
/// Body index `model.body_count()` is the static world (infinite mass, identity pose).
struct Step<'a> {
    flat: &'a FlatModel,
    model: &'a BodyModel,
    cfg: &'a SolverConfig,
    /// Substep length [s].
    h: f32,
    /// This substep's articulation response (None: no articulated bodies, or a massless chain).
    links: Option<dynamics::ContactResponse>,
    /// Each body's articulation slot (index body_count, the static world, has none), shape [body_count + 1].
    slot: &'a [Option<usize>],
    /// The body of each slot.
    link_bodies: &'a [usize],
}

/// The bodies' velocities during a step (twist of the centre of mass: linear [m/s], angular [rad/s];
/// index body_count is the static world), and the spatial impulses (force [N s], torque about the centre
/// of mass [N m s]) applied to each articulation slot since its joints last took them.
struct Vels {
    v: Vec<[Vec3; 2]>,
    phi: Vec<[Vec3; 2]>,
}

impl Step<'_> {
    fn inv_m(&self, i: usize) -> f32 {
        self.model.body_inv_mass.get(i).copied().unwrap_or(0.0)
    }

    fn com(&self, i: usize) -> Vec3 {
        self.model.body_com.get(i).copied().unwrap_or(Vec3::ZERO)
    }

    /// World-frame inverse inertia of body `i` at rotation `q` (zero for static and kinematic bodies).
    fn inv_i_world(&self, i: usize, q: Quat) -> Mat3 {
        if self.inv_m(i) > 0.0 {
            let r = Mat3::from_quat(q);
            r * self.model.body_inv_inertia[i] * r.transpose()
        } else {
            Mat3::ZERO
        }
    }

    /// The row's lever arms and the bodies' world inverse inertias, for contact normal `n`.
    fn lever(&self, r: &Row, pos: &[(Vec3, Quat)], n: Vec3) -> Lever {
        let ((pa, qa), (pb, qb)) = (pos[r.a], pos[r.b]);
        // The contact point on a's surface.
        let xa = pa + qa * r.anchor_a - self.flat.pairs[r.pair].radius * n;
        Lever {
            ra: xa - (pa + qa * self.com(r.a)),
            rb: xa - (pb + qb * self.com(r.b)),
            ia: self.inv_i_world(r.a, qa),
            ib: self.inv_i_world(r.b, qb),
        }
    }

    /// The spatial impulses (force, torque about the centre of mass) a unit `d` at the row's point puts on
    /// its bodies that are articulation links: (slot, impulse) for a, then b (which takes the opposite).
    fn link_impulses(&self, r: &Row, l: &Lever, d: Vec3) -> [Option<(usize, [Vec3; 2])>; 2] {
        [self.slot[r.a].map(|s| (s, [d, l.ra.cross(d)])), self.slot[r.b].map(|s| (s, [-d, -l.rb.cross(d)]))]
    }

    /// Inverse effective mass of the row along unit `d` [1/kg]: rigid bodies through their mass and
    /// inertia, articulation links through the substep's K blocks (cross terms included when both sides are
    /// links of the articulation).
    fn eff(&self, r: &Row, l: &Lever, d: Vec3) -> f32 {
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

    /// The [`LinkDir`] of a row along unit `d` in an articulated substep, for rows between rigid bodies
    /// too (their impulses then skip [`Step::apply`]'s per-impulse inertia products); None without an
    /// articulation response, or when the row touches a link and the articulation has more link bodies
    /// than a [`LinkDir`] holds.
    fn link_dir(&self, r: &Row, l: &Lever, d: Vec3) -> Option<LinkDir> {
        let resp = self.links.as_ref()?;
        let sides = self.link_impulses(r, l, d);
        let on_link = sides.iter().any(Option::is_some);
        if on_link && self.link_bodies.len() + 2 > LINK_DIR_BODIES {
            return None;
        }
        let mut out = LinkDir { d, jac: [l.ra.cross(d), l.rb.cross(d)], ..LinkDir::default() };
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
    fn apply(&self, r: &Row, l: &Lever, vel: &mut Vels, imp: Vec3) {
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
struct Lever {
    ra: Vec3,
    rb: Vec3,
    ia: Mat3,
    ib: Mat3,
}

/// One sweep over the rows, in (pair, patch, slot) order: each patch's rows are solved once with
/// `resample`, then `patch_iters - 1` more times on the sampled geometry (solver.wgsl's `sweep`).
///
/// In an articulated substep a patch's passes after its first (which samples the rows and builds their
/// caches) run as one block ([`solve_patch_block`]) when every row has its [`LinkDir`]s: the same
/// Gauss-Seidel updates in the same order, on the patch's own Delassus matrix. `blocks` holds those
/// matrices, one per patch in row order, built at the patch's first block after a resampling sweep (the
/// caches they come from stand until then); None: every pass row by row ([`PatchSweep::Rows`]).
#[allow(clippy::too_many_arguments)]
fn solve_rows(
    ctx: &Step,
    rows: &mut [Row],
    idle: &mut [Idle],
    pos: &[(Vec3, Quat)],
    vel: &mut Vels,
    bias: bool,
    resample: bool,
    mut blocks: Option<&mut Vec<Option<PatchBlock>>>,
) {
    if let (true, Some(b)) = (resample, blocks.as_mut()) {
        b.clear();
    }
    let mut first = 0;
    for (k, patch) in rows.chunk_by_mut(|x, y| (x.pair, x.patch) == (y.pair, y.patch)).enumerate() {
        let idle = &mut idle[first..first + patch.len()];
        first += patch.len();
        let link = ctx.slot[patch[0].a].is_some() || ctx.slot[patch[0].b].is_some();
        let passes = if link { ctx.cfg.patch_iters.max(ctx.cfg.link_patch_iters) } else { ctx.cfg.patch_iters };
        let mut pass = 0;
        if resample {
            for i in 0..patch.len() {
                solve_row(ctx, patch, i, pos, vel, bias, true);
                idle[i] = Idle::of(ctx, &patch[i]);
            }
            pass = 1;
        }
        if let (true, Some(blocks)) = (passes - pass.min(passes) >= 2, blocks.as_mut()) {
            if blocks.len() <= k {
                blocks.resize(k + 1, None);
            }
            if blocks[k].is_none() {
                blocks[k] = PatchBlock::new(patch);
            }
            if let Some(block) = &blocks[k] {
                solve_patch_block(ctx, patch, block, vel, bias, passes - pass);
                continue;
            }
        }
        for _ in pass..passes {
            for i in 0..patch.len() {
                if idle[i].stays(&patch[i], vel, bias) {
                    continue;
                }
                solve_row(ctx, patch, i, pos, vel, bias, false);
            }
        }
    }
}

/// What tells a row whether an update leaves it as it is, kept apart from the rows (which are large) so
/// that a sweep reads it in one cache line: most rows within the contact offset hold no impulse and take
/// none (the Franka's nut on the thread: ~13 of ~200 rows push), and for them the update is only this
/// normal test. Its quantities are copies of the row's normal [`LinkDir`] and the speculative targets, so
/// the test is [`solve_row`]'s own, bitwise. `mass` 0: no test (no LinkDir, or not yet cached).
#[derive(Clone, Copy, Debug, Default)]
struct Idle {
    d: Vec3,
    jac: [Vec3; 2],
    mass: f32,
    /// The normal's target velocity in position sweeps (with bias) and velocity sweeps [m/s].
    target: [f32; 2],
    a: u32,
    b: u32,
}

impl Idle {
    /// The test of row `r` as cached now.
    fn of(ctx: &Step, r: &Row) -> Self {
        // With friction pooled over the patch a row without normal impulse may still take friction.
        if ctx.cfg.friction_per_patch {
            return Idle::default();
        }
        let (Some(_), Some(c)) = (r.normal, r.cache.as_ref()) else { return Idle::default() };
        let Some(dirs) = c.link.as_ref() else { return Idle::default() };
        if c.k[0] <= 0.0 {
            return Idle::default();
        }
        let n = &dirs[0];
        Idle {
            d: n.d,
            jac: n.jac,
            mass: n.mass,
            target: [normal_target(ctx, r.sep, true), normal_target(ctx, r.sep, false)],
            a: r.a as u32,
            b: r.b as u32,
        }
    }

    /// Whether [`solve_row`] would leave row `r` unchanged and apply nothing: it holds no impulse, and the
    /// normal update clamps to zero (then friction, limited by the row's own normal impulse, has nothing to
    /// give).
    #[inline]
    fn stays(&self, r: &Row, vel: &Vels, bias: bool) -> bool {
        if self.mass == 0.0 || r.lambda_n != 0.0 || r.lambda_t != [0.0; 2] {
            return false;
        }
        let rel = dir_rel(self.d, &self.jac, vel, self.a as usize, self.b as usize);
        let dn = (self.target[!bias as usize] - rel) * self.mass;
        // (0 + dn).max(0) is 0 unless dn > 0 (f32::max takes 0 over NaN).
        !(dn > 0.0)
    }
}

/// The normal's target relative velocity [m/s] at separation `s` [m]: speculative when separated, bounded
/// depenetration when penetrating (position sweeps, `bias`), none otherwise.
#[inline]
fn normal_target(ctx: &Step, s: f32, bias: bool) -> f32 {
    if s > 0.0 {
        -s / ctx.h
    } else if bias {
        (-s / ctx.h).min(ctx.cfg.max_depenetration_velocity)
    } else {
        0.0
    }
}

/// The most rows a patch holds (its contact slots), and their directions (normal, two tangents each).
const PATCH_ROWS: usize = 4;
const PATCH_DIRS: usize = 3 * PATCH_ROWS;

/// A patch's Delassus matrix over its rows' directions (row j's normal, tangent 1, tangent 2 at 3j, 3j + 1,
/// 3j + 2): `w[d][e]` is the change of direction d's relative velocity [m/s] per N s along direction e,
/// from the [`LinkDir`]s (what `e.apply` moves, read as `d.rel` reads it). Rows without a normal this
/// substep have zero rows and columns.
#[derive(Clone, Debug)]
struct PatchBlock {
    w: [[f32; PATCH_DIRS]; PATCH_DIRS],
}

impl PatchBlock {
    /// The block of `patch`, or None where a row that takes part has no [`LinkDir`]s (no articulation
    /// response, or more link bodies than one holds) or the patch has more rows than slots.
    fn new(patch: &[Row]) -> Option<Self> {
        if patch.len() > PATCH_ROWS {
            return None;
        }
        let mut dirs: [Option<&[LinkDir; 3]>; PATCH_ROWS] = [None; PATCH_ROWS];
        for (j, r) in patch.iter().enumerate() {
            if r.normal.is_some() {
                dirs[j] = Some(r.cache.as_ref()?.link.as_ref()?);
            }
        }
        let mut w = [[0.0f32; PATCH_DIRS]; PATCH_DIRS];
        for (i, ri) in patch.iter().enumerate() {
            let Some(di) = dirs[i] else { continue };
            for (j, dj) in dirs.iter().enumerate().take(patch.len()) {
                let Some(dj) = dj else { continue };
                for (a, da) in di.iter().enumerate() {
                    for (b, db) in dj.iter().enumerate() {
                        let mut x = 0.0;
                        for (body, dv) in &db.moved[..db.moved_len as usize] {
                            let body = *body as usize;
                            if body == ri.a {
                                x += dv[0].dot(da.d) + dv[1].dot(da.jac[0]);
                            }
                            if body == ri.b {
                                x -= dv[0].dot(da.d) + dv[1].dot(da.jac[1]);
                            }
                        }
                        w[3 * i + a][3 * j + b] = x;
                    }
                }
            }
        }
        Some(PatchBlock { w })
    }
}

/// `passes` Gauss-Seidel passes over a patch's rows on their sampled geometry, as many [`solve_row`] passes
/// without resampling: the same updates in the same order, each direction's relative velocity kept up to
/// date through the patch's Delassus matrix instead of read from the bodies, and the passes' summed
/// impulse changes applied to the bodies once at the end (the velocities of bodies outside the patch are
/// not read meanwhile). Equal to the row passes up to rounding. Why: a finger pad's rows are swept
/// `link_patch_iters` (8) times per sweep, and each row pass reads two bodies and moves every link body
/// (a [`LinkDir`] apply); on the 12 x 12 matrix a direction's update is 12 products.
fn solve_patch_block(ctx: &Step, patch: &mut [Row], block: &PatchBlock, vel: &mut Vels, bias: bool, passes: u32) {
    let cfg = ctx.cfg;
    let len = patch.len();
    let n_dirs = 3 * len;
    let mut rel = [0.0f32; PATCH_DIRS];
    let mut moved = [0.0f32; PATCH_DIRS];
    for (j, r) in patch.iter().enumerate() {
        if let (Some(_), Some(dirs)) = (r.normal, r.cache.as_ref().and_then(|c| c.link.as_ref())) {
            for (e, d) in dirs.iter().enumerate() {
                rel[3 * j + e] = d.rel(vel, r.a, r.b);
            }
        }
    }
    // A change x along direction e: every direction's relative velocity follows.
    let push = |rel: &mut [f32; PATCH_DIRS], moved: &mut [f32; PATCH_DIRS], e: usize, x: f32| {
        moved[e] += x;
        for (r, w) in rel[..n_dirs].iter_mut().zip(&block.w) {
            *r += w[e] * x;
        }
    };
    for _ in 0..passes {
        for i in 0..len {
            let r = &patch[i];
            if r.normal.is_none() {
                continue;
            }
            let Some(c) = r.cache.as_ref() else { continue };
            let Some(dirs) = c.link.as_ref() else { continue };
            if c.k[0] <= 0.0 {
                continue;
            }
            let target = normal_target(ctx, r.sep, bias);
            let (mu, k, masses) = (r.mu, c.k, [dirs[0].mass, dirs[1].mass, dirs[2].mass]);
            let dn = (target - rel[3 * i]) * masses[0];
            let new = (r.lambda_n + dn).max(0.0);
            let d = new - r.lambda_n;
            patch[i].lambda_n = new;
            // Zero updates skipped, as in solve_row.
            if d != 0.0 {
                push(&mut rel, &mut moved, 3 * i, d);
            }
            if mu > 0.0 {
                let limit = if cfg.friction_per_patch {
                    mu * patch.iter().map(|o| o.lambda_n).sum::<f32>() / len.max(1) as f32
                } else {
                    mu * new
                };
                if limit == 0.0 && patch[i].lambda_t == [0.0; 2] {
                    continue;
                }
                for j in 0..2 {
                    if k[1 + j] <= 0.0 {
                        continue;
                    }
                    let dt = -rel[3 * i + 1 + j] * masses[1 + j];
                    let old = patch[i].lambda_t[j];
                    let new = (old + dt).clamp(-limit, limit);
                    patch[i].lambda_t[j] = new;
                    if new != old {
                        push(&mut rel, &mut moved, 3 * i + 1 + j, new - old);
                    }
                }
            }
        }
    }
    for (j, r) in patch.iter().enumerate() {
        if let Some(dirs) = r.cache.as_ref().and_then(|c| c.link.as_ref()) {
            for (e, d) in dirs.iter().enumerate() {
                if moved[3 * j + e] != 0.0 {
                    d.apply(vel, moved[3 * j + e]);
                }
            }
        }
    }
}

/// One Gauss-Seidel update of row `i` of a patch's rows (solver.wgsl's `solve_row`).
fn solve_row(
    ctx: &Step,
    patch: &mut [Row],
    i: usize,
    pos: &[(Vec3, Quat)],
    vel: &mut Vels,
    bias: bool,
    resample: bool,
) {
    if (resample || patch[i].cache.is_none()) && !prepare_row(ctx, &mut patch[i], pos, resample) {
        return;
    }
    let cfg = ctx.cfg;
    let pooled = cfg.friction_per_patch;
    let len = patch.len();
    // The row and its patch's other rows, so the cache is read in place while the row's impulses change.
    let (before, rest) = patch.split_at_mut(i);
    let (r, after) = rest.split_first_mut().expect("row index within its patch");
    let (Some(n), Some(c)) = (r.normal, r.cache.as_ref()) else { return };
    let s = r.sep;
    let (a, b) = (r.a, r.b);
    // The lever form's relative velocity (rows without LinkDirs), reading the cache in place.
    let rel = |vel: &Vels| {
        let l = &c.lever;
        (vel.v[a][0] + vel.v[a][1].cross(l.ra)) - (vel.v[b][0] + vel.v[b][1].cross(l.rb))
    };
    let k = c.k[0];
    if k <= 0.0 {
        return;
    }
    let target = normal_target(ctx, s, bias);
    let dn = match &c.link {
        Some(dirs) => (target - dirs[0].rel(vel, a, b)) * dirs[0].mass,
        None => (target - rel(vel).dot(n)) / k,
    };
    let new = (r.lambda_n + dn).max(0.0);
    let d = new - r.lambda_n;
    r.lambda_n = new;
    // Most rows within the contact offset stay separated and take no impulse (the Franka's nut on the
    // thread: 13 of ~200 rows pushing): an update of zero moves nothing, so it is skipped, here and below.
    if d != 0.0 {
        match &c.link {
            Some(dirs) => dirs[0].apply(vel, d),
            None => ctx.apply(r, &c.lever, vel, n * d),
        }
    }
    let mu = r.mu;
    if mu > 0.0 {
        let limit = if pooled {
            // The patch's normal impulse per contact (solver.wgsl's patch_normal_share), summed in slot order.
            let sum = before.iter().map(|o| o.lambda_n).chain([r.lambda_n]).chain(after.iter().map(|o| o.lambda_n));
            mu * sum.sum::<f32>() / len.max(1) as f32
        } else {
            mu * r.lambda_n
        };
        // No friction to give and none held: the clamp would leave both tangents at zero.
        if limit == 0.0 && r.lambda_t == [0.0; 2] {
            return;
        }
        for j in 0..2 {
            let kt = c.k[1 + j];
            if kt <= 0.0 {
                continue;
            }
            let dt = match &c.link {
                Some(dirs) => -dirs[1 + j].rel(vel, a, b) * dirs[1 + j].mass,
                None => -rel(vel).dot(c.tangents[j]) / kt,
            };
            let new = (r.lambda_t[j] + dt).clamp(-limit, limit);
            let d = new - r.lambda_t[j];
            r.lambda_t[j] = new;
            if d != 0.0 {
                match &c.link {
                    Some(dirs) => dirs[1 + j].apply(vel, d),
                    None => ctx.apply(r, &c.lever, vel, c.tangents[j] * d),
                }
            }
        }
    }
}

/// A row's sample (with `resample`: its normal and separation at the current poses) and its cache
/// ([`RowCache`]), built where missing. Out of line: a sweep reuses both, and with this inlined the
/// sweep's update copied the cache through the stack (a third of the solve in store-forwarding stalls,
/// perf 2026-12-05). False where the row has no normal (the SDF had no gradient there).
#[inline(never)]
fn prepare_row(ctx: &Step, r: &mut Row, pos: &[(Vec3, Quat)], resample: bool) -> bool {
    let cfg = ctx.cfg;
    let n = if resample {
        let ((pa, qa), (pb, qb)) = (pos[r.a], pos[r.b]);
        let pair = &ctx.flat.pairs[r.pair];
        let x = pa + qa * r.anchor_a;
        // The SDF shape's frame: body b's pose times the shape's pose on it.
        let body_b = Xf { p: pb, q: Vec4::from(qb) };
        let shape_b = body_b
            .mul(&Xf { p: Vec3::new(pair.b_pos[0], pair.b_pos[1], pair.b_pos[2]), q: Vec4::from_array(pair.b_rot) });
        let (phi, g) = sdf_sample_cpu(pair, &ctx.flat.sdf_values, shape_b.inv().point(x));
        let glen = g.length();
        if glen <= 0.0 {
            r.normal = None;
            return false;
        }
        let n = shape_b.rotate(g / glen);
        r.normal = Some(n);
        r.sep = phi - pair.radius - cfg.rest_offset;
        r.cache = None;
        n
    } else {
        match r.normal {
            Some(n) => n,
            None => return false,
        }
    };
    if r.cache.is_none() {
        let lever = ctx.lever(r, pos, n);
        let t1 = n.any_orthonormal_vector();
        let t2 = n.cross(t1);
        let k = [ctx.eff(r, &lever, n), ctx.eff(r, &lever, t1), ctx.eff(r, &lever, t2)];
        let mut link = ctx
            .link_dir(r, &lever, n)
            .and_then(|dn| Some([dn, ctx.link_dir(r, &lever, t1)?, ctx.link_dir(r, &lever, t2)?]));
        for (dir, k) in link.iter_mut().flatten().zip(k) {
            dir.mass = if k > 0.0 { 1.0 / k } else { 0.0 };
        }
        r.cache = Some(RowCache { lever, tangents: [t1, t2], k, link });
    }
    true
}

/// Converts a host pose to the kernels' transform (re-exported for callers building states).
pub fn transform(p: Vec3, q: Quat) -> TransformGpu {
    TransformGpu::new(p, q)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(i: usize, normal: Option<Vec3>) -> Row {
        let f = i as f32;
        Row {
            a: i,
            b: i + 1,
            pair: 2 * i,
            patch: 3 * i,
            anchor_a: Vec3::new(f, -f, 0.5 * f),
            mu: 0.3,
            lambda_n: 1e-3 * f,
            lambda_t: [-2e-4 * f, 7e-5],
            normal,
            sep: -1e-4 * f,
            point_b: Vec3::new(0.1, f, -f),
            cache: None,
        }
    }

    #[test]
    fn warm_start_bytes_round_trip() {
        let warm =
            WarmStart { rows: vec![vec![row(1, Some(Vec3::Z)), row(2, None)], vec![], vec![row(3, Some(-Vec3::X))]] };
        let bytes = warm.to_bytes();
        let back = WarmStart::from_bytes(&bytes).expect("round trip");
        assert_eq!(back.to_bytes(), bytes);
        assert_eq!(back.rows.len(), 3);
        assert_eq!(back.rows[0][1].normal, None);
        assert_eq!(back.rows[2][0].normal, Some(-Vec3::X));
        assert_eq!(back.pair_impulse(0, 2), warm.pair_impulse(0, 2));
        assert!(WarmStart::from_bytes(&bytes[..bytes.len() - 1]).is_none());
        assert!(WarmStart::from_bytes(&[bytes.as_slice(), &[0u8; 4]].concat()).is_none());
    }
}

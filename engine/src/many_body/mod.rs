//! Many bodies in one world: the paper's piles (section III-D: 1024 nuts, bowls or toruses falling into a
//! pile in one environment). The fixed pair list and one-invocation-per-world solver of
//! [`crate::contact::ContactPipeline`] and [`crate::solver::gpu::GpuSolver`] suit thousands of small
//! worlds; a world of N bodies has N (N - 1) / 2 candidate pairs and one long serial solve. This module
//! builds the world's work every frame instead, all on the GPU (the host records dispatches only):
//!
//! 1. **Near pairs** (`near.wgsl`): for every body, the bodies and static shapes whose bounding spheres
//!    come within the contact offset (a plane tests the sphere against its half-space), counted per
//!    body, prefix-summed and written as a compact list sorted by (body a, body b), each entry a
//!    [`PairGpu`] copied from the pair's template ([`ManyBodyModel`]) with its bodies filled in. The order
//!    does not depend on thread timing, so frames are bitwise reproducible.
//! 2. **Contacts** (`contacts.wgsl`): generation and the two-level reduction of
//!    [`crate::contact`] on the near pairs (indirect dispatches sized by the list).
//! 3. **Graph colouring** (`near.wgsl`): two pairs that share a dynamic body cannot be solved at once.
//!    Jones and Plassmann's parallel colouring (1993, "A parallel graph coloring heuristic"): in each
//!    round every uncoloured pair whose priority (a hash of its two bodies) beats that of all its
//!    uncoloured neighbours takes the lowest colour its coloured neighbours leave free. Neighbours that
//!    decide in the same round never share a body, so the result is the same as a sequential run of
//!    the rounds, and the CPU twin reproduces it exactly.
//! 4. **Solve** (`solve.wgsl`): the Gauss-Seidel step of [`crate::solver`] (same rows, warm start, patch
//!    passes, integration) with the sweep over the pairs cut into one dispatch per colour: the pairs of a
//!    colour touch disjoint bodies and run in parallel, the colours run in order. This is exactly a
//!    sequential Gauss-Seidel sweep over the pairs sorted by colour, which is what the CPU twin runs
//!    ([`crate::solver::step_cpu`] on the pairs in that order). Warm starting across frames finds last
//!    frame's entry of the same body pair by binary search in last frame's sorted keys.
//! 5. **Sleeping** ([`ManyBodyConfig::sleep`], off unless set): a pile settles but a few bodies may never
//!    quite stop (docs/BENCHMARKS.md: a nut rocking between two poses 0.7 mm apart for good, floor nuts
//!    creeping under leaning neighbours). As in PhysX, Bullet and rapier, a body that has stayed put long
//!    enough is taken out of the dynamics: after the last substep (`many_body_sleep`) each awake dynamic body
//!    compares its centre of mass and rotation with a reference pose; within [`SleepConfig::distance`] and
//!    [`SleepConfig::angle`] its count of still frames grows, else the reference becomes the current pose
//!    and the count restarts at one (the body *moved* this frame). At more than [`SleepConfig::frames`]
//!    a dynamic body falls asleep (a kinematic one never does, but standing still it wakes nobody): its
//!    velocity is set to zero, and from then on it takes no gravity and no impulses and is not integrated
//!    (the solver sees an infinitely heavy body, as a static one). Before contact generation
//!    (`many_body_wake`), every near pair (bounding spheres within the contact offset, 1.) of a sleeping body
//!    and a body that moved last frame wakes the sleeper; it counts as one frame still with its old
//!    reference, so it wakes its own neighbours only if it is then pushed out of its bounds. Then a pair
//!    whose bodies all sleep (or a sleeper and a static shape) gets no jobs (`near_dormant`): no contacts,
//!    no rows, so a pile that has gone to sleep costs little more than its near pairs and colouring. There
//!    are no islands: a body resting on a sleeper stays awake until it too stays put. The state is two
//!    vec4 per body at the end of the solver scratch (reference centre of mass and count, reference
//!    rotation); uploading a state or resetting a world wakes its bodies.
//!
//! A world whose near pairs exceed [`ManyBodyConfig::max_pairs`], whose colouring needs more than
//! [`ManyBodyConfig::max_colours`] colours or more than [`ManyBodyConfig::colour_rounds`] rounds, or whose
//! patches exceed [`ManyBodyConfig::max_patches_per_world`] is flagged and left as it was for that frame
//! (never stepped with contacts missing); [`ManyBodyFrame::flags`] says which.

pub mod gpu;

use crate::contact::generate::{pair_far_cpu, sdf_sample_cpu, shape_world, RigidTransform};
use crate::contact::model::{FlatModel, JobGpu, PairGpu, NO_BODY};
use crate::contact::{contacts_cpu, ContactConfig, ContactModel, PairSpec, QueryShape};
use crate::error::{EngineError, Result};
use crate::solver::{step_cpu, BodyModel, BodyState, Control, SolverConfig, WarmStart};
use glam::Vec3;

/// Query triangles per job in a many-body world (see ManyBodyFlat::new).
const CHUNK: u32 = 256;
/// No template for a pair of classes (the pair never collides).
pub const NO_RULE: u32 = u32::MAX;
/// Neighbour visits the serial completion of the colouring may make per world (near.wgsl's SERIAL_VISITS;
/// within lavapipe's 65535 loop passes per invocation, with the colour sort's own loops).
const SERIAL_VISITS: usize = 24576;
/// Colour word of an uncoloured pair.
const UNCOLOURED: u32 = u32::MAX;
/// Colour index of a pair that found no free colour below `max_colours`.
const COLOUR_NONE: u32 = 255;

/// [`ManyBodyFrame::flags`]: more near pairs than [`ManyBodyConfig::max_pairs`].
pub const FLAG_PAIRS: u32 = 1;
/// A pair needed a colour beyond [`ManyBodyConfig::max_colours`].
pub const FLAG_COLOURS: u32 = 2;
/// Pairs still uncoloured after [`ManyBodyConfig::colour_rounds`] rounds and the serial completion's budget.
pub const FLAG_ROUNDS: u32 = 4;
/// More patches than [`ManyBodyConfig::max_patches_per_world`] (raised only for a world coloured in full).
pub const FLAG_PATCHES: u32 = 8;
/// The near test gave another answer when the list was written than when it was counted (GPU only:
/// floating-point contraction differing between kernels; the world's list would have a gap).
pub const FLAG_RECOUNT: u32 = 16;

/// The shapes of a many-body world: each body has a shape class, and a template pair per pair of
/// classes (and per static shape and class) says how two such shapes collide.
#[derive(Clone, Debug)]
pub struct ManyBodyModel {
    /// Bodies per world.
    pub body_count: u32,
    /// Shape class of each body, shape [body_count].
    pub body_class: Vec<u32>,
    pub class_count: u32,
    /// Pair templates: the query shape on body a and the SDF shape on body b with their poses on the
    /// bodies, offset and friction; their body fields are ignored (each near pair sets its own), except
    /// that a static template's SDF shape is fixed in the world (`b_pose` in world coordinates).
    pub templates: Vec<PairSpec>,
    /// Template for bodies i < j of classes (ci, cj) at [ci * class_count + cj], or [`NO_RULE`].
    pub body_rule: Vec<u32>,
    /// Static shapes (a ground plane, a table), each colliding with every body of the classes its
    /// rule names: template at [s * class_count + c], or [`NO_RULE`].
    pub static_rule: Vec<u32>,
    pub static_count: u32,
}

impl ManyBodyModel {
    /// `body_count` bodies of one part: every two collide by `body_pair`, and each collides with each of
    /// `statics` (templates whose SDF shape is fixed in the world).
    pub fn uniform(body_count: u32, body_pair: PairSpec, statics: Vec<PairSpec>) -> Self {
        let static_count = statics.len() as u32;
        let mut templates = vec![body_pair];
        templates.extend(statics);
        ManyBodyModel {
            body_count,
            body_class: vec![0; body_count as usize],
            class_count: 1,
            templates,
            body_rule: vec![0],
            static_rule: (1..=static_count).collect(),
            static_count,
        }
    }

    /// Checks the tables' shapes and indices, naming the field.
    pub fn validate(&self) -> Result<()> {
        let bad =
            |field: &'static str, value: String, expected: String| Err(EngineError::Config { field, value, expected });
        if self.body_count == 0 {
            return bad("body_count", "0".into(), "at least 1 body".into());
        }
        // Per-body kernels loop over every body in one invocation (lavapipe: 65535 loop passes each).
        if self.body_count + self.static_count > 30_000 {
            return bad(
                "body_count",
                format!("{} bodies + {} static shapes", self.body_count, self.static_count),
                "at most 30000 together per world".into(),
            );
        }
        if self.body_class.len() != self.body_count as usize {
            return bad(
                "body_class",
                format!("{} entries", self.body_class.len()),
                format!("one per body ({})", self.body_count),
            );
        }
        if let Some((i, c)) = self.body_class.iter().enumerate().find(|(_, &c)| c >= self.class_count) {
            return bad(
                "body_class",
                format!("{c} (body {i})"),
                format!("a class below class_count = {}", self.class_count),
            );
        }
        let n_t = self.templates.len() as u32;
        for (field, table, len) in [
            ("body_rule", &self.body_rule, self.class_count * self.class_count),
            ("static_rule", &self.static_rule, self.static_count * self.class_count),
        ] {
            if table.len() != len as usize {
                return bad(field, format!("{} entries", table.len()), format!("{len} (see ManyBodyModel)"));
            }
            if let Some(t) = table.iter().find(|&&t| t != NO_RULE && t >= n_t) {
                return bad(field, t.to_string(), format!("a template index below {n_t} or NO_RULE"));
            }
        }
        Ok(())
    }

    /// The templates flattened for the GPU (jobs of `chunk` triangles each, ordered by normal within each
    /// job where `by_normal`: see ContactModel::flatten_ordered); body fields are placeholders.
    pub fn flatten(&self, chunk: u32, by_normal: bool) -> Result<FlatModel> {
        let statics: Vec<bool> = (0..self.templates.len() as u32).map(|t| self.static_rule.contains(&t)).collect();
        let pairs = self
            .templates
            .iter()
            .zip(&statics)
            .map(|(p, &is_static)| PairSpec { body_a: 0, body_b: if is_static { NO_BODY } else { 0 }, ..p.clone() })
            .collect();
        ContactModel { body_count: self.body_count, pairs }.flatten_ordered(chunk, by_normal)
    }
}

/// Capacities of a many-body world (per world).
#[derive(Clone, Debug, PartialEq)]
pub struct ManyBodyConfig {
    /// Near pairs (body-body and body-static) a world may hold.
    pub max_pairs: u32,
    /// Colours the solver may use (at most 32; a body with d near pairs needs at least d).
    pub max_colours: u32,
    /// Colouring rounds per frame.
    pub colour_rounds: u32,
    /// Patches (of all near pairs together) a world may hold: the solver's rows are allocated per patch.
    pub max_patches_per_world: u32,
    /// Sleeping of bodies that stay put (module doc, 5.); off by default.
    pub sleep: SleepConfig,
}

/// When a body of a many-body world falls asleep (module doc, 5.): it has stayed within `distance` and
/// `angle` of one pose for `frames` frames in a row. PhysX, which the paper's piles ran on, sleeps a body
/// whose mass-normalised kinetic energy stays below a threshold (default 5e-5 x (10 m/s)^2 = 0.005 J/kg,
/// about 0.1 m/s) for its wake counter (0.4 s) (PhysX 4 guide, "Rigid Body Dynamics: Sleeping"); this
/// criterion is on displacement instead, so a body rocking in place sleeps and one creeping steadily does
/// not.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SleepConfig {
    /// Frames a body must stay within the bounds below to fall asleep; 0: bodies never sleep.
    pub frames: u32,
    /// Largest displacement of the centre of mass from the reference pose [m].
    pub distance: f32,
    /// Largest rotation from the reference pose [rad].
    pub angle: f32,
}

impl SleepConfig {
    /// Bodies never sleep.
    pub const OFF: SleepConfig = SleepConfig { frames: 0, distance: 0.0, angle: 0.0 };

    pub fn enabled(&self) -> bool {
        self.frames > 0
    }

    /// cos(angle / 2): a unit quaternion q is within `angle` of r when |q . r| >= this.
    pub fn half_cos(&self) -> f32 {
        (0.5 * self.angle).cos()
    }
}

impl Default for SleepConfig {
    fn default() -> Self {
        SleepConfig::OFF
    }
}

impl ManyBodyConfig {
    /// Room for `bodies` bodies with about 10 near pairs each (at most 10000) and 8 patches per pair.
    pub fn for_bodies(bodies: u32) -> Self {
        let max_pairs = (10 * bodies).clamp(64, 10_000);
        ManyBodyConfig {
            max_pairs,
            max_colours: 32,
            colour_rounds: 64,
            max_patches_per_world: 8 * max_pairs,
            sleep: SleepConfig::OFF,
        }
    }

    pub fn validate(&self) -> Result<()> {
        let bad = |field: &'static str, value: u32, expected: &str| {
            Err(EngineError::Config { field, value: value.to_string(), expected: expected.into() })
        };
        if self.max_pairs == 0 || self.max_pairs > 10_000 {
            // The colour sort walks a world's pairs three times in one invocation, plus the serial
            // completion's SERIAL_VISITS (lavapipe's 65535 loop passes).
            return bad("max_pairs", self.max_pairs, "1..=10000 near pairs per world");
        }
        if self.max_colours == 0 || self.max_colours > 32 {
            return bad("max_colours", self.max_colours, "1..=32 (one bit per colour)");
        }
        if self.colour_rounds == 0 || self.colour_rounds > 1024 {
            return bad("colour_rounds", self.colour_rounds, "1..=1024");
        }
        if self.max_patches_per_world == 0 {
            return bad("max_patches_per_world", 0, "at least 1");
        }
        let sleep = &self.sleep;
        if sleep.frames == 1 || sleep.frames > 1_000_000 {
            // A woken body counts as one frame still (module doc, 5.): a single frame would put it straight
            // back to sleep.
            return bad("sleep.frames", sleep.frames, "0 (never sleep) or 2..=1000000 frames");
        }
        if sleep.enabled() {
            let badf = |field: &'static str, value: f32, expected: &str| {
                Err(EngineError::Config { field, value: value.to_string(), expected: expected.into() })
            };
            if !(sleep.distance.is_finite() && sleep.distance > 0.0) {
                return badf("sleep.distance", sleep.distance, "a finite distance > 0 [m]");
            }
            if !(sleep.angle > 0.0 && sleep.angle < std::f32::consts::PI) {
                return badf("sleep.angle", sleep.angle, "an angle in (0, pi) [rad]");
            }
        }
        Ok(())
    }
}

/// One near pair: its bodies (b = [`NO_BODY`] for a static shape), its sort key for b and its template.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct NearPair {
    pub a: u32,
    /// b for a body, [`STATIC_KEY`] + s for static shape s: the list is sorted by (a, key).
    pub key: u32,
    pub b: u32,
    pub template: u32,
}

/// Sort key of static shape 0 (near.wgsl's STATIC_KEY).
pub const STATIC_KEY: u32 = 0xffff_0000;

/// What one frame of one world did before its solve.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ManyBodyFrame {
    /// Near pairs in list order (sorted by (a, b)).
    pub pairs: Vec<NearPair>,
    /// Colour of each near pair (its index; 255: none found).
    pub colours: Vec<u32>,
    /// Colours in use.
    pub colour_count: u32,
    /// FLAG_* bits; non-zero: the world was not stepped.
    pub flags: u32,
}

/// PCG hash (O'Neill 2014; the variant of Jarzynski and Olano 2020, "Hash functions for GPU rendering").
pub fn pcg(v: u32) -> u32 {
    let s = v.wrapping_mul(747796405).wrapping_add(2891336453);
    let w = ((s >> ((s >> 28) + 4)) ^ s).wrapping_mul(277803737);
    (w >> 22) ^ w
}

/// Colouring priority of the pair of bodies (a, b) (near.wgsl's `priority`).
pub fn priority(a: u32, b: u32) -> u32 {
    pcg(a ^ pcg(b))
}

/// The templates and tables the kernels read, and the CPU twin's copy of them.
#[derive(Clone, Debug)]
pub struct ManyBodyFlat {
    pub model: ManyBodyModel,
    /// Flattened templates (pairs, jobs, triangles, SDF values).
    pub flat: FlatModel,
    /// Triangles per job.
    pub chunk: u32,
    /// Jobs per near pair (the most any template needs).
    pub jobs_per_pair: u32,
    /// Bounding sphere of job k's triangles of template t at [t * jobs_per_pair + k]: centre in the query
    /// shape's frame xyz [m], radius (the query radius included) w [m]; w < 0 where the template has no
    /// job k.
    pub job_bounds: Vec<[f32; 4]>,
}

/// Triangles by the Morton code of their centroids in the shape's box (10 bits per axis), so that a job's
/// run of triangles is a compact piece of the surface and its bounding sphere can cull it whole.
fn spatial_order(q: &QueryShape) -> QueryShape {
    let cent: Vec<Vec3> = q.triangles.iter().map(|[a, b, c]| (*a + *b + *c) / 3.0).collect();
    let (lo, hi) = cent.iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(l, h), c| (l.min(*c), h.max(*c)));
    let scale = (hi - lo).max(Vec3::splat(1e-9));
    let spread = |v: u32| {
        let mut x = v & 0x3ff;
        x = (x | (x << 16)) & 0x030000ff;
        x = (x | (x << 8)) & 0x0300f00f;
        x = (x | (x << 4)) & 0x030c30c3;
        (x | (x << 2)) & 0x09249249
    };
    let code = |c: &Vec3| {
        let u = ((*c - lo) / scale * 1023.0).round().clamp(Vec3::ZERO, Vec3::splat(1023.0));
        spread(u.x as u32) | (spread(u.y as u32) << 1) | (spread(u.z as u32) << 2)
    };
    let mut order: Vec<usize> = (0..q.triangles.len()).collect();
    order.sort_by_key(|&i| (code(&cent[i]), i));
    QueryShape { triangles: order.iter().map(|&i| q.triangles[i]).collect(), radius: q.radius }
}

/// Whether job `k` of near pair `pair` (its shapes posed at `world_a`, `world_b`) cannot have a candidate
/// (contacts.wgsl's job cull): the SDF at the centre of the job's bounding sphere, less its radius, the
/// query radius and the grid's interpolation slack (two voxels: trilinear interpolation can be off by up to
/// sqrt(3)/2 of a voxel either side of the 1-Lipschitz field) is beyond the contact offset.
pub fn job_far_cpu(
    pair: &PairGpu,
    sdf_values: &[u32],
    bound: [f32; 4],
    world_a: &RigidTransform,
    world_b: &RigidTransform,
) -> bool {
    if bound[3] < 0.0 {
        return true;
    }
    let b_from_a = world_b.inv().mul(world_a);
    let (d, _) = sdf_sample_cpu(pair, sdf_values, b_from_a.point(Vec3::from_slice(&bound[..3])));
    let slack = if pair.sdf_kind == 1 { 0.0 } else { 2.0 * pair.sdf_origin[3] };
    d - bound[3] - slack > pair.contact_offset
}

impl ManyBodyFlat {
    pub fn new(model: &ManyBodyModel, contact: &ContactConfig) -> Result<Self> {
        model.validate()?;
        contact.validate()?;
        let longest = model.templates.iter().map(|p| p.query.triangles.len() as u32).max().unwrap_or(0);
        // A world of many pairs fills the device with pairs, so jobs are short, for their bounding spheres
        // to cull most of a pair's surface (see job_bounds).
        let chunk = if contact.chunk_triangles > 0 {
            contact.chunk_triangles
        } else {
            CHUNK.min(longest.next_multiple_of(256)).clamp(256, contact.max_chunk_triangles().max(256))
        };
        let mut model = model.clone();
        for t in &mut model.templates {
            t.query = std::sync::Arc::new(spatial_order(&t.query));
        }
        let flat = model.flatten(chunk, contact.orders_by_normal())?;
        let jobs_per_pair = flat.pairs.iter().map(|p| p.job_count).max().unwrap_or(1).max(1);
        if chunk > contact.max_chunk_triangles() || jobs_per_pair > contact.max_jobs_per_pair() {
            return Err(EngineError::Config {
                field: "chunk_triangles",
                value: chunk.to_string(),
                expected: format!(
                    "jobs of at most {} triangles and at most {} jobs per pair (lavapipe's loop limit; the largest template has {longest} query triangles)",
                    contact.max_chunk_triangles(),
                    contact.max_jobs_per_pair()
                ),
            });
        }
        let mut job_bounds = vec![[0.0, 0.0, 0.0, -1.0]; flat.pairs.len() * jobs_per_pair as usize];
        for (ti, p) in flat.pairs.iter().enumerate() {
            for k in 0..p.job_count {
                let first = (p.tri_first + k * chunk) as usize;
                let n = chunk.min(p.tri_count - k * chunk) as usize;
                let pts: Vec<Vec3> =
                    flat.tri_verts[3 * first..3 * (first + n)].iter().map(|v| Vec3::from_slice(&v[..3])).collect();
                let (lo, hi) =
                    pts.iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(l, h), v| (l.min(*v), h.max(*v)));
                let c = 0.5 * (lo + hi);
                let r = pts.iter().map(|v| v.distance(c)).fold(0.0f32, f32::max);
                // One part in 1e5 of slack for the rounding of the test, as the pair's bounding spheres.
                job_bounds[ti * jobs_per_pair as usize + k as usize] = [c.x, c.y, c.z, (r + p.radius) * (1.0 + 1e-5)];
            }
        }
        Ok(ManyBodyFlat { model, flat, chunk, jobs_per_pair, job_bounds })
    }

    fn class(&self, body: u32) -> u32 {
        self.model.body_class[body as usize]
    }

    /// The near pairs of world `world` at poses `body_q` (all worlds), in list order, and whether more than
    /// `max_pairs` were near (the list is then cut at `max_pairs`).
    pub fn near_pairs(&self, body_q: &[RigidTransform], world: u32, max_pairs: u32) -> (Vec<NearPair>, bool) {
        let m = &self.model;
        let n = m.body_count;
        let mut out = Vec::new();
        let mut total = 0u32;
        for i in 0..n {
            for j in i + 1..n {
                let t = m.body_rule[(self.class(i) * m.class_count + self.class(j)) as usize];
                if t != NO_RULE && self.near(t, i, j, body_q, world) {
                    total += 1;
                    out.push(NearPair { a: i, key: j, b: j, template: t });
                }
            }
            for s in 0..m.static_count {
                let t = m.static_rule[(s * m.class_count + self.class(i)) as usize];
                if t != NO_RULE && self.near(t, i, NO_BODY, body_q, world) {
                    total += 1;
                    out.push(NearPair { a: i, key: STATIC_KEY + s, b: NO_BODY, template: t });
                }
            }
        }
        out.truncate(max_pairs as usize);
        (out, total > max_pairs)
    }

    fn near(&self, t: u32, a: u32, b: u32, body_q: &[RigidTransform], world: u32) -> bool {
        let p = &self.flat.pairs[t as usize];
        let n = self.model.body_count;
        let wa = shape_world(body_q, n, world, a, p.a_pos, p.a_rot);
        let wb = shape_world(body_q, n, world, b, p.b_pos, p.b_rot);
        !pair_far_cpu(p, &wa, &wb)
    }

    /// The near pair's record: its template with its bodies filled in (near.wgsl's `near_emit`).
    pub fn pair_record(&self, np: &NearPair) -> PairGpu {
        let mut p = PairGpu { body_a: np.a, body_b: np.b, job_first: np.key, ..self.flat.pairs[np.template as usize] };
        p.many_body_template = np.template;
        p
    }
}

/// Jones-Plassmann colouring of near pairs (near.wgsl's `colour_round` and `colour_sort`), the pairs the
/// rounds leave uncoloured then coloured one after another: each pair's colour index, the colours in use,
/// and FLAG_COLOURS / FLAG_ROUNDS.
pub fn colour_pairs(pairs: &[NearPair], body_count: u32, max_colours: u32, rounds: u32) -> (Vec<u32>, u32, u32) {
    let n = pairs.len();
    let mut incident: Vec<Vec<usize>> = vec![Vec::new(); body_count as usize];
    for (e, p) in pairs.iter().enumerate() {
        incident[p.a as usize].push(e);
        if p.b != NO_BODY {
            incident[p.b as usize].push(e);
        }
    }
    let prio: Vec<u32> = pairs.iter().map(|p| priority(p.a, p.b)).collect();
    let mut colour = vec![UNCOLOURED; n];
    let mut flags = 0;
    for r in 0..rounds {
        let start = colour.clone();
        for e in 0..n {
            if start[e] != UNCOLOURED {
                continue;
            }
            let mut used = 0u32;
            let mut blocked = false;
            for x in [pairs[e].a, pairs[e].b] {
                if x == NO_BODY {
                    continue;
                }
                for &f in &incident[x as usize] {
                    if f == e {
                        continue;
                    }
                    if start[f] == UNCOLOURED {
                        blocked |= (prio[f], f) > (prio[e], e);
                    } else if start[f] & 0xff < 32 {
                        used |= 1 << (start[f] & 0xff);
                    }
                }
            }
            if !blocked {
                let c = (!used).trailing_zeros();
                colour[e] = (r << 8) | if c < max_colours { c } else { COLOUR_NONE };
                if c >= max_colours {
                    flags |= FLAG_COLOURS;
                }
            }
        }
    }
    // The serial completion (near.wgsl's colour_sort): in list order, within SERIAL_VISITS neighbour visits.
    let mut visits = 0usize;
    for e in 0..n {
        if colour[e] != UNCOLOURED {
            continue;
        }
        let bodies = [pairs[e].a, pairs[e].b];
        let cost: usize =
            4 + bodies.iter().filter(|&&x| x != NO_BODY).map(|&x| incident[x as usize].len()).sum::<usize>();
        if visits + cost > SERIAL_VISITS {
            break;
        }
        visits += cost;
        let mut used = 0u32;
        for x in bodies.into_iter().filter(|&x| x != NO_BODY) {
            for &f in &incident[x as usize] {
                if f != e && colour[f] != UNCOLOURED && colour[f] & 0xff < 32 {
                    used |= 1 << (colour[f] & 0xff);
                }
            }
        }
        let c = (!used).trailing_zeros();
        colour[e] = if c < max_colours { c } else { COLOUR_NONE };
        if c >= max_colours {
            flags |= FLAG_COLOURS;
        }
    }
    if colour.contains(&UNCOLOURED) {
        flags |= FLAG_ROUNDS;
    }
    let colours: Vec<u32> = colour.iter().map(|&c| if c == UNCOLOURED { COLOUR_NONE } else { c & 0xff }).collect();
    let count = colours.iter().filter(|&&c| c < max_colours).map(|&c| c + 1).max().unwrap_or(0);
    (colours, count, flags)
}

/// The CPU reference of [`gpu::ManyBodyPipeline`]: the same near pairs, colours, contacts and a Gauss-Seidel
/// step over the pairs in colour order, world by world.
/// (A pipeline whose per-job patches would not fit one binding lengthens its jobs; its twin then takes
/// `ContactConfig { chunk_triangles: pipeline.flat.chunk, .. }`.)
pub struct ManyBodyCpu {
    pub flat: ManyBodyFlat,
    pub cfg: ManyBodyConfig,
    pub contact: ContactConfig,
    pub solver: SolverConfig,
    pub bodies: BodyModel,
    /// Per world: last frame's pairs in solve order and their rows.
    warm: Vec<(Vec<NearPair>, WarmStart)>,
    /// Sleeping state per body, shape [world_count * body_count] (module doc, 5.).
    pub rest: Vec<RestState>,
    /// A model of one world's near pairs, rebuilt every frame (triangles and SDF values set once).
    world_flat: FlatModel,
}

impl ManyBodyCpu {
    pub fn new(
        model: &ManyBodyModel,
        bodies: &BodyModel,
        cfg: &ManyBodyConfig,
        contact: &ContactConfig,
        solver: &SolverConfig,
    ) -> Result<Self> {
        check_setup(model, bodies, cfg, solver)?;
        let flat = ManyBodyFlat::new(model, contact)?;
        let world_flat = FlatModel {
            pairs: Vec::new(),
            jobs: Vec::new(),
            tri_verts: flat.flat.tri_verts.clone(),
            sdf_values: flat.flat.sdf_values.clone(),
        };
        Ok(ManyBodyCpu {
            flat,
            cfg: cfg.clone(),
            contact: contact.clone(),
            solver: solver.clone(),
            bodies: bodies.clone(),
            warm: Vec::new(),
            rest: Vec::new(),
            world_flat,
        })
    }

    /// Forgets the warm-start impulses of every world.
    pub fn forget_warm_start(&mut self) {
        self.warm.clear();
        self.rest.clear();
    }

    /// Forgets world `world`'s warm-start impulses (the twin of [`gpu::ManyBodyPipeline::reset_world`]; the
    /// caller writes the world's new state).
    pub fn reset_world(&mut self, world: usize) {
        if let Some(w) = self.warm.get_mut(world) {
            *w = Default::default();
        }
        let n = self.flat.model.body_count as usize;
        if let Some(r) = self.rest.get_mut(world * n..(world + 1) * n) {
            r.fill(RestState::default());
        }
    }

    /// Steps every world of `state` by one frame; returns per world the frame's pairs, colours and flags,
    /// and whether the world is ok (stepped, finite, below max_speed).
    pub fn step(&mut self, state: &mut BodyState, control: &Control) -> Vec<(ManyBodyFrame, bool)> {
        let n = self.flat.model.body_count as usize;
        let world_count = state.body_q.len() / n;
        self.warm.resize_with(world_count, Default::default);
        self.rest.resize(world_count * n, RestState::default());
        let xf: Vec<RigidTransform> = state.body_q.iter().map(|t| t.xf()).collect();
        let mut out = Vec::with_capacity(world_count);
        for w in 0..world_count {
            let (pairs, over) = self.flat.near_pairs(&xf, w as u32, self.cfg.max_pairs);
            // The GPU does not colour an overfull list (the world is not stepped).
            let (colours, colour_count, flags) = if over {
                (vec![COLOUR_NONE; pairs.len()], 0, FLAG_PAIRS)
            } else {
                colour_pairs(&pairs, n as u32, self.cfg.max_colours, self.cfg.colour_rounds)
            };
            // Solve order: by colour, then list order (the GPU's colour lists).
            let mut order: Vec<usize> = (0..pairs.len()).filter(|&e| colours[e] < self.cfg.max_colours).collect();
            order.sort_by_key(|&e| (colours[e], e));
            let solve_pairs: Vec<NearPair> = order.iter().map(|&e| pairs[e]).collect();
            let sleep = self.cfg.sleep;
            let rest = &mut self.rest[w * n..(w + 1) * n];
            if sleep.enabled() && !over {
                // As the GPU, before contact generation and whether or not the colouring succeeds (it
                // runs later there).
                for np in pairs.iter().filter(|np| np.b != NO_BODY) {
                    wake_by(rest, np.a as usize, np.b as usize, &sleep);
                    wake_by(rest, np.b as usize, np.a as usize, &sleep);
                }
            }
            let mut frame = ManyBodyFrame { pairs, colours, colour_count, flags };
            if frame.flags != 0 {
                // Not stepped (as on the GPU): no contacts, and no warm start for next frame.
                self.warm[w] = Default::default();
                out.push((frame, false));
                continue;
            }
            self.world_flat.pairs.clear();
            self.world_flat.jobs.clear();
            for (k, np) in solve_pairs.iter().enumerate() {
                let t = &self.flat.flat.pairs[np.template as usize];
                let record = self.flat.pair_record(np);
                let wa = shape_world(&xf, n as u32, w as u32, np.a, t.a_pos, t.a_rot);
                let wb = shape_world(&xf, n as u32, w as u32, np.b, t.b_pos, t.b_rot);
                let job_first = self.world_flat.jobs.len() as u32;
                // A pair whose bodies all sleep gets no jobs (near.wgsl near_dormant).
                let asleep = |b: u32| b == NO_BODY || rest[b as usize].asleep(&sleep);
                let dormant = sleep.enabled() && asleep(np.a) && asleep(np.b);
                for j in 0..if dormant { 0 } else { t.job_count } {
                    let bound = self.flat.job_bounds[(np.template * self.flat.jobs_per_pair + j) as usize];
                    if job_far_cpu(&record, &self.flat.flat.sdf_values, bound, &wa, &wb) {
                        continue;
                    }
                    let first = j * self.flat.chunk;
                    self.world_flat.jobs.push(JobGpu {
                        pair: k as u32,
                        tri_first: t.tri_first + first,
                        tri_count: self.flat.chunk.min(t.tri_count - first),
                        slot: j,
                    });
                }
                let job_count = self.world_flat.jobs.len() as u32 - job_first;
                self.world_flat.pairs.push(PairGpu { job_first, job_count, ..record });
            }
            let range = w * n..(w + 1) * n;
            // The many-body kernels merge every near pair's jobs (many_body/merge.wgsl), one job or several.
            let contacts =
                contacts_cpu(&self.world_flat, n as u32, 1, &state.body_q[range.clone()], &self.contact, true);
            let patches: usize = contacts.patches.iter().map(|p| p.len()).sum();
            let (old_pairs, mut warm) = std::mem::take(&mut self.warm[w]);
            if patches > self.cfg.max_patches_per_world as usize {
                frame.flags |= FLAG_PATCHES;
                out.push((frame, false));
                continue;
            }
            // Last frame's rows move to their pair's new place (the GPU finds them by binary search).
            let place: std::collections::HashMap<(u32, u32), usize> =
                solve_pairs.iter().enumerate().map(|(k, p)| (key(p), k)).collect();
            warm.remap_pairs(|old| place.get(&key(&old_pairs[old])).copied());
            let mut sleepers = None;
            if rest.iter().any(|r| r.asleep(&sleep)) {
                // The solver sees a sleeper as a static body (as solve.wgsl's body_awake).
                let mut m = self.bodies.clone();
                for (b, r) in rest.iter().enumerate() {
                    if r.asleep(&sleep) {
                        m.body_inv_mass[b] = 0.0;
                        m.body_inv_inertia[b] = glam::Mat3::ZERO;
                    }
                }
                sleepers = Some(m);
            }
            let mut ws = BodyState {
                body_q: state.body_q[range.clone()].to_vec(),
                body_qd: state.body_qd[range.clone()].to_vec(),
            };
            let cw = if control.body_f.is_empty() {
                Control::default()
            } else {
                Control { body_f: control.body_f[range.clone()].to_vec() }
            };
            let model = sleepers.as_ref().unwrap_or(&self.bodies);
            let ok = step_cpu(model, &mut ws, &contacts, &self.world_flat, &self.solver, &cw, &mut warm)[0];
            if sleep.enabled() {
                for (b, r) in rest.iter_mut().enumerate() {
                    let kinematic = self.bodies.is_kinematic(b);
                    if self.bodies.body_inv_mass[b] > 0.0 || kinematic {
                        r.update(&ws.body_q[b], self.bodies.body_com[b], &mut ws.body_qd[b], kinematic, &sleep);
                    }
                }
            }
            state.body_q[range.clone()].copy_from_slice(&ws.body_q);
            state.body_qd[range].copy_from_slice(&ws.body_qd);
            self.warm[w] = (solve_pairs, warm);
            out.push((frame, ok));
        }
        out
    }
}

/// One body's sleeping state (module doc, 5.; solve.wgsl's rest_index): the reference pose and the frames
/// the body has stayed within [`SleepConfig`]'s bounds of it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RestState {
    /// Reference centre of mass, world frame [m].
    pub com: Vec3,
    /// Reference rotation (quaternion x, y, z, w).
    pub rot: glam::Vec4,
    /// 0: no reference yet; 1: the reference was set this frame (the body moved); k + 1: still for k frames;
    /// above [`SleepConfig::frames`]: asleep. A float, as the GPU stores it.
    pub count: f32,
}

impl Default for RestState {
    fn default() -> Self {
        // As the zeroed GPU scratch (the rotation is read only once count > 0).
        RestState { com: Vec3::ZERO, rot: glam::Vec4::ZERO, count: 0.0 }
    }
}

impl RestState {
    pub fn asleep(&self, sleep: &SleepConfig) -> bool {
        sleep.enabled() && self.count > sleep.frames as f32
    }

    /// Whether the body left its bounds (or had none) at the last update.
    pub fn moved(&self) -> bool {
        self.count <= 1.0
    }

    /// The end-of-frame update of a dynamic or kinematic body at pose `q` with centre of mass `com_local`
    /// (body frame); a body falling asleep has its velocity `qd` zeroed; a kinematic body never sleeps
    /// (solve.wgsl's many_body_sleep).
    pub fn update(
        &mut self,
        q: &crate::contact::TransformGpu,
        com_local: Vec3,
        qd: &mut [Vec3; 2],
        kinematic: bool,
        sleep: &SleepConfig,
    ) {
        if self.asleep(sleep) {
            return;
        }
        let xf = q.xf();
        let com = xf.point(com_local);
        if self.count > 0.0
            && (com - self.com).length() <= sleep.distance
            && xf.q.dot(self.rot).abs() >= sleep.half_cos()
        {
            self.count += 1.0;
            if kinematic {
                self.count = self.count.min(sleep.frames as f32);
            }
            if self.asleep(sleep) {
                *qd = [Vec3::ZERO; 2];
            }
        } else {
            *self = RestState { com, rot: xf.q, count: 1.0 };
        }
    }
}

/// `rest[a]` wakes if it sleeps and `rest[b]` moved last frame (solve.wgsl's many_body_wake): it counts as one
/// frame still with its old reference.
fn wake_by(rest: &mut [RestState], a: usize, b: usize, sleep: &SleepConfig) {
    if rest[a].asleep(sleep) && rest[b].moved() {
        rest[a].count = 2.0;
    }
}

/// The checks the GPU pipeline and the CPU twin both make on their settings (the models are checked by
/// ManyBodyFlat::new).
pub(crate) fn check_setup(
    model: &ManyBodyModel,
    bodies: &BodyModel,
    cfg: &ManyBodyConfig,
    solver: &SolverConfig,
) -> Result<()> {
    cfg.validate()?;
    solver.validate()?;
    bodies.validate()?;
    if bodies.body_count() as u32 != model.body_count {
        return Err(EngineError::Config {
            field: "body_count",
            value: bodies.body_count().to_string(),
            expected: format!("the many-body model's {} bodies", model.body_count),
        });
    }
    Ok(())
}

fn key(p: &NearPair) -> (u32, u32) {
    (p.a, p.key)
}

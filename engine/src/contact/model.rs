//! Host description of the shape pairs to collide, flattened into the GPU layout of common.wgsl.
//! Meshes and SDF grids are stored once and shared by every world; only body poses are per world.

use crate::error::{EngineError, Result};
use crate::mesh::TriMesh;
use crate::sdf::SdfGrid;
use bytemuck::{Pod, Zeroable};
use glam::{Quat, Vec3};
use std::borrow::Cow;
use std::sync::Arc;

/// Marks a shape fixed in the world frame (no body).
pub const NO_BODY: u32 = u32::MAX;

/// The shape providing the signed distance.
#[derive(Clone, Debug)]
pub enum SdfShape {
    /// A baked grid in the shape frame.
    Grid(Arc<SdfGrid>),
    /// The half-space z <= 0 of the shape frame (a table or ground plane; normal +z).
    Plane,
    /// The analytic SDF of a threaded bolt (procedural parts; exact where a grid is not).
    Thread(crate::sdf::thread::ThreadSdf),
    /// The analytic SDF of a solid of revolution (round pegs: exactly round where a grid is faceted).
    Revolved(crate::sdf::revolved::RevolvedSdf),
}

/// The shape whose triangles are queried: triangles in the shape frame [m] plus a radius [m].
#[derive(Clone, Debug)]
pub struct QueryShape {
    /// Corners of each query triangle, shape frame [m].
    pub triangles: Vec<[Vec3; 3]>,
    /// Radius around the triangles [m] (0 for meshes and boxes).
    pub radius: f32,
}

impl QueryShape {
    /// A triangle mesh.
    pub fn mesh(mesh: &TriMesh) -> Self {
        QueryShape { triangles: (0..mesh.triangle_count()).map(|t| mesh.triangle(t)).collect(), radius: 0.0 }
    }
    /// A box of half extents `h` [m] centred at the shape origin: its 12 face triangles, plus its 8
    /// corners as point queries so that a face lying flat on a surface reports exactly its corners.
    pub fn cuboid(h: Vec3) -> Self {
        let mesh = crate::mesh::box_mesh(h);
        let mut q = Self::mesh(&mesh);
        q.triangles.extend(mesh.positions.iter().map(|p| [*p; 3]));
        q
    }
    /// [`QueryShape::cuboid`] plus point queries at the centres of an `n` x `n` grid of cells on each face,
    /// so that a face pressed on a smaller flat reports several points inside it.
    pub fn cuboid_grid(h: Vec3, n: u32) -> Self {
        let mut q = Self::cuboid(h);
        let t = |i: u32| -1.0 + 2.0 * (i as f32 + 0.5) / n as f32;
        for axis in 0..3 {
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            for side in [-1.0f32, 1.0] {
                for i in 0..n {
                    for j in 0..n {
                        let mut p = Vec3::ZERO;
                        p[axis] = side * h[axis];
                        p[u] = t(i) * h[u];
                        p[v] = t(j) * h[v];
                        q.triangles.push([p; 3]);
                    }
                }
            }
        }
        q
    }
    /// A sphere of `radius` [m] at the shape origin.
    pub fn sphere(radius: f32) -> Self {
        QueryShape { triangles: vec![[Vec3::ZERO; 3]], radius }
    }
    /// A capsule along z: segment of `half_length` [m] each side of the origin, `radius` [m].
    pub fn capsule(radius: f32, half_length: f32) -> Self {
        let (p, q) = (Vec3::new(0.0, 0.0, -half_length), Vec3::new(0.0, 0.0, half_length));
        QueryShape { triangles: vec![[p, q, q]], radius }
    }
}

/// One shape pair: which bodies carry the shapes, where the shapes sit on them, and contact settings.
#[derive(Clone, Debug)]
pub struct PairSpec {
    /// Body carrying the query shape (index within a world) or [`NO_BODY`].
    pub body_a: u32,
    /// Query shape pose in body a's frame (position [m], rotation).
    pub a_pose: (Vec3, Quat),
    pub query: Arc<QueryShape>,
    /// Body carrying the SDF shape or [`NO_BODY`].
    pub body_b: u32,
    /// SDF shape pose in body b's frame.
    pub b_pose: (Vec3, Quat),
    pub sdf: SdfShape,
    /// Candidates farther apart than this are ignored [m].
    pub contact_offset: f32,
    /// Coulomb friction coefficient of the pair (unitless).
    pub friction: f32,
}

/// GPU mirror of `Pair` in common.wgsl (192 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct PairGpu {
    pub a_pos: [f32; 4],
    pub a_rot: [f32; 4],
    pub b_pos: [f32; 4],
    pub b_rot: [f32; 4],
    /// SDF grid origin xyz [m], spacing w [m].
    pub sdf_origin: [f32; 4],
    /// SDF dims xyz, offset of the first value in `sdf_values` w.
    pub sdf_dims: [u32; 4],
    pub body_a: u32,
    pub body_b: u32,
    pub tri_first: u32,
    pub tri_count: u32,
    /// 0: grid, 1: half-space z <= 0, 2: analytic threaded bolt, 3: analytic solid of revolution (params of
    /// 2 and 3 at word sdf_dims.w).
    pub sdf_kind: u32,
    pub job_first: u32,
    pub job_count: u32,
    /// Metres per unit of the 16-bit quantised SDF values.
    pub sdf_scale: f32,
    pub contact_offset: f32,
    pub radius: f32,
    /// Area quantum for the patch measure [m^2].
    pub area_unit: f32,
    /// Minimum distance between two contacts of a patch [m].
    pub min_separation: f32,
    /// Coulomb friction coefficient (unitless).
    pub friction: f32,
    /// A many-body pair's template index (crate::many_body); 0 elsewhere.
    pub many_body_template: u32,
    pub _pad: [f32; 2],
    /// Bounding sphere of the query shape (its triangles plus `radius`): centre in the query shape's frame
    /// xyz [m], radius w [m].
    pub a_bound: [f32; 4],
    /// Bounding sphere of the SDF shape's surface: centre in the SDF shape's frame xyz [m], radius w [m];
    /// w < 0 for an unbounded shape (a plane, a thread). With both, the broad phase: a pair whose spheres are
    /// farther apart than the contact offset has no candidate and is skipped (`pair_far`).
    pub b_bound: [f32; 4],
}

/// w of an unbounded [`PairGpu::b_bound`].
pub const UNBOUNDED: f32 = -1.0;

/// The thread's field is the largest of up to three exact fields (the thread's flanks, a z half-space, the
/// tip's cone; the head's is a union, exact outside), which near an edge or corner of the solid reads as
/// little as 1/sqrt(3) of the true distance (three orthogonal faces; 0.92 at the 45-degree tip edge). So a
/// query point can read within the contact offset c while lying up to sqrt(3) c away: the broad phase culls
/// a thread pair only beyond sqrt(3) c, by growing the thread's sphere by (sqrt(3) - 1) c, and so never
/// drops a candidate the generation would have kept.
pub const THREAD_BOUND_SLACK: f32 = 0.732_050_8;

/// Bounding sphere (centre xyz, radius w) of points: the centre of their box and the farthest point.
fn bounding_sphere(points: impl Iterator<Item = Vec3> + Clone, pad: f32) -> [f32; 4] {
    let (lo, hi) = points.clone().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    if !lo.is_finite() {
        return [0.0, 0.0, 0.0, pad];
    }
    let c = 0.5 * (lo + hi);
    let r = points.map(|v| v.distance(c)).fold(0.0f32, f32::max);
    // One part in 1e5 of slack for the rounding of the world-frame test.
    [c.x, c.y, c.z, (r + pad) * (1.0 + 1e-5)]
}

impl SdfShape {
    /// Bounding sphere of the shape's surface in its frame (centre xyz, radius w [m]); w = [`UNBOUNDED`]
    /// for the plane (the broad phase tests a plane's half-space instead). The thread's is its solid's
    /// ([`ThreadSdf::bound`](crate::sdf::thread::ThreadSdf::bound)), which the flat model grows by
    /// [`THREAD_BOUND_SLACK`] times the contact offset. A grid's covers its samples within one spacing h of the surface,
    /// grown by h: every surface point lies within h sqrt(3)/2 of such a sample, and farther out the
    /// field (within its interpolation slack inside the box, the box value plus the distance to the box
    /// outside it) exceeds the distance to this sphere. The grid's whole box, which it replaced, was 47%
    /// wider for a pile's M16 nut (22.5 against 15.3 mm) and listed twice as many near pairs in a pile.
    pub fn bound(&self) -> [f32; 4] {
        match self {
            SdfShape::Plane => [0.0, 0.0, 0.0, UNBOUNDED],
            SdfShape::Thread(t) => t.bound(),
            SdfShape::Grid(g) => {
                let h = g.spacing;
                let near = (0..g.dims.z).flat_map(move |k| {
                    (0..g.dims.y).flat_map(move |j| {
                        (0..g.dims.x).filter_map(move |i| {
                            (g.values[g.index(i, j, k)].abs() <= h)
                                .then(|| g.origin + Vec3::new(i as f32, j as f32, k as f32) * h)
                        })
                    })
                });
                if near.clone().next().is_none() {
                    // No surface sampled (a degenerate grid): the whole box.
                    let hi = g.origin + (g.dims.as_vec3() - Vec3::ONE) * h;
                    return bounding_sphere([g.origin, hi].into_iter(), 0.0);
                }
                bounding_sphere(near, h)
            }
            SdfShape::Revolved(r) => {
                // The profile's box revolved: a cylinder, whose bounding sphere is centred on the axis.
                let rho = r.profile.iter().map(|v| v.x).fold(0.0f32, f32::max);
                let (z0, z1) =
                    r.profile.iter().fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), v| (a.min(v.y), b.max(v.y)));
                let radius = rho.hypot(0.5 * (z1 - z0)) * (1.0 + 1e-5);
                [0.0, 0.0, 0.5 * (z0 + z1), radius]
            }
        }
    }
}

/// GPU mirror of `Job` in generate.wgsl: a run of query triangles of one pair.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq, Eq)]
pub struct JobGpu {
    pub pair: u32,
    pub tri_first: u32,
    pub tri_count: u32,
    pub slot: u32,
}

/// GPU mirror of `Params` in common.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct ParamsGpu {
    pub world_count: u32,
    pub body_count: u32,
    pub pair_count: u32,
    pub job_count: u32,
    pub normal_cos: f32,
    pub iterations: u32,
    pub world_offset: u32,
    /// The first job of a generate dispatch (one per run of jobs whose pairs share an SDF kind); 0 elsewhere.
    pub job_base: u32,
}

/// GPU mirror of `PatchOut`: normal xyz + area w, then 4 slots of point xyz + depth w (3e38 = empty).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct PatchGpu {
    pub normal: [f32; 4],
    pub slots: [[f32; 4]; 4],
}

/// Depth written into empty slots.
pub const EMPTY_DEPTH: f32 = 3.0e38;

/// Flattened pairs, triangles and SDF values, shared by all worlds.
#[derive(Clone, Debug, Default)]
pub struct ContactModel {
    /// Bodies per world (poses are `body_q[world * body_count + body]`).
    pub body_count: u32,
    pub pairs: Vec<PairSpec>,
}

/// The flat arrays uploaded to the GPU (and read by the CPU twin).
#[derive(Clone, Debug, Default)]
pub struct FlatModel {
    pub pairs: Vec<PairGpu>,
    pub jobs: Vec<JobGpu>,
    /// Triangle corners, 3 per triangle, xyz [m] (w unused), shape [triangle_count * 3].
    pub tri_verts: Vec<[f32; 4]>,
    /// All SDF grids' values, quantised to i16 (value = q * `sdf_scale` [m]) and packed two per word,
    /// low half first; each grid starts at an even value index.
    pub sdf_values: Vec<u32>,
}

impl FlatModel {
    /// Whether every pair's query triangles form one job (job i being pair i's): then a pair's patches
    /// come from one workgroup's reduction, and the second level (merge.wgsl, which combines the patches of
    /// a pair's jobs) is left out: the pipeline's generate pass writes the final patches, and the CPU twin
    /// skips merge_cpu likewise. Run on one job's patches the merge would only re-order them, re-pick the
    /// same contacts into slots and re-round the patch areas from per-contact shares (the nut-bolt pair's
    /// contact handling at 256 worlds: about 14% of it).
    pub fn single_job_pairs(&self) -> bool {
        self.jobs.len() == self.pairs.len()
            && self.pairs.iter().enumerate().all(|(i, p)| p.job_count == 1 && p.job_first == i as u32)
    }
}

/// Query shapes of at most this many triangles (one batch at the default settings; a box has 20) keep their
/// order: their candidates are few, and among equally deep ones (a face flat on another) the order decides
/// the tie-breaks, which the GPU and the CPU twin, rounding differently, then resolve differently (a settling
/// stack of boxes, sorted, came out 4e-5 m apart in one cold frame against the parity test's 1e-5, where it
/// had matched).
pub const NORMAL_ORDER_MIN: usize = 256;

/// The triangles in the order the kernels query them: within each run of `chunk` (one job's triangles, so a
/// job holds the same triangles as in the given order, which the many-body model orders by space for its
/// job culls), sorted by the direction of their normals, stable. Consecutive triangles then mostly fall
/// into one patch of the reduction (bins by normal, paper III-C), where an invocation's candidates share
/// the patch list's reads (common.wgsl). Key: the normal's octahedral map on a 64 x 64 grid (cells of
/// about 3-6 degrees against the 10 degree bins), cells in Morton order so that neighbouring cells mostly
/// stay neighbours; degenerate triangles (spheres, capsules, a box's corner points) last, in their order, so
/// that among equally deep candidates (a box's face on a plane) the corners, whose codes are higher, still
/// win slot 0's tie-break. Shapes of at most [`NORMAL_ORDER_MIN`] triangles keep their order.
pub fn normal_ordered(triangles: &[[Vec3; 3]], chunk: usize) -> Vec<[Vec3; 3]> {
    let key = |[a, b, c]: &[Vec3; 3]| -> u32 {
        let n = (*b - *a).cross(*c - *a);
        let l2 = n.length_squared();
        if l2.is_nan() || l2 <= 0.0 {
            return u32::MAX;
        }
        let n = n / (n.x.abs() + n.y.abs() + n.z.abs());
        let (mut u, mut v) = (n.x, n.y);
        if n.z < 0.0 {
            (u, v) = ((1.0 - n.y.abs()) * n.x.signum(), (1.0 - n.x.abs()) * n.y.signum());
        }
        let q = |x: f32| ((x * 0.5 + 0.5) * 64.0).clamp(0.0, 63.0) as u32;
        let (qu, qv) = (q(u), q(v));
        let mut m = 0;
        for bit in 0..6 {
            m |= ((qu >> bit) & 1) << (2 * bit) | ((qv >> bit) & 1) << (2 * bit + 1);
        }
        m
    };
    let mut out = triangles.to_vec();
    if out.len() <= NORMAL_ORDER_MIN {
        return out;
    }
    for run in out.chunks_mut(chunk.max(1)) {
        run.sort_by_key(key);
    }
    out
}

fn pose4(p: Vec3) -> [f32; 4] {
    [p.x, p.y, p.z, 0.0]
}

fn quat4(q: Quat) -> [f32; 4] {
    let q = q.normalize();
    [q.x, q.y, q.z, q.w]
}

/// Checks a pair's body indices, friction and contact offset.
fn check_pair(i: usize, p: &PairSpec, body_count: u32) -> Result<()> {
    for (field, body) in [("body_a", p.body_a), ("body_b", p.body_b)] {
        if body != NO_BODY && body >= body_count {
            return Err(EngineError::Config {
                field,
                value: format!("{body} (pair {i})"),
                expected: format!("a body index below body_count = {body_count} or NO_BODY"),
            });
        }
    }
    if !(p.friction.is_finite() && p.friction >= 0.0) {
        return Err(EngineError::Config {
            field: "friction",
            value: format!("{} (pair {i})", p.friction),
            expected: "a finite coefficient >= 0".into(),
        });
    }
    if !(p.contact_offset.is_finite() && p.contact_offset >= 0.0) {
        return Err(EngineError::Config {
            field: "contact_offset",
            value: format!("{} (pair {i})", p.contact_offset),
            expected: "a finite distance >= 0 [m]".into(),
        });
    }
    Ok(())
}

/// A [`FlatModel`] being built, with the query shapes and grids already in it: shared ones are uploaded (and
/// a grid's bound scanned) once.
#[derive(Default)]
struct Flattening {
    flat: FlatModel,
    query_first: Vec<(*const QueryShape, u32)>,
    grid_offset: Vec<(*const SdfGrid, u32)>,
    grid_bound: Vec<(*const SdfGrid, [f32; 4])>,
}

impl Flattening {
    /// The first query triangle of `p`'s query shape, uploading the shape where it is new.
    fn query(&mut self, p: &PairSpec, chunk: u32, by_normal: bool) -> u32 {
        let key = Arc::as_ptr(&p.query);
        match self.query_first.iter().find(|(k, _)| *k == key) {
            Some(&(_, f)) => f,
            None => {
                let f = (self.flat.tri_verts.len() / 3) as u32;
                let ordered: Cow<[[Vec3; 3]]> = if by_normal {
                    Cow::Owned(normal_ordered(&p.query.triangles, chunk as usize))
                } else {
                    Cow::Borrowed(&p.query.triangles)
                };
                for t in ordered.iter() {
                    self.flat.tri_verts.extend(t.iter().map(|v| pose4(*v)));
                }
                self.query_first.push((key, f));
                f
            }
        }
    }

    /// The SDF shape's (sdf_kind, sdf_origin, sdf_dims, sdf_scale) of [`PairGpu`], appending its words to
    /// sdf_values where they are new.
    fn sdf(&mut self, sdf: &SdfShape) -> (u32, [f32; 4], [u32; 4], f32) {
        let flat = &mut self.flat;
        match sdf {
            SdfShape::Plane => (1u32, [0.0; 4], [2, 2, 2, 0], 0.0),
            // Exact field: no interpolation slack (sdf_origin.w = 0); parameters as words in sdf_values.
            SdfShape::Thread(t) => {
                let base = flat.sdf_values.len() as u32;
                flat.sdf_values.extend_from_slice(&t.to_words());
                (2u32, [0.0; 4], [2, 2, 2, base], 0.0)
            }
            SdfShape::Revolved(r) => {
                let base = flat.sdf_values.len() as u32;
                flat.sdf_values.extend_from_slice(&r.to_words());
                (3u32, [0.0; 4], [2, 2, 2, base], 0.0)
            }
            SdfShape::Grid(g) => {
                let key = Arc::as_ptr(g);
                let scale = sdf_quantum(g.spacing);
                let off = match self.grid_offset.iter().find(|(k, _)| *k == key) {
                    Some(&(_, o)) => o,
                    None => {
                        let o = 2 * flat.sdf_values.len() as u32;
                        flat.sdf_values.extend(pack_i16(&g.values, scale));
                        self.grid_offset.push((key, o));
                        o
                    }
                };
                (0, [g.origin.x, g.origin.y, g.origin.z, g.spacing], [g.dims.x, g.dims.y, g.dims.z, off], scale)
            }
        }
    }

    /// Jobs of `chunk` query triangles (the last one shorter) over a pair's triangles; returns the first.
    fn push_jobs(&mut self, pair: u32, tri_first: u32, tri_count: u32, chunk: u32) -> u32 {
        let jobs = &mut self.flat.jobs;
        let job_first = jobs.len() as u32;
        let mut start = 0;
        while start < tri_count {
            let n = chunk.min(tri_count - start);
            jobs.push(JobGpu { pair, tri_first: tri_first + start, tri_count: n, slot: jobs.len() as u32 - job_first });
            start += n;
        }
        job_first
    }

    /// The bounding sphere of `p`'s SDF shape in its own frame ([`PairGpu::b_bound`]).
    fn sdf_bound(&mut self, p: &PairSpec) -> [f32; 4] {
        match &p.sdf {
            // Shared grids (a pile's parts) are scanned once.
            SdfShape::Grid(g) => {
                let key = Arc::as_ptr(g);
                match self.grid_bound.iter().find(|(k, _)| *k == key) {
                    Some(&(_, b)) => b,
                    None => {
                        let b = p.sdf.bound();
                        self.grid_bound.push((key, b));
                        b
                    }
                }
            }
            SdfShape::Thread(t) => {
                let [x, y, z, r] = t.bound();
                [x, y, z, r + THREAD_BOUND_SLACK * p.contact_offset]
            }
            other => other.bound(),
        }
    }
}

impl ContactModel {
    /// Flattens the model; `chunk` query triangles per job (a multiple of 256), each shape's triangles in
    /// their order.
    pub fn flatten(&self, chunk: u32) -> Result<FlatModel> {
        self.flatten_ordered(chunk, false)
    }

    /// [`flatten`](Self::flatten), with each job's query triangles ordered by normal where `by_normal`
    /// ([`normal_ordered`]; the contact pipelines ask for it with several candidates per invocation).
    pub fn flatten_ordered(&self, chunk: u32, by_normal: bool) -> Result<FlatModel> {
        // Regression: chunk 0 split every pair into endless empty jobs until the process ran out of memory.
        if chunk == 0 || chunk % 256 != 0 {
            return Err(EngineError::Config {
                field: "chunk",
                value: chunk.to_string(),
                expected: "query triangles per job: a multiple of 256 (256, 512, ...)".into(),
            });
        }
        let mut f = Flattening::default();
        for (i, p) in self.pairs.iter().enumerate() {
            check_pair(i, p, self.body_count)?;
            let tri_first = f.query(p, chunk, by_normal);
            let tri_count = p.query.triangles.len() as u32;
            let (sdf_kind, sdf_origin, sdf_dims, sdf_scale) = f.sdf(&p.sdf);
            // Area quantum: 1/64 of the mean triangle area, so patch measures resolve small triangles.
            let total_area: f32 =
                p.query.triangles.iter().map(|[a, b, c]| 0.5 * (*b - *a).cross(*c - *a).length()).sum();
            let mean_area = total_area / tri_count.max(1) as f32;
            let area_unit = if mean_area > 0.0 { mean_area / 64.0 } else { 1e-12 };
            let mean_edge = (2.0 * mean_area).sqrt();
            let job_first = f.push_jobs(i as u32, tri_first, tri_count, chunk);
            let pair = PairGpu {
                a_pos: pose4(p.a_pose.0),
                a_rot: quat4(p.a_pose.1),
                b_pos: pose4(p.b_pose.0),
                b_rot: quat4(p.b_pose.1),
                sdf_origin,
                sdf_dims,
                body_a: p.body_a,
                body_b: p.body_b,
                tri_first,
                tri_count,
                sdf_kind,
                job_first,
                job_count: f.flat.jobs.len() as u32 - job_first,
                sdf_scale,
                contact_offset: p.contact_offset,
                radius: p.query.radius,
                area_unit,
                // Contacts of one patch closer than a tenth of a typical edge add nothing.
                min_separation: 0.1 * mean_edge,
                friction: p.friction,
                many_body_template: 0,
                _pad: [0.0; 2],
                a_bound: bounding_sphere(p.query.triangles.iter().flatten().copied(), p.query.radius),
                b_bound: f.sdf_bound(p),
            };
            f.flat.pairs.push(pair);
        }
        let mut flat = f.flat;
        if flat.tri_verts.is_empty() {
            flat.tri_verts.push([0.0; 4]);
        }
        if flat.sdf_values.is_empty() {
            flat.sdf_values.push(0);
        }
        Ok(flat)
    }

    /// Query triangles of the largest pair: used to pick the job size.
    pub fn max_triangles(&self) -> u32 {
        self.pairs.iter().map(|p| p.query.triangles.len() as u32).max().unwrap_or(0)
    }
}

/// Quantum of the 16-bit SDF storage for a grid of `spacing` [m]: 1/256 of a voxel, so values within
/// 128 voxels of the surface are stored to 0.2% of a voxel and farther ones are clamped (still a valid
/// lower bound for culling). Halving the f32 grid lets a 512-resolution bolt (~46M samples) fit the
/// 128 MiB storage-buffer binding limit of many adapters (lavapipe's included).
pub fn sdf_quantum(spacing: f32) -> f32 {
    spacing / 256.0
}

/// Quantises values [m] to i16 units of `scale` and packs them two per u32 (low half first).
pub fn pack_i16(values: &[f32], scale: f32) -> Vec<u32> {
    let q = |v: f32| ((v / scale).round().clamp(-32767.0, 32767.0) as i16) as u16 as u32;
    values.chunks(2).map(|c| q(c[0]) | (c.get(1).map_or(0, |&v| q(v)) << 16)).collect()
}

/// Triangles per job: enough workgroups to fill the device (~64) without splitting pairs needlessly.
pub fn auto_chunk(max_triangles: u32, world_count: u32) -> u32 {
    let per_pair_jobs = (64 / world_count.max(1)).max(1);
    let chunk = max_triangles.div_ceil(per_pair_jobs).next_multiple_of(256);
    chunk.clamp(256, 1 << 20)
}

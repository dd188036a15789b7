//! The CPU SDF baker: a triangle mesh in, a dense [`SdfGrid`] of exact signed distances out.
//!
//! # Grid
//! `resolution` is the number of samples along the mesh's longest AABB axis *across the mesh*: the
//! spacing is `h = longest_extent / (resolution - 1)`, so the first and last of those samples lie on the
//! mesh's bounds. The sampled box is the mesh AABB grown on every side by the band
//! `max(margin, MIN_MARGIN_VOXELS * h)` (so the default `margin = 0` gives a 4-voxel band, and the surface
//! never touches the box, where [`SdfGrid::sample`] switches to its outside extrapolation); `origin` is
//! `aabb.min - band` and `dims` is the smallest sample count per axis whose last sample reaches
//! `aabb.max + band`. The whole memory the bake needs (the grid and its scratch,
//! [`BAKE_BYTES_PER_SAMPLE`] per sample) is computed from `dims` before anything is allocated, and a grid
//! over `max_bytes` is refused with [`EngineError::TooLarge`] naming the largest resolution that fits.
//!
//! # Unsigned distance (exact)
//! Every sample gets the exact Euclidean distance to the closest point of the closest triangle (the
//! closest-point-on-triangle construction of Ericson, *Real-Time Collision Detection*, 2005, section
//! 5.1.5, as implemented by parry3d's point queries, found through parry3d's BVH). Samples are visited in
//! rows, and since the distance function is 1-Lipschitz (`|d(p) - d(q)| <= |p - q|`), the previous
//! sample's distance plus one spacing bounds the next one's, and passing that bound to the BVH search
//! prunes every node farther away from the start. Z-slices run in parallel with rayon (the M16 bolt at
//! resolution 256, 159 x 159 x 265 samples, takes about 7 s on 2 busy cores).
//!
//! # Sign (robust to small holes)
//! Pseudo-normal signs (Baerentzen and Aanaes, "Signed distance computation using the angle weighted
//! pseudonormal", IEEE TVCG 11(3), 2005) are exact on closed meshes but flip whole regions near a hole, so
//! they are only the last resort here. The sign comes from three stages:
//! 1. **Ray votes along the three axes** (the "ray stabbing" with a majority vote of Nooruddin and Turk,
//!    "Simplification and repair of polygonal models using volumetric techniques", IEEE TVCG 9(2), 2003):
//!    for each axis, every grid row parallel to it is a line; each triangle is rasterised onto the 2D grid
//!    of rows (its projection's bounding box, then an exact edge test per row), giving the depth at which
//!    the row crosses it and whether it enters or leaves (from the triangle's winding). Rows meeting an
//!    edge or vertex exactly are resolved with Simulation of Simplicity (Edelsbrunner and Muecke, ACM TOG
//!    9(1), 1990): the row is perturbed by `(eps, eps^2)`, and each edge's side test is evaluated in one
//!    canonical vertex order, so of two triangles sharing an edge exactly one is crossed, whatever the
//!    rounding, and a closed mesh's rows always see balanced crossings. An entry and an exit at the same
//!    depth (a row grazing a fold) cancel. How a row's sorted crossings become votes depends on the mesh:
//!    - closed (no boundary edge): the winding number (inside where it is not zero, so overlapping shells
//!      stay inside); a row whose running winding goes negative or does not end at zero abstains;
//!    - with boundary edges: each sample looks only at the crossing just before it and the one just after
//!      it. Inside after an entry and before an exit, outside after an exit (or none) and before an entry
//!      (or none); if the two disagree, a crossing is missing beside the sample (a hole) and it abstains.
//!      A hole thus silences only the stretch of one row between the crossings around it, and a wrong
//!      vote needs two holes on one row to hide each other;
//!    - with misoriented edges (entry and exit cannot be told apart): parity, rows with an odd count
//!      abstain.
//!
//!    A sample's sign is the majority of its (up to three) votes.
//! 2. Samples without a majority (no vote, or one each way) take the sign of neighbours that provably lie
//!    on the same side: two neighbouring samples `p`, `q` (distance `h` apart) with
//!    `|d(p)| + |d(q)| > h` cannot have a surface point `s` between them, since it would give
//!    `|d(p)| + |d(q)| <= |p - s| + |s - q| = h` (triangle inequality). This is a breadth-first propagation
//!    over such links, with a small slack over `h` so float rounding never links the two sides of a
//!    surface. (Near a hole, the link can pass through the hole; this is why it only fills in samples the
//!    votes left open and never overrides a vote.)
//! 3. Samples still undecided (isolated at the surface) take the pseudo-normal sign at their closest point.
//!
//! A mesh that is not watertight ([`TriMesh::topology`]) is baked anyway with a `log::warn!` naming the
//! counts. Degenerate (zero-area) triangles are skipped: they bound nothing.

use super::SdfGrid;
use crate::error::{EngineError, Result};
use crate::mesh::TriMesh;
use glam::{DVec3, UVec3, Vec3};
use parry3d::query::PointQueryWithLocation;
use parry3d::shape::{CompositeShapeRef, TriMesh as ParryMesh, TrianglePointLocation};
use rayon::prelude::*;
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicI8, AtomicUsize, Ordering};
use std::time::Instant;

/// The band around the mesh AABB is at least this many voxels, whatever `margin` says.
pub const MIN_MARGIN_VOXELS: f32 = 4.0;

/// Peak bytes the bake may need per grid sample: the f32 value (4) and its ray vote (1), plus, in the worst
/// case where no sample gets a vote, an undecided-sample list (4) and a propagation queue (4). Per-row
/// crossing lists come on top; they grow with the square of the resolution, not its cube, and are small
/// next to this.
pub const BAKE_BYTES_PER_SAMPLE: u64 = 13;

/// Default memory limit of a bake [bytes] (2 GiB).
pub const DEFAULT_MAX_BYTES: u64 = 2 << 30;

/// Relative slack of the 1-Lipschitz bounds (BVH pruning and same-side links) over the exact spacing,
/// so that f32 rounding of distances and sample positions never makes a bound too tight.
const LIPSCHITZ_SLACK: f32 = 1e-3;

/// What to bake.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BakeParams {
    /// Samples along the mesh's longest AABB axis, from its min to its max bound (>= 2).
    pub resolution: u32,
    /// Band around the mesh AABB that is also sampled [m]; the bake uses at least
    /// [`MIN_MARGIN_VOXELS`] voxels.
    pub margin: f32,
    /// Refuse bakes needing more memory than this [bytes] (grid plus scratch, see
    /// [`BAKE_BYTES_PER_SAMPLE`]).
    pub max_bytes: u64,
}

impl Default for BakeParams {
    /// Resolution 256 (the paper's and the design's default), the minimum band of
    /// [`MIN_MARGIN_VOXELS`] voxels, 2 GiB.
    fn default() -> Self {
        BakeParams { resolution: 256, margin: 0.0, max_bytes: DEFAULT_MAX_BYTES }
    }
}

/// Where the samples of a bake lie.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridLayout {
    /// Position of sample (0, 0, 0) [m].
    pub origin: Vec3,
    /// Distance between neighbouring samples [m].
    pub spacing: f32,
    /// Samples along x, y, z.
    pub dims: UVec3,
}

impl GridLayout {
    /// Number of samples.
    pub fn sample_count(&self) -> u64 {
        self.dims.x as u64 * self.dims.y as u64 * self.dims.z as u64
    }

    /// Peak memory of baking this layout [bytes].
    pub fn bake_bytes(&self) -> u64 {
        self.sample_count() * BAKE_BYTES_PER_SAMPLE
    }

    #[inline]
    fn point(&self, i: u32, j: u32, k: u32) -> Vec3 {
        // The same arithmetic as `SdfGrid::point`, so both agree to the bit.
        self.origin + self.spacing * Vec3::new(i as f32, j as f32, k as f32)
    }
}

/// Dims computed in u64, before any check that they fit anything.
struct RawLayout {
    origin: Vec3,
    spacing: f32,
    dims: [u64; 3],
}

impl RawLayout {
    fn samples(&self) -> u128 {
        self.dims.iter().map(|&d| d as u128).product()
    }
    fn bytes(&self) -> u128 {
        self.samples() * BAKE_BYTES_PER_SAMPLE as u128
    }
    /// Fits the grid's u32 sample indexing and the memory limit.
    fn fits(&self, max_bytes: u64) -> bool {
        self.samples() <= u32::MAX as u128 && self.bytes() <= max_bytes as u128
    }
}

fn raw_layout(lo: Vec3, hi: Vec3, resolution: u32, margin: f32) -> RawLayout {
    let ext = hi - lo;
    let longest = ext.max_element() as f64;
    let spacing = (longest / (resolution as f64 - 1.0)) as f32;
    let band = margin.max(MIN_MARGIN_VOXELS * spacing);
    let origin = lo - Vec3::splat(band);
    let mut dims = [0u64; 3];
    for a in 0..3 {
        let span = ext[a] as f64 + 2.0 * band as f64;
        let mut n = (span / spacing as f64).ceil().max(1.0) as u64 + 1;
        // f32 rounding of origin + spacing * (n - 1) may fall a hair short of the far bound.
        for _ in 0..3 {
            if origin[a] + spacing * (n - 1) as f32 >= hi[a] + band {
                break;
            }
            n += 1;
        }
        dims[a] = n;
    }
    RawLayout { origin, spacing, dims }
}

fn mesh_error(message: String) -> EngineError {
    EngineError::Asset { path: PathBuf::from("<mesh being baked into an SDF>"), message }
}

/// Validates `params` and `mesh` and returns the bake's sample layout, refusing (without allocating) a
/// grid whose bake would need more than `params.max_bytes`.
pub fn layout(mesh: &TriMesh, params: &BakeParams) -> Result<GridLayout> {
    if params.resolution < 2 {
        return Err(EngineError::Config {
            field: "resolution",
            value: params.resolution.to_string(),
            expected: "at least 2 samples along the longest axis (256 is the default)".into(),
        });
    }
    if !params.margin.is_finite() || params.margin < 0.0 {
        return Err(EngineError::Config {
            field: "margin",
            value: params.margin.to_string(),
            expected: "a finite band >= 0 m around the mesh".into(),
        });
    }
    if mesh.triangles.is_empty() {
        return Err(mesh_error("no triangles: an SDF needs a surface".into()));
    }
    let n = mesh.positions.len();
    if let Some((t, tri)) = mesh.triangles.iter().enumerate().find(|(_, tri)| tri.iter().any(|&i| i as usize >= n)) {
        return Err(mesh_error(format!("triangle {t} = {tri:?} indexes past the {n} vertices")));
    }
    if let Some((v, p)) = mesh.positions.iter().enumerate().find(|(_, p)| !p.is_finite()) {
        return Err(mesh_error(format!("vertex {v} = {p} is not finite")));
    }
    let (lo, hi) = mesh.aabb();
    if (hi - lo).max_element() <= 0.0 {
        return Err(mesh_error(format!("all vertices coincide at {lo}: the mesh has no extent")));
    }
    let raw = raw_layout(lo, hi, params.resolution, params.margin);
    if !raw.fits(params.max_bytes) {
        // The largest resolution that fits (memory grows monotonically with resolution).
        let (mut ok, mut bad) = (1u32, params.resolution);
        while bad - ok > 1 {
            let mid = ok + (bad - ok) / 2;
            if raw_layout(lo, hi, mid, params.margin).fits(params.max_bytes) {
                ok = mid
            } else {
                bad = mid
            }
        }
        let hint = if ok >= 2 {
            format!("resolution {ok} or less fits (the limit, and at most 2^32 samples), or raise max_bytes")
        } else {
            "not even resolution 2 fits: raise max_bytes or shrink the margin".into()
        };
        let d = raw.dims;
        return Err(EngineError::TooLarge {
            what: format!("an SDF bake at resolution {} ({} x {} x {} samples)", params.resolution, d[0], d[1], d[2]),
            needed_bytes: raw.bytes().min(u64::MAX as u128) as u64,
            limit_bytes: params.max_bytes,
            hint,
        });
    }
    let d = raw.dims;
    Ok(GridLayout { origin: raw.origin, spacing: raw.spacing, dims: UVec3::new(d[0] as u32, d[1] as u32, d[2] as u32) })
}

/// How crossings along a row decide inside.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Rule {
    /// Closed meshes: inside where the winding number is not zero (overlapping shells stay inside); a row
    /// is trusted when its running winding never goes negative and ends at zero.
    Winding,
    /// Meshes with holes: each sample is judged by the crossings on either side of it only: inside after
    /// an entry and before an exit, outside after an exit (or none) and before an entry (or none); a
    /// sample whose two neighbouring crossings disagree has a missing crossing beside it and abstains.
    /// A hole thus spoils only the stretch of the row between the crossings around it.
    Alternation,
    /// Misoriented meshes (entering and leaving cannot be told apart): inside where the crossing count is
    /// odd; a row is trusted when it crosses an even number of times.
    Parity,
}

/// Bakes the signed distance field of `mesh` (negative inside). See the module documentation.
pub fn bake(mesh: &TriMesh, params: &BakeParams) -> Result<SdfGrid> {
    let layout = layout(mesh, params)?;
    let start = Instant::now();
    let topo = mesh.topology();
    if !topo.is_watertight() {
        log::warn!(
            "SDF bake: mesh is not watertight ({} boundary edges, {} non-manifold edges, {} misoriented edges, \
             {} degenerate triangles); signs come from ray votes and may be wrong next to the defects",
            topo.boundary_edges,
            topo.non_manifold_edges,
            topo.misoriented_edges,
            topo.degenerate_triangles
        );
    }
    let rule = if topo.misoriented_edges > 0 {
        Rule::Parity
    } else if topo.boundary_edges > 0 || topo.non_manifold_edges > 0 {
        Rule::Alternation
    } else {
        Rule::Winding
    };
    // A mesh wound clockwise seen from outside has negative volume; its crossings' roles swap.
    let inverted = mesh.signed_volume() < 0.0;
    // Zero-area triangles bound nothing, and the closest-point query has nothing to gain from them.
    let triangles: Vec<[u32; 3]> = (0..mesh.triangles.len())
        .filter(|&t| {
            let [a, b, c] = mesh.triangle(t);
            (b - a).cross(c - a).length_squared() > 0.0
        })
        .map(|t| mesh.triangles[t])
        .collect();
    if triangles.is_empty() {
        return Err(mesh_error(format!("all {} triangles have zero area", mesh.triangles.len())));
    }
    let parry = ParryMesh::new(mesh.positions.clone(), triangles.clone())
        .map_err(|e| mesh_error(format!("cannot build the distance BVH: {e:?}")))?;

    let mut values = unsigned_distances(&parry, &layout);
    let t_dist = start.elapsed();
    let (votes, abstained, rows) = ray_votes(&mesh.positions, &triangles, &layout, rule, inverted);
    let t_rays = start.elapsed();
    let (propagated, fallback) = apply_signs(&mut values, votes, &layout, &mesh.positions, &triangles, &parry);
    log::debug!(
        "SDF bake {} x {} x {} (h = {:.3e} m, {} triangles): distances {:.2?}, rays {:.2?} ({abstained} of {rows} \
         rows abstained at least in part, {rule:?} rule), signs {:.2?} ({propagated} samples from a \
         neighbour, {fallback} by pseudo-normal)",
        layout.dims.x,
        layout.dims.y,
        layout.dims.z,
        layout.spacing,
        triangles.len(),
        t_dist,
        t_rays - t_dist,
        start.elapsed() - t_rays,
    );
    Ok(SdfGrid { origin: layout.origin, spacing: layout.spacing, dims: layout.dims, values })
}

/// Absolute rounding scale of sample positions and distances [m].
fn rounding_eps(layout: &GridLayout) -> f32 {
    let far = layout.origin.abs().max((layout.origin + layout.spacing * layout.dims.as_vec3()).abs());
    16.0 * f32::EPSILON * far.max_element()
}

/// Exact distance from every sample to the mesh surface.
fn unsigned_distances(parry: &ParryMesh, layout: &GridLayout) -> Vec<f32> {
    let UVec3 { x: nx, y: ny, z: nz } = layout.dims;
    let step = layout.spacing * (1.0 + LIPSCHITZ_SLACK) + rounding_eps(layout);
    let closest = |p: Vec3, bound: f32| -> f32 {
        let shape = CompositeShapeRef(parry);
        shape
            .project_local_point(p, bound, false)
            // The Lipschitz bound was a hair too tight for rounding: search everything.
            .or_else(|| shape.project_local_point(p, f32::MAX, false))
            .map(|(_, proj)| (proj.point - p).length())
            .unwrap_or(f32::MAX)
    };
    let mut values = vec![0.0f32; (nx * ny * nz) as usize];
    values.par_chunks_mut((nx * ny) as usize).enumerate().for_each(|(k, slab)| {
        let k = k as u32;
        let mut row_bound = f32::MAX;
        for j in 0..ny {
            let mut bound = row_bound;
            for i in 0..nx {
                let d = closest(layout.point(i, j, k), bound);
                bound = d + step;
                if i == 0 {
                    row_bound = bound;
                }
                slab[(i + nx * j) as usize] = d;
            }
        }
    });
    values
}

/// A row crossing a triangle: the row, the depth along the axis, and +1 entering / -1 leaving.
#[derive(Clone, Copy)]
struct Hit {
    row: u32,
    t: f32,
    w: i8,
}

/// Twice the signed area of (a, b, c).
#[inline]
fn orient(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

/// Whether `q`, perturbed by (eps, eps^2), lies left of the directed edge p0 -> p1. The determinant is
/// always evaluated in one canonical vertex order, so the two directions of an edge get exactly opposite
/// answers whatever the rounding (Simulation of Simplicity).
#[inline]
fn left_of(p0: [f64; 2], p1: [f64; 2], q: [f64; 2]) -> bool {
    let flip = (p1[0], p1[1]) < (p0[0], p0[1]);
    let (a, b) = if flip { (p1, p0) } else { (p0, p1) };
    let det = orient(a, b, q);
    let left = if det != 0.0 {
        det > 0.0
    } else {
        // The perturbation adds -(b - a).v * eps + (b - a).u * eps^2 to the determinant.
        let (du, dv) = (b[0] - a[0], b[1] - a[1]);
        if dv != 0.0 {
            dv < 0.0
        } else {
            du > 0.0
        }
    };
    left != flip
}

/// Per-sample votes (+1 per axis whose row says inside, -1 outside, 0 abstained), rows that abstained
/// (wholly or in part), rows. `inverted`: the mesh winds clockwise seen from outside.
fn ray_votes(
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    layout: &GridLayout,
    rule: Rule,
    inverted: bool,
) -> (Vec<i8>, usize, usize) {
    let dims = layout.dims.to_array();
    let n = layout.sample_count() as usize;
    let votes: Vec<AtomicI8> = (0..n).map(|_| AtomicI8::new(0)).collect();
    let abstained = AtomicUsize::new(0);
    let mut total_rows = 0;
    let h = layout.spacing;
    let org = layout.origin.to_array();
    let eps_t = rounding_eps(layout);
    for axis in 0..3 {
        // (u, v, axis) is a cyclic permutation of (x, y, z): counter-clockwise in (u, v) means the
        // triangle's normal points along +axis.
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        let (nu, nv, na) = (dims[u], dims[v], dims[axis]);
        let rows = nu as usize * nv as usize;
        total_rows += rows;
        let coord = |o: f32, i: u32| o + h * i as f32;
        let mut hits: Vec<Hit> = triangles
            .par_chunks(256)
            .flat_map_iter(|chunk| {
                let mut out = Vec::new();
                for tri in chunk {
                    let p = tri.map(|i| positions[i as usize]);
                    let q = p.map(|x| [x[u] as f64, x[v] as f64]);
                    let area = orient(q[0], q[1], q[2]);
                    if area == 0.0 {
                        continue; // parallel to the rows: no perturbed row crosses it
                    }
                    let ccw = area > 0.0;
                    // Counter-clockwise: the outward normal points along +axis, so the row leaves there.
                    let w: i8 = if ccw != inverted { -1 } else { 1 };
                    let depth = p.map(|x| x[axis] as f64);
                    let (dmin, dmax) = (depth[0].min(depth[1]).min(depth[2]), depth[0].max(depth[1]).max(depth[2]));
                    let range = |c: usize, n: u32| {
                        let lo = q.iter().map(|x| x[c]).fold(f64::MAX, f64::min);
                        let hi = q.iter().map(|x| x[c]).fold(f64::MIN, f64::max);
                        let o = org[if c == 0 { u } else { v }] as f64;
                        // One extra row each side: the exact test below decides.
                        let a = (((lo - o) / h as f64).floor() - 1.0).max(0.0) as u32;
                        let b = (((hi - o) / h as f64).ceil() + 1.0).min(n as f64 - 1.0).max(0.0) as u32;
                        a..=b
                    };
                    for iv in range(1, nv) {
                        let pv = coord(org[v], iv) as f64;
                        for iu in range(0, nu) {
                            let s = [coord(org[u], iu) as f64, pv];
                            if left_of(q[0], q[1], s) == ccw
                                && left_of(q[1], q[2], s) == ccw
                                && left_of(q[2], q[0], s) == ccw
                            {
                                let b0 = orient(q[1], q[2], s) / area;
                                let b1 = orient(q[2], q[0], s) / area;
                                let t = b0 * depth[0] + b1 * depth[1] + (1.0 - b0 - b1) * depth[2];
                                out.push(Hit { row: iu + nu * iv, t: t.clamp(dmin, dmax) as f32, w });
                            }
                        }
                    }
                }
                out
            })
            .collect();
        hits.par_sort_unstable_by(|a, b| a.row.cmp(&b.row).then(a.t.total_cmp(&b.t)).then(a.w.cmp(&b.w)));
        let mut offsets = vec![0usize; rows + 1];
        for hit in &hits {
            offsets[hit.row as usize + 1] += 1;
        }
        for r in 0..rows {
            offsets[r + 1] += offsets[r];
        }
        let mut stride = [1usize; 3];
        stride[1] = dims[0] as usize;
        stride[2] = dims[0] as usize * dims[1] as usize;
        (0..rows).into_par_iter().for_each_init(Vec::new, |row: &mut Vec<Hit>, r| {
            // A row grazing a fold enters and leaves at the same depth: that pair cancels.
            row.clear();
            for &hit in &hits[offsets[r]..offsets[r + 1]] {
                match row.last() {
                    Some(last) if hit.t - last.t <= eps_t && (rule == Rule::Parity || last.w == -hit.w) => {
                        row.pop();
                    }
                    _ => row.push(hit),
                }
            }
            let (iu, iv) = (r % nu as usize, r / nu as usize);
            let base = iu * stride[u] + iv * stride[v];
            let vote = |ia: u32, inside: bool| {
                votes[base + ia as usize * stride[axis]].fetch_add(if inside { 1 } else { -1 }, Ordering::Relaxed);
            };
            // Index of the first crossing at or beyond each sample, walked along the row.
            let mut next = 0usize;
            let mut advance = |ia: u32| {
                let x = coord(org[axis], ia);
                while next < row.len() && row[next].t < x {
                    next += 1;
                }
                next
            };
            match rule {
                Rule::Winding | Rule::Parity => {
                    let mut running = 0i32;
                    let mut valid = true;
                    for hit in row.iter() {
                        running += if rule == Rule::Winding { hit.w as i32 } else { 1 };
                        valid &= rule == Rule::Parity || running >= 0;
                    }
                    valid &= if rule == Rule::Winding { running == 0 } else { running % 2 == 0 };
                    if !valid {
                        abstained.fetch_add(1, Ordering::Relaxed);
                        return;
                    }
                    let mut winding = 0i32;
                    let mut counted = 0usize;
                    for ia in 0..na {
                        let k = advance(ia);
                        while counted < k {
                            winding += if rule == Rule::Winding { row[counted].w as i32 } else { 1 };
                            counted += 1;
                        }
                        vote(ia, if rule == Rule::Winding { winding != 0 } else { winding % 2 != 0 });
                    }
                }
                Rule::Alternation => {
                    let mut partial = false;
                    for ia in 0..na {
                        let k = advance(ia);
                        let after_entry = k > 0 && row[k - 1].w > 0;
                        let before_exit = k < row.len() && row[k].w < 0;
                        if after_entry == before_exit {
                            vote(ia, after_entry);
                        } else {
                            partial = true;
                        }
                    }
                    if partial {
                        abstained.fetch_add(1, Ordering::Relaxed);
                    }
                }
            }
        });
    }
    (votes.into_iter().map(AtomicI8::into_inner).collect(), abstained.into_inner(), total_rows)
}

/// Signs `values` (unsigned distances on entry) from the votes; returns how many samples took their sign
/// from a neighbour and how many needed the pseudo-normal fallback.
fn apply_signs(
    values: &mut [f32],
    mut state: Vec<i8>,
    layout: &GridLayout,
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    parry: &ParryMesh,
) -> (usize, usize) {
    let UVec3 { x: nx, y: ny, z: nz } = layout.dims;
    let link = layout.spacing * (1.0 + LIPSCHITZ_SLACK) + rounding_eps(layout);
    // +1 inside, -1 outside, 0 undecided (no vote or a tie).
    state.iter_mut().for_each(|s| *s = s.signum());
    let undecided: Vec<u32> = (0..state.len() as u32).filter(|&a| state[a as usize] == 0).collect();
    let neighbours = |a: u32| {
        let (i, j, k) = (a % nx, (a / nx) % ny, a / (nx * ny));
        let sz = nx * ny;
        [
            (i > 0).then(|| a - 1),
            (i + 1 < nx).then(|| a + 1),
            (j > 0).then(|| a - nx),
            (j + 1 < ny).then(|| a + nx),
            (k > 0).then(|| a - sz),
            (k + 1 < nz).then(|| a + sz),
        ]
        .into_iter()
        .flatten()
    };
    // Breadth-first from decided samples across links that cannot cross the surface. QUEUED marks an
    // undecided sample already in the queue, which bounds the queue by the sample count.
    const QUEUED: i8 = 2;
    let mut queue: std::collections::VecDeque<u32> = std::collections::VecDeque::new();
    let mut propagated = 0;
    let mut try_decide = |a: u32, state: &mut [i8], queue: &mut std::collections::VecDeque<u32>| {
        let da = values[a as usize];
        let linked = |b: u32| da + values[b as usize] > link;
        let sum: i32 =
            neighbours(a).filter(|&b| linked(b) && state[b as usize] != QUEUED).map(|b| state[b as usize] as i32).sum();
        state[a as usize] = sum.signum() as i8;
        if sum != 0 {
            propagated += 1;
            for b in neighbours(a) {
                if state[b as usize] == 0 && linked(b) {
                    state[b as usize] = QUEUED;
                    queue.push_back(b);
                }
            }
        }
    };
    for &a in &undecided {
        if state[a as usize] == 0 {
            try_decide(a, &mut state, &mut queue);
        }
    }
    while let Some(a) = queue.pop_front() {
        try_decide(a, &mut state, &mut queue);
    }
    let rest: Vec<u32> = undecided.into_iter().filter(|&a| state[a as usize] == 0).collect();
    if !rest.is_empty() {
        let normals = PseudoNormals::new(positions, triangles);
        let inside: Vec<bool> = rest
            .par_iter()
            .map(|&a| {
                let p = layout.point(a % nx, (a / nx) % ny, a / (nx * ny));
                let (proj, (t, loc)) = parry.project_local_point_and_get_location(p, false);
                (p - proj.point).as_dvec3().dot(normals.at(t as usize, loc)) < 0.0
            })
            .collect();
        for (&a, inside) in rest.iter().zip(inside) {
            state[a as usize] = if inside { 1 } else { -1 };
        }
    }
    values.par_iter_mut().zip(state.par_iter()).for_each(|(v, &s)| {
        if s > 0 {
            *v = -*v;
        }
    });
    (propagated, rest.len())
}

/// Angle-weighted vertex pseudo-normals and edge pseudo-normals (sum of the incident faces' unit
/// normals), after Baerentzen and Aanaes 2005.
struct PseudoNormals<'a> {
    positions: &'a [Vec3],
    triangles: &'a [[u32; 3]],
    vertex: Vec<DVec3>,
    edge: HashMap<(u32, u32), DVec3>,
}

impl<'a> PseudoNormals<'a> {
    fn new(positions: &'a [Vec3], triangles: &'a [[u32; 3]]) -> Self {
        let mut vertex = vec![DVec3::ZERO; positions.len()];
        let mut edge: HashMap<(u32, u32), DVec3> = HashMap::new();
        for tri in triangles {
            let p = tri.map(|i| positions[i as usize].as_dvec3());
            let nrm = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
            for c in 0..3 {
                let (a, b) = (p[(c + 1) % 3] - p[c], p[(c + 2) % 3] - p[c]);
                vertex[tri[c] as usize] += a.angle_between(b) * nrm;
                let (e0, e1) = (tri[c], tri[(c + 1) % 3]);
                *edge.entry((e0.min(e1), e0.max(e1))).or_default() += nrm;
            }
        }
        PseudoNormals { positions, triangles, vertex, edge }
    }

    /// The pseudo-normal at a closest-point location on triangle `t`.
    fn at(&self, t: usize, loc: TrianglePointLocation) -> DVec3 {
        let tri = self.triangles[t];
        let face = || {
            let p = tri.map(|i| self.positions[i as usize].as_dvec3());
            (p[1] - p[0]).cross(p[2] - p[0])
        };
        match loc {
            TrianglePointLocation::OnVertex(i) => self.vertex[tri[i as usize] as usize],
            TrianglePointLocation::OnEdge(e, _) => {
                // parry numbers the edges AB, BC, AC.
                let (a, b) = match e {
                    0 => (tri[0], tri[1]),
                    1 => (tri[1], tri[2]),
                    _ => (tri[0], tri[2]),
                };
                self.edge.get(&(a.min(b), a.max(b))).copied().unwrap_or_else(face)
            }
            TrianglePointLocation::OnFace(..) | TrianglePointLocation::OnSolid => face(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::box_mesh;

    /// A box whose faces lie exactly on grid planes and whose edges lie on grid rows: the degenerate case
    /// for the row tests. Every sample gets the exact box SDF.
    #[test]
    fn box_on_grid_lines_is_exact() {
        let h = Vec3::new(0.5, 0.25, 0.75);
        let mesh = box_mesh(h);
        let grid = bake(&mesh, &BakeParams { resolution: 13, ..Default::default() }).unwrap();
        assert_eq!(grid.spacing, 0.125);
        for k in 0..grid.dims.z {
            for j in 0..grid.dims.y {
                for i in 0..grid.dims.x {
                    let p = grid.point(i, j, k);
                    let q = p.abs() - h;
                    let exact = q.max(Vec3::ZERO).length() + q.max_element().min(0.0);
                    let got = grid.values[grid.index(i, j, k)];
                    assert!((got - exact).abs() < 1e-6, "{p}: {got} vs {exact}");
                }
            }
        }
    }

    /// A box with its +z face missing (a hole as large as a face), and the same box wound inside out,
    /// keep the closed box's signs: everywhere for the inverted one, and away from the missing face for
    /// the open one, whose rows through the hole abstain instead of flipping.
    #[test]
    fn open_and_inverted_boxes_keep_signs() {
        let h = Vec3::new(0.5, 0.25, 0.75);
        let params = BakeParams { resolution: 25, ..Default::default() };
        let closed = bake(&box_mesh(h), &params).unwrap();
        let mut inverted = box_mesh(h);
        inverted.triangles.iter_mut().for_each(|t| t.swap(1, 2));
        let inv = bake(&inverted, &params).unwrap();
        // Same distances up to rounding (the triangles' corners come in another order), same signs.
        let worst = inv.values.iter().zip(&closed.values).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max);
        assert!(worst < 1e-6, "inverted box differs by {worst}");
        let mut open = box_mesh(h);
        open.triangles.drain(2..4); // the two +z triangles
        assert_eq!(open.topology().boundary_edges, 4);
        let g = bake(&open, &params).unwrap();
        let mut compared = 0;
        for k in 0..g.dims.z {
            for j in 0..g.dims.y {
                for i in 0..g.dims.x {
                    let p = g.point(i, j, k);
                    let idx = g.index(i, j, k);
                    let near_hole = p.z > h.z - 1.5 * g.spacing
                        && p.x.abs() < h.x + 1.5 * g.spacing
                        && p.y.abs() < h.y + 1.5 * g.spacing;
                    if near_hole || closed.values[idx].abs() < 1e-6 {
                        continue;
                    }
                    compared += 1;
                    assert_eq!(
                        g.values[idx] < 0.0,
                        closed.values[idx] < 0.0,
                        "{p}: {} vs {}",
                        g.values[idx],
                        closed.values[idx]
                    );
                }
            }
        }
        assert!(compared > g.values.len() / 2);
    }

    #[test]
    fn bad_params_and_meshes_are_refused() {
        let mesh = box_mesh(Vec3::ONE);
        let e = bake(&mesh, &BakeParams { resolution: 1, ..Default::default() }).unwrap_err();
        assert!(matches!(e, EngineError::Config { field: "resolution", .. }), "{e}");
        let e = bake(&mesh, &BakeParams { margin: f32::NAN, ..Default::default() }).unwrap_err();
        assert!(matches!(e, EngineError::Config { field: "margin", .. }), "{e}");
        let e = bake(&TriMesh::default(), &BakeParams::default()).unwrap_err();
        assert!(matches!(e, EngineError::Asset { .. }), "{e}");
        let flat = TriMesh::new(vec![Vec3::ZERO; 3], vec![[0, 1, 2]]);
        assert!(matches!(bake(&flat, &BakeParams::default()), Err(EngineError::Asset { .. })));
    }

    #[test]
    fn layout_covers_the_band() {
        let mesh = box_mesh(Vec3::new(1.0, 0.5, 0.25));
        let l = layout(&mesh, &BakeParams { resolution: 101, margin: 0.3, max_bytes: u64::MAX }).unwrap();
        assert!((l.spacing - 0.02).abs() < 1e-7);
        let far = l.origin + l.spacing * (l.dims - UVec3::ONE).as_vec3();
        assert!(l.origin.cmple(Vec3::new(-1.3, -0.8, -0.55)).all() && far.cmpge(Vec3::new(1.3, 0.8, 0.55)).all());
        // No more than one extra sample per axis.
        assert!((far - Vec3::new(1.3, 0.8, 0.55)).max_element() < 2.0 * l.spacing, "{far}");
    }
}

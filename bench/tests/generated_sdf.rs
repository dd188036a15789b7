//! The SDF baker on OUR generated ISO M16 tight nut and bolt (factory-assets), checked against an
//! independent reference written here: the sign of every grid sample, and the interpolated distance near
//! the nut's surface. (engine/tests/sdf_bake.rs does the same for Factory's meshes with parry3d; this crate
//! has no parry3d, so the reference is a few lines of f64 geometry.)
//!
//! Reference inside test: ray parity along generic (non-axis) directions, majority of three, with
//! Moeller-Trumbore ray-triangle tests in f64 (Moeller and Trumbore, "Fast, minimum storage ray-triangle
//! intersection", JGT 2(1), 1997): independent of the baker's axis-aligned, perturbed scanlines and winding
//! numbers. Reference distance: the closest point on each triangle (Ericson, *Real-Time Collision
//! Detection*, 2005, section 5.1.5) in f64, brute force over all triangles.

use factory_assets::{nut_bolt, Fit, IsoSize, NutBolt, ThreadOptions};
use factory_engine::mesh::TriMesh;
use factory_engine::sdf::bake::{bake, BakeParams};
use factory_engine::sdf::SdfGrid;
use glam::{DVec3, Vec3};
use std::sync::OnceLock;

/// Resolution of both tests: nut about 90 x 103 x 55 samples, a few seconds for every check on 2 cores.
const RESOLUTION: u32 = 80;
/// Samples closer than this to the surface [m] have no meaningful sign; they are skipped.
const SURFACE_EPS: f64 = 1e-6;
/// Random points for the distance test, drawn within this many voxels of the nut's surface.
const NEAR_POINTS: usize = 3000;
const NEAR_BAND_VOXELS: f32 = 3.0;
/// Trilinear interpolation of exact samples of a 1-Lipschitz function errs by at most half a voxel
/// diagonal, sqrt(3)/2 voxel (see engine/tests/sdf_bake.rs for the derivation); this relative slack only
/// covers f32 rounding.
const HALF_DIAGONAL_SLACK: f32 = 1e-3;
/// Trilinear error is second order on smooth surface and largest at thread crests and roots, which are
/// creases 3 voxels apart at this resolution (pitch 2 mm, voxel about 0.34 mm); measured mean 0.054 voxel.
/// A systematic error (a shifted grid, a wrong spacing) raises the mean to a good fraction of a voxel.
const MEAN_ERROR_MAX_VOXELS: f32 = 0.1;
/// Generic ray directions for the parity test (normalised on use).
const RAY_DIRS: [[f64; 3]; 3] = [[0.5377, 0.8622, 0.3188], [-0.4336, 0.3426, 0.8339], [0.7254, -0.6303, 0.2769]];

fn parts() -> &'static NutBolt {
    static P: OnceLock<NutBolt> = OnceLock::new();
    P.get_or_init(|| nut_bolt(IsoSize::M16, Fit::Tight, &ThreadOptions::default()).unwrap())
}

fn nut_grid() -> &'static SdfGrid {
    static G: OnceLock<SdfGrid> = OnceLock::new();
    G.get_or_init(|| bake(&parts().nut.mesh, &BakeParams { resolution: RESOLUTION, ..Default::default() }).unwrap())
}

/// Runs `f` over `0..n` on every core, in order.
fn par_map<T: Send>(n: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
    let threads = std::thread::available_parallelism().map_or(2, |t| t.get());
    let chunk = n.div_ceil(threads).max(1);
    std::thread::scope(|s| {
        let handles: Vec<_> = (0..n)
            .step_by(chunk)
            .map(|lo| {
                s.spawn({
                    let f = &f;
                    move || (lo..(lo + chunk).min(n)).map(f).collect::<Vec<T>>()
                })
            })
            .collect();
        handles.into_iter().flat_map(|h| h.join().unwrap()).collect()
    })
}

/// The mesh in f64, with a bucket grid per ray direction for the parity test.
struct Reference {
    tris: Vec<[DVec3; 3]>,
    rays: Vec<RayBuckets>,
}

/// Triangles bucketed by their projection on the plane orthogonal to a ray direction: a ray from any point
/// can only cross the triangles of its point's bucket.
struct RayBuckets {
    dir: DVec3,
    u: DVec3,
    v: DVec3,
    lo: [f64; 2],
    cell: f64,
    n: [usize; 2],
    cells: Vec<Vec<u32>>,
}

impl RayBuckets {
    fn new(tris: &[[DVec3; 3]], dir: DVec3, cell: f64) -> Self {
        let u = dir.any_orthonormal_vector();
        let v = dir.cross(u);
        let proj = |p: DVec3| [p.dot(u), p.dot(v)];
        let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
        for p in tris.iter().flatten() {
            let q = proj(*p);
            for a in 0..2 {
                lo[a] = lo[a].min(q[a]);
                hi[a] = hi[a].max(q[a]);
            }
        }
        let n = [0, 1].map(|a| ((hi[a] - lo[a]) / cell) as usize + 1);
        let mut cells = vec![Vec::new(); n[0] * n[1]];
        for (t, tri) in tris.iter().enumerate() {
            let q = tri.map(proj);
            // Cells overlapping the projection's bounds, one cell wider for rounding.
            let range = |a: usize| {
                let (mn, mx) = q.iter().fold((f64::MAX, f64::MIN), |(mn, mx), p| (mn.min(p[a]), mx.max(p[a])));
                let first = ((mn - lo[a]) / cell).floor() as isize - 1;
                let last = ((mx - lo[a]) / cell).floor() as isize + 1;
                first.max(0) as usize..=(last.max(0) as usize).min(n[a] - 1)
            };
            for j in range(1) {
                for i in range(0) {
                    cells[i + n[0] * j].push(t as u32);
                }
            }
        }
        RayBuckets { dir, u, v, lo, cell, n, cells }
    }

    fn bucket(&self, p: DVec3) -> &[u32] {
        let c = [(p.dot(self.u) - self.lo[0]) / self.cell, (p.dot(self.v) - self.lo[1]) / self.cell];
        if c.iter().zip(self.n).any(|(&c, n)| c < 0.0 || c >= n as f64) {
            return &[];
        }
        &self.cells[c[0] as usize + self.n[0] * c[1] as usize]
    }
}

/// Whether the ray o + t d (t > 0) crosses triangle abc (Moeller-Trumbore).
fn ray_hits(o: DVec3, d: DVec3, [a, b, c]: [DVec3; 3]) -> bool {
    let (e1, e2) = (b - a, c - a);
    let pv = d.cross(e2);
    let det = e1.dot(pv);
    if det == 0.0 {
        return false;
    }
    let tv = o - a;
    let u = tv.dot(pv) / det;
    if !(0.0..=1.0).contains(&u) {
        return false;
    }
    let qv = tv.cross(e1);
    let v = d.dot(qv) / det;
    v >= 0.0 && u + v <= 1.0 && e2.dot(qv) / det > 0.0
}

/// Closest point to p on triangle abc (Ericson 2005, 5.1.5).
fn closest_on_triangle(p: DVec3, [a, b, c]: [DVec3; 3]) -> DVec3 {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = 1.0 / (va + vb + vc);
    a + ab * (vb * denom) + ac * (vc * denom)
}

impl Reference {
    /// `cell`: bucket size [m] (about a voxel).
    fn new(mesh: &TriMesh, cell: f64) -> Self {
        let topo = mesh.topology();
        assert!(topo.is_watertight(), "the generated part must be watertight: {topo:?}");
        let tris: Vec<[DVec3; 3]> =
            (0..mesh.triangle_count()).map(|t| mesh.triangle(t).map(|p| p.as_dvec3())).collect();
        let rays = RAY_DIRS.iter().map(|d| RayBuckets::new(&tris, DVec3::from_array(*d).normalize(), cell)).collect();
        Reference { tris, rays }
    }

    /// Inside by a majority of three parity counts.
    fn inside(&self, p: DVec3) -> bool {
        let odd = |r: &RayBuckets| {
            r.bucket(p).iter().filter(|&&t| ray_hits(p, r.dir, self.tris[t as usize])).count() % 2 == 1
        };
        self.rays.iter().filter(|r| odd(r)).count() >= 2
    }

    /// Exact unsigned distance [m] (brute force).
    fn distance(&self, p: DVec3) -> f64 {
        self.tris.iter().map(|t| (closest_on_triangle(p, *t) - p).length_squared()).fold(f64::MAX, f64::min).sqrt()
    }

    /// Marks the grid samples within [`SURFACE_EPS`] of some triangle.
    fn near_surface(&self, g: &SdfGrid) -> Vec<bool> {
        let mut near = vec![false; g.values.len()];
        let (o, h) = (g.origin.as_dvec3(), g.spacing as f64);
        for tri in &self.tris {
            let lo = (tri[0].min(tri[1]).min(tri[2]) - o - SURFACE_EPS) / h;
            let hi = (tri[0].max(tri[1]).max(tri[2]) - o + SURFACE_EPS) / h;
            let first = lo.ceil().max(DVec3::ZERO).as_uvec3();
            let last = hi.floor().as_ivec3().max(glam::IVec3::splat(-1));
            for k in first.z as i32..=last.z.min(g.dims.z as i32 - 1) {
                for j in first.y as i32..=last.y.min(g.dims.y as i32 - 1) {
                    for i in first.x as i32..=last.x.min(g.dims.x as i32 - 1) {
                        let p = g.point(i as u32, j as u32, k as u32).as_dvec3();
                        if (closest_on_triangle(p, *tri) - p).length() <= SURFACE_EPS {
                            near[g.index(i as u32, j as u32, k as u32)] = true;
                        }
                    }
                }
            }
        }
        near
    }
}

/// Compares every sample's sign with the reference; returns (samples compared, samples inside).
fn assert_signs_everywhere(name: &str, mesh: &TriMesh, g: &SdfGrid) -> (usize, usize) {
    let reference = Reference::new(mesh, g.spacing as f64);
    let near = reference.near_surface(g);
    let (nx, ny) = (g.dims.x as usize, g.dims.y as usize);
    let inside = par_map(g.values.len(), |idx| {
        let (i, j, k) = (idx % nx, (idx / nx) % ny, idx / (nx * ny));
        !near[idx] && reference.inside(g.point(i as u32, j as u32, k as u32).as_dvec3())
    });
    let mut wrong = Vec::new();
    let (mut compared, mut inside_count) = (0, 0);
    for idx in 0..g.values.len() {
        if near[idx] {
            continue;
        }
        compared += 1;
        inside_count += inside[idx] as usize;
        if inside[idx] != (g.values[idx] < 0.0) {
            wrong.push((idx, g.values[idx], inside[idx]));
        }
    }
    assert!(
        wrong.is_empty(),
        "{name}: {} of {compared} samples have the wrong sign, e.g. (index, value, reference inside) {:?}",
        wrong.len(),
        &wrong[..wrong.len().min(5)]
    );
    // Not vacuous: both signs occur in bulk.
    let outside = compared - inside_count;
    assert!(inside_count > compared / 10 && outside > compared / 10, "{name}: {inside_count} of {compared} inside");
    eprintln!(
        "{name}: {} samples, {compared} compared, {} within {SURFACE_EPS} m of the surface skipped",
        g.values.len(),
        g.values.len() - compared
    );
    (compared, inside_count)
}

#[test]
fn sign_at_every_grid_point_of_our_m16_nut_and_bolt() {
    let nb = parts();
    let (n, n_in) = assert_signs_everywhere("nut", &nb.nut.mesh, nut_grid());
    let bolt = bake(&nb.bolt.mesh, &BakeParams { resolution: RESOLUTION, ..Default::default() }).unwrap();
    let (m, m_in) = assert_signs_everywhere("bolt", &nb.bolt.mesh, &bolt);
    eprintln!("signs right at every sample: nut {n} ({n_in} inside), bolt {m} ({m_in} inside)");
}

/// A tiny 64-bit LCG (Knuth's MMIX constants); uniform f32 in [0, 1) from its top 24 bits.
struct Lcg(u64);

impl Lcg {
    fn next_f32(&mut self) -> f32 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
}

#[test]
fn distance_near_the_nut_within_half_a_voxel_diagonal() {
    let mesh = &parts().nut.mesh;
    let g = nut_grid();
    let h = g.spacing;
    let reference = Reference::new(mesh, h as f64);
    // Seeded points near the surface: a random point of a random triangle, moved up to the band width in a
    // random direction (inside and outside alike).
    let mut rng = Lcg(7);
    let points: Vec<Vec3> = (0..NEAR_POINTS)
        .map(|_| {
            let tri = mesh.triangle((rng.next_f32() * mesh.triangle_count() as f32) as usize);
            let (mut s, mut t) = (rng.next_f32(), rng.next_f32());
            if s + t > 1.0 {
                (s, t) = (1.0 - s, 1.0 - t);
            }
            let on = tri[0] + s * (tri[1] - tri[0]) + t * (tri[2] - tri[0]);
            let dir = Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, rng.next_f32() - 0.5).normalize_or(Vec3::Z);
            on + dir * (NEAR_BAND_VOXELS * h * rng.next_f32())
        })
        .collect();
    let exact: Vec<f64> = par_map(points.len(), |i| {
        let p = points[i].as_dvec3();
        let d = reference.distance(p);
        if reference.inside(p) {
            -d
        } else {
            d
        }
    });
    let bound = 0.5 * 3f32.sqrt() * h * (1.0 + HALF_DIAGONAL_SLACK);
    let (mut worst, mut sum, mut inside) = (0.0f32, 0.0f64, 0);
    for (p, &want) in points.iter().zip(&exact) {
        let got = g.sample(*p).0;
        let err = (got - want as f32).abs();
        assert!(err <= bound, "{p}: sampled {got}, exact {want}, error {:.3} voxels", err / h);
        worst = worst.max(err);
        sum += err as f64;
        inside += (want < 0.0) as usize;
    }
    // Both sides of the surface were sampled.
    assert!(inside > NEAR_POINTS / 5 && inside < NEAR_POINTS * 4 / 5, "{inside} of {NEAR_POINTS} inside");
    let mean = (sum / NEAR_POINTS as f64) as f32 / h;
    eprintln!(
        "nut at {RESOLUTION}: {NEAR_POINTS} points ({inside} inside), mean error {mean:.4} voxels, worst {:.4} voxels",
        worst / h
    );
    assert!(mean <= MEAN_ERROR_MAX_VOXELS, "mean error {mean} voxels");
}

/// The analytic bolt SDF (`SdfShape::Thread`) against the exact distance to our generated bolt mesh, near
/// the threads: they differ by the mesh's chord error (the helix sampled on 192 columns per turn lies up to
/// r (1 - cos(pi / 192)) = 1.1 um inside the true surface for M16) plus the analytic field's lead-angle
/// overestimate (at most 0.1% of the distance, 0.2 um at the 0.2 mm band).
const ANALYTIC_VS_MESH_TOL: f64 = 1.5e-6;
const ANALYTIC_POINTS: usize = 400;
const ANALYTIC_BAND: f32 = 0.2e-3;

#[test]
fn analytic_bolt_sdf_matches_the_bolt_mesh_near_the_thread() {
    let nb = parts();
    let mesh = &nb.bolt.mesh;
    let sdf = nb.bolt_sdf();
    let reference = Reference::new(mesh, 2e-4);
    let mut rng = Lcg(11);
    // Points near the threaded surface, away from the clip planes (head face, tip) by a millimetre.
    let (z0, z1) = (sdf.z_lo + 1e-3, sdf.z_hi - 1e-3);
    let mut points = Vec::new();
    while points.len() < ANALYTIC_POINTS {
        let tri = mesh.triangle((rng.next_f32() * mesh.triangle_count() as f32) as usize);
        let (mut s, mut t) = (rng.next_f32(), rng.next_f32());
        if s + t > 1.0 {
            (s, t) = (1.0 - s, 1.0 - t);
        }
        let on = tri[0] + s * (tri[1] - tri[0]) + t * (tri[2] - tri[0]);
        if on.z < z0 || on.z > z1 {
            continue;
        }
        let dir = Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, rng.next_f32() - 0.5).normalize_or(Vec3::Z);
        points.push(on + dir * (ANALYTIC_BAND * rng.next_f32()));
    }
    let exact: Vec<f64> = par_map(points.len(), |i| {
        let p = points[i].as_dvec3();
        let d = reference.distance(p);
        if reference.inside(p) {
            -d
        } else {
            d
        }
    });
    let mut worst = 0.0f64;
    for (p, &want) in points.iter().zip(&exact) {
        let got = sdf.sample(*p).0 as f64;
        let err = (got - want).abs();
        assert!(err <= ANALYTIC_VS_MESH_TOL, "{p}: analytic {got}, mesh {want}, error {err}");
        worst = worst.max(err);
    }
    eprintln!("analytic bolt SDF vs mesh: {ANALYTIC_POINTS} points, worst {:.3} um", worst * 1e6);
}

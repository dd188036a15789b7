//! Integration tests of the SDF baker and its on-disk cache on Factory's M16 nut and bolt meshes.
//!
//! The reference everywhere is parry3d's exact point projection on the (watertight) mesh with its
//! angle-weighted pseudo-normals for the sign, an implementation independent of the baker's ray votes.

use factory_engine::mesh::TriMesh;
use factory_engine::sdf::bake::{bake, layout, BakeParams};
use factory_engine::sdf::cache::{self, SdfCache};
use factory_engine::sdf::SdfGrid;
use factory_engine::EngineError;
use glam::Vec3;
use parry3d::query::{PointQuery, Ray, RayCast};
use parry3d::shape::TriMesh as ParryMesh;
use rayon::prelude::*;
use std::io::BufRead;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};
use std::time::{Duration, Instant};

/// Factory's meshes are not part of this repository: the tests read them from the folder named by
/// `FACTORY_PEER_ASSETS` (Factory's asset tree, with the meshes under `factory/mesh/`) and skip, saying so,
/// when it is unset. `.ci/run` sets it where the CI machine provides the folder.
const PEER_ASSETS_VAR: &str = "FACTORY_PEER_ASSETS";
const NUT: &str = "factory_nut_m16_tight_subdiv_3x.obj";
const BOLT: &str = "factory_bolt_m16_tight.obj";

/// The path of one of Factory's meshes, or `None` (after saying why the test is skipped) when
/// `FACTORY_PEER_ASSETS` is unset.
fn peer_mesh(name: &str) -> Option<PathBuf> {
    match std::env::var_os(PEER_ASSETS_VAR) {
        Some(dir) => Some(Path::new(&dir).join("factory/mesh").join(name)),
        None => {
            eprintln!(
                "skipped: {PEER_ASSETS_VAR} is not set (the folder holding Factory's meshes under factory/mesh/)"
            );
            None
        }
    }
}

/// Returns from the test, skipped, when Factory's meshes are not available.
macro_rules! require_peer_assets {
    () => {
        if peer_mesh(NUT).is_none() {
            return;
        }
    };
}

/// Resolution of the accuracy and gradient tests (nut: about 119 x 136 x 69 samples).
const ACCURACY_RESOLUTION: u32 = 128;
/// Resolution of the every-grid-point sign tests (fast enough to check every sample against parry).
const SIGN_RESOLUTION: u32 = 80;
/// Samples closer than this to the surface [m] have no meaningful sign (f32 rounding of the closest
/// point at 3 cm coordinates is ~2e-9 m); the sign tests skip them.
const SURFACE_EPS: f32 = 1e-6;

/// The OBJ as written, with every vertex repeated per face (11140 boundary edges for the nut).
fn load_raw(name: &str) -> TriMesh {
    let path = peer_mesh(name).expect("FACTORY_PEER_ASSETS checked by require_peer_assets!");
    TriMesh::load_obj(&path).unwrap_or_else(|e| panic!("{e}"))
}

/// Welds coincident vertices (the OBJ writes coordinates to 1e-6 m, so 1e-9 m merges exact duplicates only).
fn load(name: &str) -> TriMesh {
    load_raw(name).weld(1e-9)
}

fn nut() -> &'static TriMesh {
    static M: OnceLock<TriMesh> = OnceLock::new();
    M.get_or_init(|| load(NUT))
}

fn bolt() -> &'static TriMesh {
    static M: OnceLock<TriMesh> = OnceLock::new();
    M.get_or_init(|| load(BOLT))
}

fn params(resolution: u32) -> BakeParams {
    BakeParams { resolution, ..Default::default() }
}

/// The nut baked at [`ACCURACY_RESOLUTION`], shared by the accuracy and gradient tests.
fn nut_fine() -> &'static SdfGrid {
    static G: OnceLock<SdfGrid> = OnceLock::new();
    G.get_or_init(|| bake(nut(), &params(ACCURACY_RESOLUTION)).unwrap())
}

/// The nut baked at [`SIGN_RESOLUTION`], shared by the sign and open-mesh tests.
fn nut_coarse() -> &'static SdfGrid {
    static G: OnceLock<SdfGrid> = OnceLock::new();
    G.get_or_init(|| bake(nut(), &params(SIGN_RESOLUTION)).unwrap())
}

/// Exact signed distance: parry's closest point through its BVH for the magnitude, and for the sign a
/// majority of three ray-parity counts along fixed generic (non-axis) directions, using parry's own BVH
/// and ray-triangle test: independent of the baker's axis-aligned, perturbed scanlines. (Parry's
/// pseudo-normal sign would be the natural reference, but the nut has two zero-width seams along its hex
/// edges where the welded mesh still has 108 boundary edges, and pseudo-normals are wrong there.)
struct Exact(ParryMesh);

/// Generic ray directions for the inside test (normalised on use).
const RAY_DIRS: [[f32; 3]; 3] = [[0.5377, 0.8622, 0.3188], [-0.4336, 0.3426, 0.8339], [0.7254, -0.6303, 0.2769]];

impl Exact {
    fn new(mesh: &TriMesh) -> Self {
        let topo = mesh.topology();
        assert!(topo.non_manifold_edges == 0 && topo.misoriented_edges == 0, "{topo:?}");
        Exact(ParryMesh::new(mesh.positions.clone(), mesh.triangles.clone()).unwrap())
    }
    /// Distance [m] and closest surface point.
    fn closest(&self, p: Vec3) -> (f32, Vec3) {
        let proj = self.0.project_local_point(p, false);
        ((p - proj.point).length(), proj.point)
    }
    fn crossings(&self, p: Vec3, dir: Vec3) -> usize {
        let ray = Ray::new(p, dir);
        self.0
            .bvh()
            .leaves(|node| node.aabb().intersects_local_ray(&ray, f32::MAX))
            .filter(|&t| self.0.triangle(t).intersects_local_ray(&ray, f32::MAX))
            .count()
    }
    fn inside(&self, p: Vec3) -> bool {
        RAY_DIRS.iter().filter(|d| self.crossings(p, Vec3::from_array(**d).normalize()) % 2 == 1).count() >= 2
    }
    /// Signed distance [m] and closest surface point.
    fn query(&self, p: Vec3) -> (f32, Vec3) {
        let (d, q) = self.closest(p);
        (if self.inside(p) { -d } else { d }, q)
    }
    fn signed(&self, p: Vec3) -> f32 {
        self.query(p).0
    }
}

fn exact_nut() -> &'static Exact {
    static E: OnceLock<Exact> = OnceLock::new();
    E.get_or_init(|| Exact::new(nut()))
}

/// A tiny 64-bit LCG (Knuth's MMIX constants); uniform f32 in [0, 1) from its top 24 bits.
struct Lcg(u64);

impl Lcg {
    fn next_f32(&mut self) -> f32 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
    fn in_box(&mut self, lo: Vec3, hi: Vec3) -> Vec3 {
        lo + (hi - lo) * Vec3::new(self.next_f32(), self.next_f32(), self.next_f32())
    }
}

/// Collects log records so tests can check the warnings (one global logger per test binary).
struct Recorder(Mutex<Vec<String>>);

impl log::Log for Recorder {
    fn enabled(&self, _: &log::Metadata) -> bool {
        true
    }
    fn log(&self, record: &log::Record) {
        let line = format!("{} {}", record.level(), record.args());
        eprintln!("{line}");
        self.0.lock().unwrap().push(line);
    }
    fn flush(&self) {}
}

fn recorder() -> &'static Recorder {
    static R: OnceLock<&'static Recorder> = OnceLock::new();
    R.get_or_init(|| {
        let r: &'static Recorder = Box::leak(Box::new(Recorder(Mutex::new(Vec::new()))));
        log::set_logger(r).expect("no other logger in this test binary");
        log::set_max_level(log::LevelFilter::Debug);
        r
    })
}

/// Every sample's grid position, in index order.
fn grid_points(g: &SdfGrid) -> Vec<Vec3> {
    let mut pts = Vec::with_capacity(g.values.len());
    for k in 0..g.dims.z {
        for j in 0..g.dims.y {
            for i in 0..g.dims.x {
                pts.push(g.point(i, j, k));
            }
        }
    }
    pts
}

/// Trilinear interpolation of the exact grid values of any 1-Lipschitz function f errs by at most
/// sum_c w_c |c - p| <= sqrt(sum_c w_c |c - p|^2) (Jensen) = sqrt(sum_axes f_a (1 - f_a)) <= sqrt(3)/2 of a
/// voxel: the bound holds everywhere, edges and corners included, so no point is excluded. This slack
/// [voxels] only covers f32 rounding.
const INTERP_ROUNDING_VOXELS: f32 = 1e-3;
/// Accuracy samples are drawn within this many voxels of the surface.
const NEAR_BAND_VOXELS: f32 = 3.0;
/// Grid values are the exact distances; parry's own f32 rounding differs by ~1e-9 m at 3 cm.
const GRID_VALUE_TOL: f32 = 1e-7;
/// On a smooth surface trilinear error is second order; the mean over the band must be far below the
/// worst-case bound (measured: about 0.015 voxel).
const MEAN_ERROR_MAX_VOXELS: f32 = 0.05;

#[test]
fn distance_accuracy_nut() {
    require_peer_assets!();
    let g = nut_fine();
    let exact = exact_nut();
    let h = g.spacing;
    let mut rng = Lcg(1);
    // Grid values themselves are the exact signed distances.
    for _ in 0..2000 {
        let (i, j, k) = (
            (rng.next_f32() * g.dims.x as f32) as u32,
            (rng.next_f32() * g.dims.y as f32) as u32,
            (rng.next_f32() * g.dims.z as f32) as u32,
        );
        let p = g.point(i, j, k);
        let (got, want) = (g.values[g.index(i, j, k)], exact.signed(p));
        assert!(
            (got - want).abs() <= GRID_VALUE_TOL || want.abs() < SURFACE_EPS && got.abs() < SURFACE_EPS,
            "sample ({i},{j},{k}) {p}: {got} vs exact {want}"
        );
    }
    let bound = (0.5 * 3f32.sqrt() + INTERP_ROUNDING_VOXELS) * h;
    let (lo, hi) = (g.origin, g.max_corner());
    let (mut n, mut sum, mut worst) = (0usize, 0.0f64, 0.0f32);
    for _ in 0..200_000 {
        let p = rng.in_box(lo, hi);
        let d = exact.closest(p).0;
        if d >= NEAR_BAND_VOXELS * h {
            continue;
        }
        let want = if exact.inside(p) { -d } else { d };
        let got = g.sample(p).0;
        let err = (got - want).abs();
        assert!(err <= bound, "{p}: sampled {got}, exact {want}, error {:.3} voxels", err / h);
        sum += err as f64;
        worst = worst.max(err);
        n += 1;
        if n == 4000 {
            break;
        }
    }
    assert_eq!(n, 4000, "too few samples near the surface");
    let mean = (sum / n as f64) as f32;
    eprintln!(
        "nut at {ACCURACY_RESOLUTION}: {n} points, mean error {:.4} voxels, worst {:.4} voxels",
        mean / h,
        worst / h
    );
    assert!(mean <= MEAN_ERROR_MAX_VOXELS * h, "mean error {} voxels", mean / h);
}

/// Gradient samples lie within this many voxels of the surface.
const GRADIENT_BAND_VOXELS: f32 = 1.5;
/// ...but not closer than this [voxels], where the exact outward direction is ill-conditioned.
const GRADIENT_MIN_VOXELS: f32 = 0.05;
/// A point is "away from edges" when the exact SDF is planar over its cell: every corner's exact value is
/// within this many voxels of the plane through p with p's exact normal. (Trilinear interpolation
/// reproduces a linear field exactly, so there the gradient must be the normal.)
const PLANARITY_TOL_VOXELS: f32 = 0.01;
/// | |grad| - 1 | bound.
const GRADIENT_LENGTH_TOL: f32 = 0.1;
/// Minimum cosine between the sampled gradient and the exact outward direction (about 8 degrees).
const GRADIENT_MIN_COS: f32 = 0.99;
/// The filter must leave at least this many points, so the test cannot pass vacuously.
const GRADIENT_MIN_POINTS: usize = 500;

#[test]
fn gradient_near_surface_nut() {
    require_peer_assets!();
    let g = nut_fine();
    let exact = exact_nut();
    let h = g.spacing;
    let mut rng = Lcg(7);
    let (mut checked, mut worst_len, mut worst_cos) = (0usize, 0.0f32, 1.0f32);
    for _ in 0..100_000 {
        let p = rng.in_box(g.origin, g.max_corner());
        let (d, q) = exact.closest(p);
        if d > GRADIENT_BAND_VOXELS * h || d < GRADIENT_MIN_VOXELS * h {
            continue;
        }
        let d = if exact.inside(p) { -d } else { d };
        let n = (p - q).normalize() * d.signum();
        let cell = ((p - g.origin) / h).floor();
        let planar = (0..8).all(|c| {
            let corner = g.origin + h * (cell + Vec3::new((c & 1) as f32, ((c >> 1) & 1) as f32, (c >> 2) as f32));
            (exact.signed(corner) - (d + n.dot(corner - p))).abs() <= PLANARITY_TOL_VOXELS * h
        });
        if !planar {
            continue;
        }
        let grad = g.sample(p).1;
        let (len, cos) = (grad.length(), grad.normalize().dot(n));
        assert!((len - 1.0).abs() <= GRADIENT_LENGTH_TOL, "{p}: |grad| = {len}");
        assert!(cos >= GRADIENT_MIN_COS, "{p}: grad {grad} vs outward {n} (cos {cos})");
        worst_len = worst_len.max((len - 1.0).abs());
        worst_cos = worst_cos.min(cos);
        checked += 1;
        if checked == 2000 {
            break;
        }
    }
    eprintln!("gradient: {checked} points, worst | |g| - 1 | = {worst_len:.4}, worst cos = {worst_cos:.5}");
    assert!(checked >= GRADIENT_MIN_POINTS, "only {checked} points passed the planarity filter");
}

/// Checks every sample's sign against the reference; returns how many samples were compared.
fn assert_signs_everywhere(name: &str, g: &SdfGrid, exact: &Exact) -> usize {
    let pts = grid_points(g);
    let reference: Vec<f32> = pts
        .par_iter()
        .map(|&p| {
            let d = exact.closest(p).0;
            if d <= SURFACE_EPS {
                0.0
            } else if exact.inside(p) {
                -d
            } else {
                d
            }
        })
        .collect();
    let mut compared = 0;
    let mut wrong = Vec::new();
    for (idx, (&want, &got)) in reference.iter().zip(&g.values).enumerate() {
        if want.abs() <= SURFACE_EPS {
            continue;
        }
        compared += 1;
        if (want < 0.0) != (got < 0.0) {
            wrong.push((pts[idx], got, want));
        }
    }
    assert!(
        wrong.is_empty(),
        "{name}: {} of {compared} samples have the wrong sign, e.g. {:?}",
        wrong.len(),
        &wrong[..wrong.len().min(5)]
    );
    // The field must actually have both signs (an all-outside grid would trivially match nothing).
    assert!(g.values.iter().any(|&v| v < -SURFACE_EPS) && g.values.iter().any(|&v| v > SURFACE_EPS));
    compared
}

#[test]
fn sign_at_every_grid_point_nut_and_bolt() {
    require_peer_assets!();
    let n = assert_signs_everywhere("nut", nut_coarse(), exact_nut());
    let bolt_grid = bake(bolt(), &params(SIGN_RESOLUTION)).unwrap();
    let m = assert_signs_everywhere("bolt", &bolt_grid, &Exact::new(bolt()));
    // The OBJ as loaded, before welding (every edge a boundary edge), bakes to the same grid.
    let raw = bake(&load_raw(NUT), &params(SIGN_RESOLUTION)).unwrap();
    assert_eq!(&raw, nut_coarse());
    eprintln!("signs: nut {n} samples, bolt {m} samples, all right");
}

/// Fraction of the nut's triangles removed to open it.
const OPEN_DROP_FRACTION: f32 = 0.01;
/// Samples closer than this many voxels to a removed triangle are excluded from the comparison.
const OPEN_EXCLUSION_VOXELS: f32 = 2.0;

#[test]
fn open_mesh_keeps_signs() {
    require_peer_assets!();
    let rec = recorder();
    let closed = nut();
    let mut rng = Lcg(12345);
    let (mut kept, mut removed) = (Vec::new(), Vec::new());
    for &t in &closed.triangles {
        if rng.next_f32() < OPEN_DROP_FRACTION {
            removed.push(t);
        } else {
            kept.push(t);
        }
    }
    let open = TriMesh::new(closed.positions.clone(), kept);
    let topo = open.topology();
    assert!(topo.boundary_edges > 0, "{topo:?}");
    let g_open = bake(&open, &params(SIGN_RESOLUTION)).unwrap();
    let warned = rec.0.lock().unwrap().iter().any(|l| {
        l.starts_with("WARN")
            && l.contains("not watertight")
            && l.contains(&format!("{} boundary edges", topo.boundary_edges))
    });
    assert!(warned, "no warning naming the {} boundary edges", topo.boundary_edges);

    let g_closed = nut_coarse();
    assert_eq!((g_open.dims, g_open.origin, g_open.spacing), (g_closed.dims, g_closed.origin, g_closed.spacing));
    let holes = ParryMesh::new(closed.positions.clone(), removed.clone()).unwrap();
    let pts = grid_points(g_closed);
    let near_hole: Vec<bool> = pts
        .par_iter()
        .map(|&p| holes.distance_to_local_point(p, false) <= OPEN_EXCLUSION_VOXELS * g_closed.spacing)
        .collect();
    let (mut compared, mut wrong, mut wrong_near) = (0usize, Vec::new(), 0usize);
    for idx in 0..pts.len() {
        let (c, o) = (g_closed.values[idx], g_open.values[idx]);
        if c.abs() <= SURFACE_EPS || (c < 0.0) == (o < 0.0) {
            compared += !near_hole[idx] as usize;
            continue;
        }
        if near_hole[idx] {
            wrong_near += 1;
        } else {
            compared += 1;
            wrong.push((pts[idx], c, o));
        }
    }
    eprintln!(
        "open nut: {} of {} triangles removed, {} boundary edges; {compared} samples compared, {} wrong; {wrong_near} differ within {OPEN_EXCLUSION_VOXELS} voxels of a hole",
        removed.len(),
        closed.triangles.len(),
        topo.boundary_edges,
        wrong.len()
    );
    assert!(
        wrong.is_empty(),
        "{} samples away from the holes changed sign, e.g. {:?}",
        wrong.len(),
        &wrong[..wrong.len().min(5)]
    );
    assert!(compared > pts.len() / 2);
}

/// A refusal does no work proportional to the grid; generous for a loaded 2-core CI machine.
const REFUSAL_TIME_LIMIT: Duration = Duration::from_millis(100);

#[test]
fn oversized_bake_is_refused_before_allocating() {
    require_peer_assets!();
    let mesh = nut();
    let start = Instant::now();
    let e = bake(mesh, &params(100_000)).unwrap_err();
    let elapsed = start.elapsed();
    let EngineError::TooLarge { what, needed_bytes, limit_bytes, hint } = &e else { panic!("{e}") };
    assert!(what.contains("resolution 100000"), "{e}");
    assert!(*needed_bytes > *limit_bytes && *limit_bytes == BakeParams::default().max_bytes, "{e}");
    assert!(hint.contains("resolution"), "{e}");
    assert!(elapsed < REFUSAL_TIME_LIMIT, "refusal took {elapsed:?}");
    // More samples than u32 indices can address is refused even without a memory limit.
    let e = bake(mesh, &BakeParams { resolution: 3000, margin: 0.0, max_bytes: u64::MAX }).unwrap_err();
    assert!(matches!(e, EngineError::TooLarge { .. }), "{e}");

    // The hint is exact: its resolution fits the limit, one more does not, and it bakes.
    let max_bytes = 4 << 20;
    let e = bake(mesh, &BakeParams { resolution: 96, margin: 0.0, max_bytes }).unwrap_err();
    let EngineError::TooLarge { hint, .. } = &e else { panic!("{e}") };
    let fit: u32 = hint
        .split_whitespace()
        .nth(1)
        .and_then(|w| w.parse().ok())
        .unwrap_or_else(|| panic!("no resolution in {hint:?}"));
    assert!((2..96).contains(&fit), "{hint}");
    let g = bake(mesh, &BakeParams { resolution: fit, margin: 0.0, max_bytes }).unwrap();
    assert!(g.values.len() as u64 * factory_engine::sdf::bake::BAKE_BYTES_PER_SAMPLE <= max_bytes);
    assert!(matches!(
        layout(mesh, &BakeParams { resolution: fit + 1, margin: 0.0, max_bytes }),
        Err(EngineError::TooLarge { .. })
    ));
}

/// A unique, empty temporary directory for one test.
fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("factory-sdf-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn cache_hits_and_rebakes_corrupt_entries() {
    require_peer_assets!();
    let dir = temp_dir("cache");
    let cache = SdfCache::new(&dir);
    let mesh = bolt();
    let p = params(40);
    let path = cache.entry_path(mesh, &p);
    assert!(!path.exists());
    let baked = cache.get_or_bake(mesh, &p).unwrap();
    assert!(path.exists());
    assert_eq!(cache.entries().unwrap(), vec![path.clone()]);
    assert_eq!(cache::load(&path).unwrap(), baked);
    assert_eq!(cache.get_or_bake(mesh, &p).unwrap(), baked);

    // A hit really comes from the file: replace the entry with a different valid grid of the same layout.
    let mut other = baked.clone();
    other.values.iter_mut().for_each(|v| *v += 1e-3);
    cache::save(&path, &other).unwrap();
    assert_eq!(cache.get_or_bake(mesh, &p).unwrap(), other);

    // Corruptions are caught, never returned, and the entry is rewritten with a fresh bake.
    let len = std::fs::metadata(&path).unwrap().len();
    let corruptions: [(&str, Box<dyn Fn(&Path)>); 3] = [
        (
            "flipped payload byte",
            Box::new(|f: &Path| {
                let mut b = std::fs::read(f).unwrap();
                let i = b.len() / 2;
                b[i] ^= 0x01;
                std::fs::write(f, b).unwrap();
            }),
        ),
        (
            "truncated",
            Box::new(|f: &Path| std::fs::OpenOptions::new().write(true).open(f).unwrap().set_len(len / 2).unwrap()),
        ),
        (
            "garbage header",
            Box::new(|f: &Path| {
                let mut b = std::fs::read(f).unwrap();
                b[..8].copy_from_slice(b"GARBAGE!");
                std::fs::write(f, b).unwrap();
            }),
        ),
    ];
    for (what, corrupt) in &corruptions {
        cache::save(&path, &other).unwrap();
        corrupt(&path);
        assert!(cache::load(&path).is_err(), "{what}: corrupt file loaded");
        assert_eq!(cache.get_or_bake(mesh, &p).unwrap(), baked, "{what}: not rebaked");
        assert_eq!(cache::load(&path).unwrap(), baked, "{what}: entry not rewritten");
    }
    // Other parameters, other entry.
    assert_ne!(cache.entry_path(mesh, &params(41)), path);
    assert_ne!(cache.entry_path(mesh, &BakeParams { margin: 1e-3, ..p }), path);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Environment variable telling [`killed_bake_child`] which cache directory to fill.
const KILL_DIR_ENV: &str = "FACTORY_SDF_KILL_TEST_DIR";
/// The child's bakes: increasing resolutions, each a new entry.
const CHILD_RESOLUTIONS: std::ops::Range<u32> = 40..400;
const CHILD_STEP: usize = 6;
/// How long the parent lets the child run after its first entry is written.
const KILL_DELAY: Duration = Duration::from_millis(700);

/// Run by [`killed_bake_leaves_no_corrupt_cache`] as a child process: bakes ever larger grids of the nut
/// into the cache until killed.
#[test]
#[ignore = "child process of killed_bake_leaves_no_corrupt_cache"]
fn killed_bake_child() {
    let Some(dir) = std::env::var_os(KILL_DIR_ENV) else { return };
    let cache = SdfCache::new(PathBuf::from(dir));
    for r in CHILD_RESOLUTIONS.step_by(CHILD_STEP) {
        cache.get_or_bake(nut(), &params(r)).unwrap();
        println!("WROTE {r}");
        use std::io::Write;
        std::io::stdout().flush().unwrap();
    }
}

#[test]
fn killed_bake_leaves_no_corrupt_cache() {
    require_peer_assets!();
    let dir = temp_dir("killed");
    let mut child = std::process::Command::new(std::env::current_exe().unwrap())
        .args(["--exact", "killed_bake_child", "--ignored", "--nocapture", "--test-threads", "1"])
        .env(KILL_DIR_ENV, &dir)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let stdout = child.stdout.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in std::io::BufReader::new(stdout).lines().map_while(Result::ok) {
            if line.starts_with("WROTE") && tx.send(line).is_err() {
                break;
            }
        }
    });
    let first = rx.recv_timeout(Duration::from_secs(60));
    std::thread::sleep(KILL_DELAY);
    child.kill().unwrap();
    let status = child.wait().unwrap();
    first.expect("the child wrote no entry within 60 s");
    assert!(!status.success(), "the child finished all its bakes before being killed: make them larger");

    let cache = SdfCache::new(&dir);
    let mesh = nut();
    let entries = cache.entries().unwrap();
    assert!(!entries.is_empty());
    let mut done = Vec::new();
    for file in std::fs::read_dir(&dir).unwrap() {
        let path = file.unwrap().path();
        let name = path.file_name().unwrap().to_str().unwrap().to_owned();
        if SdfCache::is_entry_name(&name) {
            let grid = cache::load(&path).unwrap_or_else(|e| panic!("a killed bake left a corrupt entry: {e}"));
            let r = CHILD_RESOLUTIONS
                .step_by(CHILD_STEP)
                .find(|&r| cache.entry_path(mesh, &params(r)) == path)
                .expect("entry of an unknown bake");
            let l = layout(mesh, &params(r)).unwrap();
            assert_eq!((grid.dims, grid.origin, grid.spacing), (l.dims, l.origin, l.spacing));
            done.push(r);
        } else {
            // Anything else is an interrupted write's temporary file, which is not an entry.
            assert!(name.starts_with('.') && name.ends_with(".tmp"), "unexpected file {name}");
            assert!(!entries.contains(&path));
        }
    }
    eprintln!("killed child after bakes at resolutions {done:?}");
    // The next bake the child had started (or the first, if none finished) succeeds from scratch, and the
    // entries it did finish are hits.
    let next = CHILD_RESOLUTIONS.step_by(CHILD_STEP).find(|r| !done.contains(r)).unwrap();
    let fresh = cache.get_or_bake(mesh, &params(next)).unwrap();
    assert_eq!(cache::load(&cache.entry_path(mesh, &params(next))).unwrap(), fresh);
    let hit = cache.get_or_bake(mesh, &params(done[0])).unwrap();
    assert_eq!(hit, cache::load(&cache.entry_path(mesh, &params(done[0]))).unwrap());
    std::fs::remove_dir_all(&dir).unwrap();
}

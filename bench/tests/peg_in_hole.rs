//! Peg-in-hole dynamics (issue 4, DESIGN section 6: "a peg drops into a hole with its ISO clearance") on our
//! generated 4 mm tight round peg and hole (factory-assets; diametral clearance 0.104 mm, Table VII), on the GPU
//! solver with the CPU reference `step_cpu` run on the same scene (contacts from the GPU pipeline every frame
//! in both cases; the GPU path submits contacts + solver as one command buffer per frame).
//!
//! Scene: the hole block (25 x 25 mm, 8.99 mm tall, through bore 4.1 mm) is fixed on a table (the plane
//! z = 0), so the bore's bottom is the table: a peg that goes all the way down rests on the table inside the
//! bore. Pairs by Factory's rules (`contact::roles::pair_spec`): peg vs hole, the peg's exact round field
//! (`ShapeGeometry::Revolved`, which takes the SDF role) against the hole's 1024 triangles; peg vs table, the
//! peg's triangles against the exact half-space. Solver at Factory's task settings (DESIGN 4.4: dt = 1/60 s,
//! 2 substeps, 16 position iterations) with 8 passes per patch (PATCH_ITERS).

use factory_assets::{peg_hole, Fit, PegHole, PegHoleOptions, PegSize};
use factory_engine::contact::roles::{pair_spec, ShapeDesc, ShapeGeometry};
use factory_engine::contact::{ContactConfig, ContactModel, ContactPipeline, TransformGpu};
use factory_engine::gpu::GpuContext;
use factory_engine::sdf::cache::SdfCache;
use factory_engine::solver::gpu::GpuSolver;
use factory_engine::solver::{step_cpu_with_pipeline, BodyModel, BodyState, Control, SolverConfig, WarmStart};
use glam::{Quat, Vec3};
use std::sync::{Arc, OnceLock};

const G: f32 = 9.81;
/// Steel on steel, both pairs (unitless).
const FRICTION: f32 = 0.5;
/// Contact offset of the peg-hole pair [m]: the peg moves sideways by far less in a frame.
const HOLE_OFFSET: f32 = 1e-3;
/// Contact offset of the peg-table pair [m]: covers the peg's fall in a frame (~7 mm at the bottom of the
/// 10 mm drop), so the table contact is there, speculatively, before the impact.
const TABLE_OFFSET: f32 = 0.01;
/// The peg starts with its bottom this far above the block's top [m].
const START_GAP: f32 = 1e-3;

/// Aligned drop: the resting peg's bottom is within this of the table [m] (the solver's resting
/// penetration is micrometres; see the box tests in engine/tests).
const BOTTOM_TOL: f32 = 0.02e-3;
/// Aligned drop: the peg's axis stays within the radial clearance of the bore's axis, plus this [m] for the
/// sampled peg SDF (256 samples over 50 mm: 0.2 mm voxels; trilinear error on a 2 mm cylinder ~h^2/(8 r)
/// = 2.5 um, and the 16-bit quantum is 0.8 um).
const SDF_SLACK: f32 = 5e-6;
/// Aligned drop: at rest means a median frame-end speed below this [m/s] over the second second ...
const REST_SPEED: f32 = 1e-3;
/// ... and a centre of mass that moves less than this [m] in that second.
const REST_DRIFT: f32 = 0.05e-3;
/// Gauss-Seidel passes per contact patch and sweep (`SolverConfig::patch_iters`; the solver's module doc):
/// at 1, the peg standing on the table rocks and topples (below).
const PATCH_ITERS: u32 = 8;
/// Standing on the table: the peg's axis stays within this of vertical [deg] (tipping over starts at
/// atan(1.5 mm bottom radius / 25 mm COM height) = 3.4 deg).
const STANDING_TILT_DEG: f32 = 1.0;

/// Tilt of the jammed peg [deg] and the push.
const JAM_TILT_DEG: f32 = 6.0;
/// The push: there is no external-force API yet, so the peg is pushed by a gravity of 3 g (a constant force of
/// twice its weight along -z through its centre of mass, on top of its weight), starting at rest.
const PUSH_GRAVITY: f32 = 3.0 * G;
/// A tilted peg can enter a bore of diameter D only to the depth where its diameter's projection meets the
/// wall: (D - d cos t) / sin t, 1.2 mm at 6 degrees for the 4 mm pair (+ the 0.5 mm chamfer). Jammed: its
/// bottom stays within this of the entrance [m], a third of the 9 mm bore, far above the table.
const JAM_DEPTH_MAX: f32 = 3e-3;

fn parts() -> &'static PegHole {
    static P: OnceLock<PegHole> = OnceLock::new();
    P.get_or_init(|| peg_hole(PegSize::D4, Fit::Tight, &PegHoleOptions::default()).unwrap())
}

/// The peg as an exact solid of revolution (its mesh is queried against the table; its exact field is the
/// SDF against the hole, where a grid baked from its 128-sided mesh would spin it: engine sdf::revolved).
fn exact_peg() -> ShapeGeometry {
    let ph = parts();
    ShapeGeometry::Revolved { mesh: Arc::new(ph.peg.mesh.clone()), sdf: ph.peg_sdf() }
}

fn scene() -> ContactModel {
    let ph = parts();
    let cache = SdfCache::new(SdfCache::default_dir());
    let res = factory_assets::peg_hole::PEG_HOLE_SDF_RESOLUTION;
    let tagged = |m: &factory_engine::mesh::TriMesh| ShapeGeometry::Mesh {
        mesh: Arc::new(m.clone()),
        sdf_resolution: Some(res),
    };
    let peg = ShapeDesc::new(0, exact_peg());
    let hole = ShapeDesc::fixed((Vec3::ZERO, Quat::IDENTITY), tagged(&ph.hole.mesh));
    let table = ShapeDesc::fixed((Vec3::ZERO, Quat::IDENTITY), ShapeGeometry::Plane);
    let mut a = pair_spec(&peg, &hole, HOLE_OFFSET, &cache).unwrap();
    let mut b = pair_spec(&peg, &table, TABLE_OFFSET, &cache).unwrap();
    a.friction = FRICTION;
    b.friction = FRICTION;
    ContactModel { body_count: 1, pairs: vec![a, b] }
}

/// Solver settings of the peg scenes: Factory's task settings (DESIGN 4.4) with PATCH_ITERS passes per
/// patch and sweep.
fn solver_config() -> SolverConfig {
    SolverConfig { substeps: 2, pos_iters: 16, vel_iters: 1, patch_iters: PATCH_ITERS, ..Default::default() }
}

/// Runs the peg from `start` for `frames` under `gravity` [m/s^2]; returns the final state.
fn run(start: &BodyState, gravity: f32, frames: u32, on_gpu: bool) -> BodyState {
    run_in(&scene(), start, gravity, frames, on_gpu, |_| {})
}

/// Runs the peg in `model` from `start`; `each` sees the state after every frame (GPU: read back each frame).
fn run_in(
    model: &ContactModel,
    start: &BodyState,
    gravity: f32,
    frames: u32,
    on_gpu: bool,
    mut each: impl FnMut(&BodyState),
) -> BodyState {
    let gpu = GpuContext::global().unwrap();
    let pipe = ContactPipeline::new(gpu, model, 1, &ContactConfig::default()).unwrap();
    let mp = parts().peg.mass_properties;
    let mut bodies = BodyModel { gravity: Vec3::new(0.0, 0.0, -gravity), ..Default::default() };
    bodies.add_dynamic(mp.mass, mp.inertia, mp.com);
    let cfg = solver_config();
    let solver = GpuSolver::new(gpu, &pipe, &bodies, &cfg).unwrap();
    let mut state = start.clone();
    solver.write_state(gpu, &pipe, &state);
    let mut warm = WarmStart::default();
    for f in 0..frames {
        if on_gpu {
            solver.submit_frame(gpu, &pipe);
            let (s, ok) = solver.read_state(gpu, &pipe);
            assert!(ok[0], "GPU solver: world diverged (frame {f})");
            state = s;
        } else {
            assert!(
                step_cpu_with_pipeline(gpu, &pipe, &bodies, &mut state, &cfg, &Control::default(), &mut warm)[0],
                "CPU reference: world diverged (frame {f})"
            );
        }
        each(&state);
    }
    state
}

/// Regression: with plain Gauss-Seidel (patch_iters 1) a 4 mm peg set down upright on the table (50 mm tall,
/// on a 3 mm bottom face) rocked at 0.2-0.5 rad/s and toppled within 1.5 s (max tilt 101 deg over 3 s), on the
/// GPU solver and the CPU reference; at 8 passes per patch it stands (max tilt 0.11 deg).
#[test]
fn a_peg_standing_on_the_table_stays_upright() {
    let cache = SdfCache::new(SdfCache::default_dir());
    let peg = ShapeDesc::new(0, exact_peg());
    let table = ShapeDesc::fixed((Vec3::ZERO, Quat::IDENTITY), ShapeGeometry::Plane);
    let mut pair = pair_spec(&peg, &table, TABLE_OFFSET, &cache).unwrap();
    pair.friction = FRICTION;
    let model = ContactModel { body_count: 1, pairs: vec![pair] };
    // Set down 0.5 mm above the table, upright.
    let start = BodyState {
        body_q: vec![TransformGpu::new(Vec3::new(0.0, 0.0, 0.5e-3), Quat::IDENTITY)],
        body_qd: vec![[Vec3::ZERO; 2]],
    };
    for on_gpu in [true, false] {
        let mut worst = 0.0f32;
        let end = run_in(&model, &start, G, 180, on_gpu, |s| worst = worst.max(tilt_deg(s)));
        eprintln!(
            "{}: largest tilt over 3 s {worst:.3} deg, final speed {:.2e} m/s",
            who(on_gpu),
            end.body_qd[0][0].length()
        );
        assert!(worst < STANDING_TILT_DEG, "{}: tilted {worst} deg", who(on_gpu));
        assert!(axis_point(&end, 0.0).z.abs() < BOTTOM_TOL, "{}: bottom at {} m", who(on_gpu), axis_point(&end, 0.0).z);
    }
}

fn who(on_gpu: bool) -> &'static str {
    if on_gpu {
        "GPU solver"
    } else {
        "CPU reference"
    }
}

/// A point of the peg's axis at height `z` above its bottom (peg frame), in the world [m].
fn axis_point(s: &BodyState, z: f32) -> Vec3 {
    let t = s.body_q[0];
    Vec3::from_slice(&t.p[..3]) + Quat::from_array(t.q) * Vec3::new(0.0, 0.0, z)
}

fn tilt_deg(s: &BodyState) -> f32 {
    (Quat::from_array(s.body_q[0].q) * Vec3::Z).angle_between(Vec3::Z).to_degrees()
}

#[test]
fn an_aligned_peg_drops_into_the_hole_and_rests_on_the_bottom() {
    let ph = parts();
    let hole_top = factory_assets::peg_hole::HOLE_HEIGHT as f32;
    let radial_clearance = 0.5 * ph.clearance;
    // Upright, its axis 20 um off the bore's axis (within the 52 um radial clearance), bottom 1 mm above
    // the block.
    let start = BodyState {
        body_q: vec![TransformGpu::new(Vec3::new(20e-6, 0.0, hole_top + START_GAP), Quat::IDENTITY)],
        body_qd: vec![[Vec3::ZERO; 2]],
    };
    for on_gpu in [true, false] {
        let end = run(&start, G, 60, on_gpu);
        let bottom = axis_point(&end, 0.0);
        let at_entrance = axis_point(&end, hole_top - bottom.z);
        let speed = end.body_qd[0][0].length();
        eprintln!(
            "{}: after 1 s the peg's bottom is at z {:.4} mm, its axis {:.4} mm off the bore's axis at the bottom \
             and {:.4} mm at the entrance (radial clearance {:.4} mm), tilt {:.4} deg, speed {:.2e} m/s",
            who(on_gpu),
            bottom.z * 1e3,
            bottom.truncate().length() * 1e3,
            at_entrance.truncate().length() * 1e3,
            radial_clearance * 1e3,
            tilt_deg(&end),
            speed
        );
        assert!(bottom.z.abs() <= BOTTOM_TOL, "{}: bottom at z {} m", who(on_gpu), bottom.z);
        for (where_, p) in [("bottom", bottom), ("entrance", at_entrance)] {
            let off = p.truncate().length();
            assert!(off <= radial_clearance + SDF_SLACK, "{}: axis {off} m off at the {where_}", who(on_gpu));
        }
    }
}

/// The same drop must also come to rest: over its second second the peg's centre of mass moves less than
/// REST_DRIFT and its frame-end speed stays below REST_SPEED in most frames (median; the peg rocks in place
/// by hundredths of a degree, which shows as single frames up to ~1.5 mm/s at its centre of mass).
/// Regression: with patch_iters 1 it rattled at 6-20 mm/s, tilt wandering 0.15-0.5 deg, spin up to 1 rad/s.
#[test]
fn an_aligned_peg_dropped_into_the_hole_comes_to_rest() {
    let hole_top = factory_assets::peg_hole::HOLE_HEIGHT as f32;
    let start = BodyState {
        body_q: vec![TransformGpu::new(Vec3::new(20e-6, 0.0, hole_top + START_GAP), Quat::IDENTITY)],
        body_qd: vec![[Vec3::ZERO; 2]],
    };
    for on_gpu in [true, false] {
        let mut track: Vec<(Vec3, f32, f32)> = Vec::new();
        run_in(&scene(), &start, G, 120, on_gpu, |s| {
            let com = axis_point(s, 0.5 * factory_assets::peg_hole::PEG_LENGTH as f32);
            track.push((com, s.body_qd[0][0].length(), tilt_deg(s)));
        });
        let last = &track[60..];
        let drift = (last[last.len() - 1].0 - last[0].0).length();
        let mut speeds: Vec<f32> = last.iter().map(|t| t.1).collect();
        speeds.sort_by(f32::total_cmp);
        let (median, fastest) = (speeds[speeds.len() / 2], speeds[speeds.len() - 1]);
        let tilt = last.iter().map(|t| t.2).fold(0.0f32, f32::max);
        eprintln!(
            "{}: second second: centre of mass moved {:.4} mm, speed median {median:.2e} max {fastest:.2e} m/s, \
             largest tilt {tilt:.3} deg",
            who(on_gpu),
            drift * 1e3
        );
        assert!(drift < REST_DRIFT, "{}: moved {drift} m in the second second", who(on_gpu));
        assert!(median < REST_SPEED, "{}: median speed {median} m/s", who(on_gpu));
    }
}

#[test]
#[ignore = "the bore does not hold a tilted peg: started at rest 0.3 mm inside the mouth, 6 deg, pushed at 3 g, it is \
            levered out over the rim and ends lying on the block (tilt 90 deg; GPU solver and CPU reference). Found \
            2026-11-22: (1) one contact candidate per 9 mm bore triangle misses the peg's corner lower on the wall \
            (TriMesh::split_long_triangles at 0.5 mm finds it, 4.6 um away); (2) even started at the two-point \
            contact pose (1.48 mm deep) with the split bore and patch_iters 8, the push through the centre of mass, \
            2.6 mm outboard of the rim, tips it out within 4 frames (7 -> 45 deg) with the corner sliding up the \
            wall. Pushing along the peg's axis, as an insertion does, needs an external-force API (not built)."]
fn a_tilted_peg_pushed_into_the_hole_jams() {
    let hole_top = factory_assets::peg_hole::HOLE_HEIGHT as f32;
    let tilt = JAM_TILT_DEG.to_radians();
    // Tilted about y (its top leans towards +x), the centre of its bottom on the bore's axis 0.3 mm inside the
    // bore's mouth (the tilted peg clears both walls there: +x side 2.04 mm from the axis at the rim, bore
    // radius 2.05 mm); pushed down (see PUSH_GRAVITY).
    let start = BodyState {
        body_q: vec![TransformGpu::new(Vec3::new(0.0, 0.0, hole_top - 0.3e-3), Quat::from_rotation_y(tilt))],
        body_qd: vec![[Vec3::ZERO; 2]],
    };
    for on_gpu in [true, false] {
        // 1 s to jam, then 1 s more to see that it holds.
        let mid = run(&start, PUSH_GRAVITY, 60, on_gpu);
        let end = run(&mid, PUSH_GRAVITY, 60, on_gpu);
        let (b_mid, b_end) = (axis_point(&mid, 0.0), axis_point(&end, 0.0));
        eprintln!(
            "{}: pushed at 3 g, the bottom of the peg is {:.4} mm below the entrance after 1 s and {:.4} mm after \
             2 s (table: {:.3} mm below), tilt {:.3} deg, bottom {:.4} mm off the bore's axis, speed {:.2e} m/s",
            who(on_gpu),
            (hole_top - b_mid.z) * 1e3,
            (hole_top - b_end.z) * 1e3,
            hole_top * 1e3,
            tilt_deg(&end),
            b_end.truncate().length() * 1e3,
            end.body_qd[0][0].length()
        );
        assert!(
            hole_top - b_end.z <= JAM_DEPTH_MAX,
            "{}: the peg went {} m into the bore",
            who(on_gpu),
            hole_top - b_end.z
        );
        // Stuck in the bore's mouth, not fallen beside it, and not creeping down: the second second moved
        // it by less than what REST_SPEED allows.
        assert!(hole_top - b_end.z > 0.0, "{}: the peg's bottom is above the bore", who(on_gpu));
        assert!(b_end.truncate().length() < 0.5 * parts().hole_diameter, "{}: outside the bore", who(on_gpu));
        assert!(
            (b_mid - b_end).length() < REST_SPEED * 1.0,
            "{}: moved {} m in the second second",
            who(on_gpu),
            (b_mid - b_end).length()
        );
    }
}

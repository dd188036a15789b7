//! Many bodies in one world (`factory_engine::many_body`): the near-pair list and its colouring against the
//! CPU twin and against their definitions, the coloured Gauss-Seidel step against the CPU twin (a
//! sequential sweep in colour order), bitwise determinism, and a world over its capacity flagged and left
//! as it was while the other worlds step as if alone.

use factory_engine::contact::roles::{pair_spec, ShapeDesc, ShapeGeometry};
use factory_engine::contact::{ContactConfig, PairSpec, TransformGpu, NO_BODY};
use factory_engine::gpu::GpuContext;
use factory_engine::many_body::gpu::ManyBodyPipeline;
use factory_engine::many_body::{
    colour_pairs, ManyBodyConfig, ManyBodyCpu, ManyBodyFlat, ManyBodyModel, SleepConfig, FLAG_PAIRS,
};
use factory_engine::rng::SplitMix64;
use factory_engine::sdf::cache::SdfCache;
use factory_engine::solver::{BodyModel, BodyState, Control, SolverConfig};
use glam::{Mat3, Quat, Vec3};

/// Steel [kg/m^3].
const DENSITY: f32 = 7850.0;
/// Contact offset [m].
const OFFSET: f32 = 0.005;
/// Half extents of every box [m].
const H: Vec3 = Vec3::new(0.02, 0.015, 0.01);
/// GPU against the CPU twin, one frame from the same poses: the same sweeps in the same order, so they
/// differ by f32 rounding (fused multiply-adds, lavapipe's reassociation) only; but a box lying flat has
/// four equally deep corners, and which of them takes a patch slot is decided by that rounding, so a
/// frame can end a few micrometres apart (measured: at most 3.7e-6 m) [m], [m/s] ...
const PARITY_TOL: f32 = 1e-5;
/// ... (and velocities up to 1.8e-3 m/s) [m/s] ...
const PARITY_VEL_TOL: f32 = 5e-3;
/// ... while the median frame agrees to rounding [m]. Warm-started, each side keeps its own rows (they
/// cannot be re-synchronised), and one warm-start match at its distance threshold going the other way
/// carries other impulses for about a dozen frames: measured, 6.6e-6 m growing to 5.7e-5 m
/// and back over frames 47-58 of 60 (median 2e-8 m) [m].
const PARITY_MEDIAN_TOL: f32 = 2e-7;
const PARITY_WARM_TOL: f32 = 2e-4;

fn gpu() -> &'static GpuContext {
    GpuContext::global().unwrap()
}

fn box_model(n: u32, mu: f32) -> (ManyBodyModel, BodyModel) {
    let cache = SdfCache::new(SdfCache::default_dir());
    let a = ShapeDesc::new(0, ShapeGeometry::Box { half_extents: H });
    let b = ShapeDesc::new(1, ShapeGeometry::Box { half_extents: H });
    let table = ShapeDesc::fixed((Vec3::ZERO, Quat::IDENTITY), ShapeGeometry::Plane);
    let with_mu = |mut p: PairSpec| {
        p.friction = mu;
        p
    };
    let body_pair = with_mu(pair_spec(&a, &b, OFFSET, &cache).unwrap());
    let ground = with_mu(pair_spec(&a, &table, OFFSET, &cache).unwrap());
    assert_eq!(ground.body_b, NO_BODY, "the table is the SDF shape of its pair");
    let mut bodies = BodyModel { gravity: Vec3::new(0.0, 0.0, -9.81), ..Default::default() };
    let mass = DENSITY * 8.0 * H.x * H.y * H.z;
    let inertia = Mat3::from_diagonal(
        Vec3::new(H.y * H.y + H.z * H.z, H.x * H.x + H.z * H.z, H.x * H.x + H.y * H.y) * mass / 3.0,
    );
    for _ in 0..n {
        bodies.add_dynamic(mass, inertia, Vec3::ZERO);
    }
    (ManyBodyModel::uniform(n, body_pair, vec![ground]), bodies)
}

/// `n` boxes at random poses in a column of side `side` [m] above the table, some overlapping.
fn jumble(n: u32, side: f32, seed: u64) -> Vec<TransformGpu> {
    let mut rng = SplitMix64(seed);
    (0..n)
        .map(|_| {
            let p = Vec3::new((rng.unit() - 0.5) * side, (rng.unit() - 0.5) * side, 0.012 + rng.unit() * side);
            let axis = Vec3::new(rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5).normalize_or(Vec3::Z);
            TransformGpu::new(p, Quat::from_axis_angle(axis, rng.unit() * 3.0))
        })
        .collect()
}

fn at_rest(body_q: Vec<TransformGpu>) -> BodyState {
    let n = body_q.len();
    BodyState { body_q, body_qd: vec![[Vec3::ZERO; 2]; n] }
}

fn max_distance(a: &BodyState, b: &BodyState) -> f32 {
    a.body_q
        .iter()
        .zip(&b.body_q)
        .map(|(x, y)| (Vec3::from_slice(&x.p[..3]) - Vec3::from_slice(&y.p[..3])).length())
        .fold(0.0, f32::max)
}

#[test]
fn near_pairs_and_colours_match_the_cpu_twin_and_colour_properly() {
    near_pairs_and_colours(ManyBodyConfig::for_bodies(40).colour_rounds);
}

/// Two rounds colour only part of a dense world: the serial completion colours the rest, alike on the
/// GPU and in the CPU twin, still properly.
#[test]
fn pairs_the_rounds_leave_uncoloured_are_coloured_serially_alike() {
    near_pairs_and_colours(2);
}

fn near_pairs_and_colours(rounds: u32) {
    let n = 40;
    let (model, bodies) = box_model(n, 0.5);
    let cfg = ManyBodyConfig { colour_rounds: rounds, ..ManyBodyConfig::for_bodies(n) };
    let contact = ContactConfig { max_patches: 16, ..Default::default() };
    let solver = SolverConfig::default();
    let worlds = 2;
    let pipe = ManyBodyPipeline::new(gpu(), &model, &bodies, worlds, &cfg, &contact, &solver).unwrap();
    let mut q = jumble(n, 0.12, 3);
    q.extend(jumble(n, 0.2, 4));
    pipe.write_state(gpu(), &at_rest(q.clone()));
    pipe.submit_frame(gpu());
    let frames = pipe.read_frames(gpu());
    let flat = ManyBodyFlat::new(&model, &contact).unwrap();
    let xf: Vec<_> = q.iter().map(|t| t.xf()).collect();
    for (w, f) in frames.iter().enumerate() {
        let (pairs, over) = flat.near_pairs(&xf, w as u32, cfg.max_pairs);
        assert!(!over);
        assert_eq!(f.pairs, pairs, "world {w}: near pairs, GPU vs CPU twin");
        assert!(pairs.iter().filter(|p| p.b != NO_BODY).count() > 2 * n as usize / 3, "world {w}: a dense world");
        let (colours, count, flags) = colour_pairs(&pairs, n, cfg.max_colours, cfg.colour_rounds);
        assert_eq!(f.flags, flags, "world {w}: flags");
        assert_eq!(flags, 0, "world {w}: coloured within {} colours and {} rounds", cfg.max_colours, cfg.colour_rounds);
        assert_eq!(f.colours, colours, "world {w}: colours, GPU vs CPU twin");
        assert_eq!(f.colour_count, count);
        if rounds < 10 {
            // The rounds alone did not finish: all rounds give another colouring.
            assert_ne!(
                colours,
                colour_pairs(&pairs, n, cfg.max_colours, 1000).0,
                "world {w}: the serial completion ran"
            );
        }
        // A proper colouring: two pairs that share a body never share a colour.
        for (i, p) in pairs.iter().enumerate() {
            for (j, o) in pairs.iter().enumerate().skip(i + 1) {
                let shared = [p.a, p.b].iter().any(|&x| x != NO_BODY && (x == o.a || x == o.b));
                assert!(
                    !(shared && colours[i] == colours[j]),
                    "world {w}: pairs {p:?} and {o:?} share colour {}",
                    colours[i]
                );
            }
        }
        // Every pair's shapes are within reach of each other, and no pair within reach is missing.
        let mut brute = 0;
        for i in 0..n {
            for j in i + 1..n {
                let d = (Vec3::from_slice(&q[w * n as usize + i as usize].p[..3])
                    - Vec3::from_slice(&q[w * n as usize + j as usize].p[..3]))
                .length();
                if d <= 2.0 * H.length() + OFFSET {
                    brute += 1;
                    assert!(
                        pairs.iter().any(|p| p.a == i && p.b == j),
                        "world {w}: boxes {i} and {j} within reach, not listed"
                    );
                }
            }
        }
        println!("world {w}: {} near pairs ({brute} body pairs within reach), {count} colours", pairs.len());
    }
}

/// Boxes falling onto the table and each other, stepped by the GPU and by the CPU twin from the same start.
fn falling_boxes(n: u32) -> (ManyBodyModel, BodyModel, BodyState) {
    let (model, bodies) = box_model(n, 0.5);
    // A loose jumble (some overlap) 2-10 cm up: they land within the 20 frames.
    (model, bodies, at_rest(jumble(n, 0.08, 11)))
}

/// Frames of landing (stepped cold) and of resting (warm) in the parity test.
const LANDING: u32 = 30;
const RESTING: u32 = 30;

/// Two layers of six boxes, 2 mm apart side by side and 0.5 mm above what carries them, settling onto the
/// table and each other: resting contacts that last from frame to frame, so warm starting matters. Landing
/// is chaotic (which of four equally deep corners wins a patch slot is decided by rounding): free runs of
/// the GPU and the CPU twin part ways, 1e-8 m becoming 5e-5 m within 3 frames (measured), so the
/// CPU twin is re-synchronised to the GPU's poses every frame: landing frames cold on both sides, resting
/// frames warm-started, each side from its own rows (see PARITY_WARM_TOL).
fn stacked_boxes() -> (ManyBodyModel, BodyModel, BodyState) {
    let (model, bodies) = box_model(12, 0.5);
    let mut q = Vec::new();
    for layer in 0..2 {
        for k in 0..6 {
            let (i, j) = ((k % 3) as f32 - 1.0, (k / 3) as f32 - 0.5);
            let p = Vec3::new(
                i * (2.0 * H.x + 0.002) + 0.004 * layer as f32,
                j * (2.0 * H.y + 0.002),
                H.z + 0.0005 + layer as f32 * (2.0 * H.z + 0.0005),
            );
            q.push(TransformGpu::new(p, Quat::from_rotation_z(0.01 * k as f32)));
        }
    }
    (model, bodies, at_rest(q))
}

/// One world on the GPU, started at `start`, and its CPU twin, at the parity tests' settings (16 patches per
/// pair, 16 position iterations).
fn pipe_and_twin(
    model: &ManyBodyModel,
    bodies: &BodyModel,
    cfg: &ManyBodyConfig,
    start: &BodyState,
) -> (ManyBodyPipeline, ManyBodyCpu) {
    let contact = ContactConfig { max_patches: 16, ..Default::default() };
    let solver = SolverConfig { pos_iters: 16, ..Default::default() };
    let pipe = ManyBodyPipeline::new(gpu(), model, bodies, 1, cfg, &contact, &solver).unwrap();
    let cpu = ManyBodyCpu::new(model, bodies, cfg, &contact, &solver).unwrap();
    pipe.write_state(gpu(), start);
    (pipe, cpu)
}

#[test]
fn coloured_gpu_step_matches_the_cpu_twin() {
    let (model, bodies, start) = stacked_boxes();
    let cfg = ManyBodyConfig::for_bodies(12);
    let (pipe, mut cpu) = pipe_and_twin(&model, &bodies, &cfg, &start);
    let mut state = start.clone();
    let (mut touching, mut cold, mut warm) = (0, Vec::new(), Vec::new());
    for frame in 0..LANDING + RESTING {
        let landing = frame < LANDING;
        if landing {
            // Landing: both sides cold, from the same poses (see stacked_boxes).
            pipe.write_state(gpu(), &state);
            cpu.forget_warm_start();
        }
        pipe.submit_frame(gpu());
        let (g, ok) = pipe.read_state(gpu());
        let c = cpu.step(&mut state, &Control::default());
        assert!(ok[0] && c[0].1, "frame {frame}: both worlds ok");
        let gf = &pipe.read_frames(gpu())[0];
        assert_eq!(gf.pairs, c[0].0.pairs, "frame {frame}: near pairs");
        assert_eq!(gf.colours, c[0].0.colours, "frame {frame}: colours");
        touching = touching.max(pipe.read_stats(gpu())[0].touching_pairs);
        let d = max_distance(&g, &state);
        let dv = g.body_qd.iter().zip(&state.body_qd).map(|(a, b)| (a[0] - b[0]).length()).fold(0.0f32, f32::max);
        let tol = if landing { PARITY_TOL } else { PARITY_WARM_TOL };
        assert!(d < tol, "frame {frame} ({}): GPU and CPU twin {d} m apart", if landing { "cold" } else { "warm" });
        assert!(
            dv < if landing { PARITY_VEL_TOL } else { 10.0 * PARITY_VEL_TOL },
            "frame {frame}: velocities {dv} m/s apart"
        );
        if landing {
            cold.push(d)
        } else {
            warm.push(d)
        }
        // Resting: each side keeps its own rows for the warm start; only the poses are re-synchronised.
        state = g;
    }
    let worst = |v: &[f32]| v.iter().copied().fold(0.0f32, f32::max);
    let median = |v: &mut Vec<f32>| {
        v.sort_by(f32::total_cmp);
        v[v.len() / 2]
    };
    let (mc, mw) = (median(&mut cold), median(&mut warm));
    println!(
        "coloured step, GPU vs CPU twin per frame: landing (cold) at most {:.3e} m (median {mc:.1e}), resting (warm) at most {:.3e} m (median {mw:.1e}); up to {touching} pairs touching",
        worst(&cold),
        worst(&warm)
    );
    assert!(mc < PARITY_MEDIAN_TOL && mw < PARITY_MEDIAN_TOL, "median frames {mc} and {mw} m apart");
    assert!(touching >= 12, "the boxes rest on the table and on each other ({touching} pairs touching)");
    // Warm starting is at work: the same frame stepped cold from the same state ends elsewhere.
    let (now, _) = pipe.read_state(gpu());
    let fresh = ManyBodyPipeline::new(gpu(), &model, &bodies, 1, &cfg, &pipe.contact, &pipe.solver).unwrap();
    fresh.write_state(gpu(), &now);
    fresh.submit_frame(gpu());
    pipe.submit_frame(gpu());
    let (a, b) = (pipe.read_state(gpu()).0, fresh.read_state(gpu()).0);
    let bits = |s: &BodyState| -> Vec<u32> { bytemuck::cast_slice::<TransformGpu, u32>(&s.body_q).to_vec() };
    assert_ne!(bits(&a), bits(&b), "warm and cold steps differ: rows found last frame's impulses");
}

#[test]
fn many_body_frames_are_bitwise_reproducible() {
    frames_are_bitwise_reproducible(SleepConfig::OFF);
}

/// The same with sleeping on, loose enough that boxes fall asleep within the 15 frames.
#[test]
fn many_body_frames_with_sleeping_bodies_are_bitwise_reproducible() {
    frames_are_bitwise_reproducible(SleepConfig { frames: 3, distance: 0.002, angle: 0.05 });
}

fn frames_are_bitwise_reproducible(sleep: SleepConfig) {
    let n = 12;
    let (model, bodies, start) = falling_boxes(n);
    let cfg = ManyBodyConfig { sleep, ..ManyBodyConfig::for_bodies(n) };
    let contact = ContactConfig { max_patches: 16, ..Default::default() };
    let solver = SolverConfig { pos_iters: 16, ..Default::default() };
    let run = || {
        let pipe = ManyBodyPipeline::new(gpu(), &model, &bodies, 1, &cfg, &contact, &solver).unwrap();
        pipe.write_state(gpu(), &start);
        let mut slept = 0;
        for _ in 0..15 {
            pipe.submit_frame(gpu());
            slept += pipe.read_rest(gpu()).iter().filter(|r| r.asleep(&sleep)).count();
        }
        (pipe.read_state(gpu()).0, slept)
    };
    let ((a, slept_a), (b, slept_b)) = (run(), run());
    assert_eq!(slept_a, slept_b, "the same bodies asleep for the same frames");
    if sleep.enabled() {
        assert!(slept_a > 0, "some box fell asleep");
    }
    let bits = |s: &BodyState| -> Vec<u32> { bytemuck::cast_slice::<TransformGpu, u32>(&s.body_q).to_vec() };
    assert_eq!(bits(&a), bits(&b), "same start, same settings: bitwise the same poses");
    assert!(max_distance(&a, &start) > 0.01, "the boxes moved");
}

#[test]
fn a_world_over_its_pair_capacity_is_flagged_and_left_as_it_was_while_others_step_alone() {
    let n = 12;
    let (model, bodies, start) = falling_boxes(n);
    let contact = ContactConfig { max_patches: 16, ..Default::default() };
    let solver = SolverConfig { pos_iters: 16, ..Default::default() };
    // World 0: the falling jumble; world 1: the same boxes packed into a 3 cm cube, far more near pairs.
    let packed = jumble(n, 0.03, 5);
    let mut two = start.clone();
    two.body_q.extend(packed.iter().copied());
    two.body_qd.extend(vec![[Vec3::ZERO; 2]; n as usize]);
    let cpu_pairs = |q: &[TransformGpu]| {
        let flat = ManyBodyFlat::new(&model, &contact).unwrap();
        flat.near_pairs(&q.iter().map(|t| t.xf()).collect::<Vec<_>>(), 0, u32::MAX).0.len() as u32
    };
    let (loose, dense) = (cpu_pairs(&start.body_q), cpu_pairs(&packed));
    assert!(dense > loose + 10, "{dense} vs {loose} near pairs");
    let cfg = ManyBodyConfig { max_pairs: loose + 5, ..ManyBodyConfig::for_bodies(n) };
    let pipe = ManyBodyPipeline::new(gpu(), &model, &bodies, 2, &cfg, &contact, &solver).unwrap();
    pipe.write_state(gpu(), &two);
    pipe.submit_frame(gpu());
    let (s, ok) = pipe.read_state(gpu());
    let frames = pipe.read_frames(gpu());
    assert_eq!((ok[0], ok[1]), (true, false), "the packed world is flagged");
    assert_eq!(frames[1].flags, FLAG_PAIRS, "flagged for its pair count (alone)");
    let mut cpu = ManyBodyCpu::new(&model, &bodies, &cfg, &contact, &solver).unwrap();
    let mut twin = two.clone();
    let c = cpu.step(&mut twin, &Control::default());
    assert_eq!((c[0].0.flags, c[1].0.flags, c[1].1), (0, FLAG_PAIRS, false), "the CPU twin flags alike");
    assert_eq!(&twin.body_q[n as usize..], &packed[..], "and leaves the world as it was");
    assert_eq!(&s.body_q[n as usize..], &packed[..], "the flagged world is left as it was");
    // World 0 steps exactly as it does alone.
    let alone = ManyBodyPipeline::new(gpu(), &model, &bodies, 1, &cfg, &contact, &solver).unwrap();
    alone.write_state(gpu(), &start);
    alone.submit_frame(gpu());
    let (a, _) = alone.read_state(gpu());
    let bits = |q: &[TransformGpu]| -> Vec<u32> { bytemuck::cast_slice::<TransformGpu, u32>(q).to_vec() };
    assert_eq!(bits(&s.body_q[..n as usize]), bits(&a.body_q), "the other world is bitwise unchanged");
}

/// The job cull (`many_body::job_far_cpu`, contacts.wgsl) drops a run of query triangles on one SDF sample at
/// the centre of its bounding sphere; it must never drop one that has a candidate. Two boxes meshed with
/// 2 mm triangles (spatially ordered into jobs of 256) and a 32-resolution grid, 300 random poses within
/// reach of each other: every culled job, generated anyway, has no candidate.
#[test]
fn the_job_cull_never_drops_a_job_with_a_candidate() {
    use factory_engine::contact::generate::{generate_job_cpu, RigidTransform};
    use factory_engine::contact::model::FlatModel;
    use factory_engine::many_body::{job_far_cpu, NearPair};
    use factory_engine::mesh::box_mesh;
    use std::sync::Arc;
    let cache = SdfCache::new(SdfCache::default_dir());
    let mesh = Arc::new(box_mesh(H).split_long_triangles(0.002));
    let shape = |body| ShapeDesc::new(body, ShapeGeometry::Mesh { mesh: mesh.clone(), sdf_resolution: Some(32) });
    let spec = pair_spec(&shape(0), &shape(1), OFFSET, &cache).unwrap();
    let model = ManyBodyModel::uniform(2, spec, vec![]);
    let contact = ContactConfig { chunk_triangles: 256, max_patches: 16, ..Default::default() };
    let flat = ManyBodyFlat::new(&model, &contact).unwrap();
    assert!(flat.jobs_per_pair >= 4, "{} jobs per pair", flat.jobs_per_pair);
    let np = NearPair { a: 0, key: 1, b: 1, template: 0 };
    let one = FlatModel {
        pairs: vec![flat.pair_record(&np)],
        jobs: flat.flat.jobs.clone(),
        tri_verts: flat.flat.tri_verts.clone(),
        sdf_values: flat.flat.sdf_values.clone(),
    };
    let pair = &one.pairs[0];
    let mut rng = SplitMix64(17);
    let (mut culled, mut kept_with_candidates) = (0, 0);
    for _ in 0..300 {
        let axis = Vec3::new(rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5).normalize_or(Vec3::Z);
        let p = Vec3::new(rng.unit() - 0.5, rng.unit() - 0.5, rng.unit() - 0.5) * 0.09;
        let q = [RigidTransform::IDENTITY, TransformGpu::new(p, Quat::from_axis_angle(axis, rng.unit() * 6.0)).xf()];
        let wa = q[0].mul(&TransformGpu { p: pair.a_pos, q: pair.a_rot }.xf());
        let wb = q[1].mul(&TransformGpu { p: pair.b_pos, q: pair.b_rot }.xf());
        for (k, job) in one.jobs.iter().enumerate() {
            let out = generate_job_cpu(&one, job, &q, 2, 0, &contact);
            if job_far_cpu(pair, &one.sdf_values, flat.job_bounds[k], &wa, &wb) {
                culled += 1;
                assert_eq!(out.candidates, 0, "job {k} culled at body 1 pose {p:?} has {} candidates", out.candidates);
            } else if out.candidates > 0 {
                kept_with_candidates += 1;
            }
        }
    }
    println!("job cull: {culled} of {} jobs culled, {kept_with_candidates} kept with candidates", 300 * one.jobs.len());
    assert!(culled > 100 && kept_with_candidates > 100, "the poses exercise both outcomes");
}

/// The auto-reset of one many-body world: world 1 is given a NaN velocity, is flagged, and is reset alone;
/// a run in which it never broke but was reset to the same state at the same frame ends bitwise the same.
#[test]
fn a_broken_many_body_world_is_reset_alone_and_every_world_then_steps_as_if_it_never_broke() {
    let n = 12;
    let (model, bodies, start) = stacked_boxes();
    let cfg = ManyBodyConfig::for_bodies(n);
    let contact = ContactConfig { max_patches: 16, ..Default::default() };
    let solver = SolverConfig { pos_iters: 16, ..Default::default() };
    let pipe = ManyBodyPipeline::new(gpu(), &model, &bodies, 2, &cfg, &contact, &solver).unwrap();
    let mut good = start.clone();
    good.body_q.extend(start.body_q.iter().copied());
    good.body_qd.extend(start.body_qd.iter().copied());
    let run = |s0: &BodyState| {
        pipe.write_state(gpu(), s0);
        for _ in 0..8 {
            pipe.submit_frame(gpu());
        }
        let (_, ok_before) = pipe.read_state(gpu());
        pipe.reset_world(gpu(), 1, &start.body_q, &start.body_qd);
        for _ in 0..8 {
            pipe.submit_frame(gpu());
        }
        let (s, ok) = pipe.read_state(gpu());
        (s, ok_before, ok)
    };
    let mut broken = good.clone();
    broken.body_qd[n as usize + 3][0] = Vec3::new(f32::NAN, 0.0, 0.0);
    let (a, ok_a0, ok_a) = run(&good);
    let (b, ok_b0, ok_b) = run(&broken);
    assert_eq!((ok_a0, ok_b0), (vec![true; 2], vec![true, false]), "world 1 broke and was flagged");
    assert_eq!((ok_a, ok_b), (vec![true; 2], vec![true; 2]), "after its reset world 1 is ok");
    let bits = |s: &BodyState| -> Vec<u32> { bytemuck::cast_slice::<TransformGpu, u32>(&s.body_q).to_vec() };
    assert_eq!(bits(&a), bits(&b), "both worlds bitwise as if world 1 never broke");
}

/// Sleeping (`ManyBodyConfig::sleep`): the six boxes of the stack's lower layer settle on the table and fall
/// asleep, alike on the GPU and in the CPU twin; asleep, they keep their poses to the bit with zero velocity;
/// a kinematic box driven across the table into them wakes the boxes it reaches, which then move, and never
/// sleeps itself. (The upper layer is left out: at these settings, 1 substep and 16 iterations, its boxes,
/// each bridging two lower ones, keep rocking at up to 1 rad/s, 0.01-0.06 rad a frame, as
/// this test's trace shows.)
#[test]
fn a_settled_stack_falls_asleep_alike_on_the_gpu_and_in_the_twin_and_a_pusher_wakes_it() {
    /// Frames a box must stay within SLEEP_DISTANCE and SLEEP_ANGLE of one pose to sleep.
    const SLEEP_FRAMES: u32 = 20;
    /// [m]: a box resting on the table moves by micrometres; one pushed at PUSH_SPEED by 0.83 mm a frame.
    const SLEEP_DISTANCE: f32 = 5e-4;
    const SLEEP_ANGLE: f32 = 0.01;
    /// The kinematic pusher's speed [m/s] along +x; it starts 88 mm left of the stack, comes near it
    /// (bounding spheres within the contact offset: it wakes the boxes it nears) after about 59 frames and
    /// touches it after about 82, when the stack has slept for about 40.
    const PUSH_SPEED: f32 = 0.05;
    const FRAMES: usize = 120;
    /// Frame by which every box is asleep, before the pusher reaches them.
    const ASLEEP_BY: usize = 30;
    const N: usize = 6;
    let (model, mut bodies) = box_model(N as u32 + 1, 0.5);
    let pusher = N;
    bodies.body_inv_mass[pusher] = 0.0;
    bodies.body_inv_inertia[pusher] = Mat3::ZERO;
    bodies.body_kinematic = vec![false; N + 1];
    bodies.body_kinematic[pusher] = true;
    let (_, _, mut stack) = stacked_boxes();
    stack.body_q.truncate(N);
    stack.body_qd.truncate(N);
    let mut start = stack.clone();
    start.body_q.push(TransformGpu::new(Vec3::new(-0.15, 0.0, H.z + 0.0005), Quat::IDENTITY));
    start.body_qd.push([Vec3::new(PUSH_SPEED, 0.0, 0.0), Vec3::ZERO]);
    let sleep = SleepConfig { frames: SLEEP_FRAMES, distance: SLEEP_DISTANCE, angle: SLEEP_ANGLE };
    let cfg = ManyBodyConfig { sleep, ..ManyBodyConfig::for_bodies(N as u32 + 1) };
    let (pipe, mut cpu) = pipe_and_twin(&model, &bodies, &cfg, &start);
    let mut state = start.clone();
    let mut last = start.clone();
    let mut was_asleep = vec![false; N + 1];
    let (mut asleep_at, mut slept_frames, mut woke, mut dormant_pairs) = (None, 0usize, Vec::new(), 0usize);
    for frame in 0..FRAMES {
        pipe.submit_frame(gpu());
        let (g, ok) = pipe.read_state(gpu());
        let c = cpu.step(&mut state, &Control::default());
        assert!(ok[0] && c[0].1, "frame {frame}: both worlds ok");
        let rest = pipe.read_rest(gpu());
        let gpu_asleep: Vec<bool> = rest.iter().map(|r| r.asleep(&sleep)).collect();
        let cpu_asleep: Vec<bool> = cpu.rest.iter().map(|r| r.asleep(&sleep)).collect();
        assert_eq!(gpu_asleep, cpu_asleep, "frame {frame}: the same bodies asleep on the GPU and in the twin");
        assert!(!gpu_asleep[pusher], "frame {frame}: the kinematic pusher never sleeps");
        let d = max_distance(&g, &state);
        assert!(d < PARITY_WARM_TOL, "frame {frame}: GPU and CPU twin {d} m apart");
        for b in 0..N {
            if gpu_asleep[b] {
                assert_eq!(g.body_qd[b], [Vec3::ZERO; 2], "frame {frame}: box {b} asleep with a velocity");
                if rest[b].count > SLEEP_FRAMES as f32 + 1.0 {
                    // Asleep since last frame at least: not moved by a bit.
                    let bits = |t: &TransformGpu| bytemuck::cast::<TransformGpu, [u32; 8]>(*t);
                    assert_eq!(bits(&g.body_q[b]), bits(&last.body_q[b]), "frame {frame}: sleeping box {b} moved");
                }
            }
        }
        let stack_asleep = gpu_asleep[..N].iter().filter(|&&a| a).count();
        // Pairs whose bodies all slept through the frame (asleep when it began and not woken) get no
        // contacts (near_dormant).
        let (gf, patches) = &pipe.read_patches(gpu())[0];
        for (np, ps) in gf.pairs.iter().zip(patches) {
            let asleep = |b: u32| b == NO_BODY || (gpu_asleep[b as usize] && was_asleep[b as usize]);
            if asleep(np.a) && asleep(np.b) {
                assert!(ps.is_empty(), "frame {frame}: sleeping pair ({}, {}) has contacts", np.a, np.b);
                dormant_pairs += 1;
            }
        }
        if stack_asleep == N {
            asleep_at.get_or_insert(frame);
            slept_frames += 1;
        }
        if asleep_at.is_some() {
            for b in 0..N {
                if !gpu_asleep[b] && !woke.contains(&b) {
                    woke.push(b);
                }
            }
        }
        // Each side keeps its own rows and sleeping state; the poses are re-synchronised (as above).
        was_asleep = gpu_asleep;
        last = g.clone();
        state = g;
    }
    let moved: Vec<f32> = (0..N)
        .map(|b| (Vec3::from_slice(&last.body_q[b].p[..3]) - Vec3::from_slice(&stack.body_q[b].p[..3])).length())
        .collect();
    println!(
        "stack asleep from frame {asleep_at:?} for {slept_frames} frames ({dormant_pairs} pair-frames without contacts); woken by the pusher: {woke:?}; moved [mm]: {:?}",
        moved.iter().map(|m| (m * 1e4).round() / 10.0).collect::<Vec<_>>()
    );
    let asleep_at = asleep_at.expect("the stack fell asleep");
    assert!(asleep_at <= ASLEEP_BY, "the stack fell asleep only at frame {asleep_at}");
    assert!(woke.len() >= 2, "the pusher woke {woke:?}");
    assert!(dormant_pairs >= 6 * 20, "{dormant_pairs} pair-frames left out while asleep");
    for &b in &woke {
        assert!(moved[b] > 0.01, "box {b} woke but moved {} m", moved[b]);
    }
}

#[test]
fn sleep_settings_out_of_range_are_refused_naming_the_field() {
    let (model, bodies) = box_model(2, 0.5);
    let contact = ContactConfig::default();
    let solver = SolverConfig::default();
    let on = SleepConfig { frames: 30, distance: 0.001, angle: 0.1 };
    for (sleep, field) in [
        (SleepConfig { frames: 1, ..on }, "sleep.frames"),
        (SleepConfig { distance: 0.0, ..on }, "sleep.distance"),
        (SleepConfig { distance: f32::NAN, ..on }, "sleep.distance"),
        (SleepConfig { angle: -0.1, ..on }, "sleep.angle"),
        (SleepConfig { angle: 4.0, ..on }, "sleep.angle"),
    ] {
        let cfg = ManyBodyConfig { sleep, ..ManyBodyConfig::for_bodies(2) };
        let err = ManyBodyCpu::new(&model, &bodies, &cfg, &contact, &solver).err().expect("refused").to_string();
        assert!(err.contains(field), "{sleep:?}: {err}");
    }
    // Off needs no bounds.
    let cfg = ManyBodyConfig { sleep: SleepConfig::OFF, ..ManyBodyConfig::for_bodies(2) };
    assert!(ManyBodyCpu::new(&model, &bodies, &cfg, &contact, &solver).is_ok());
}

//! Dynamics of the M16 nut on its bolt against the analytic reference (docs/ARCHITECTURE.md section 10): a frictionless
//! rigid nut on a helix descends with a = g m / (m + I (2 pi / p)^2), I its inertia about the axis, p the
//! pitch, and advances one pitch per turn. Contacts come from the GPU pipeline (analytic bolt SDF), the
//! solver is the GPU step and the CPU reference `solver::step_cpu`. Also: the nut resting on a table.

use factory_assets::{nut_bolt, Fit, IsoSize, ThreadOptions};
use factory_bench::contact_scene::{lower_until_touch, ContactScene, PartPair};
use factory_bench::scene::TurnCounter;
use factory_engine::contact::{ContactConfig, ContactPipeline};
use factory_engine::gpu::GpuContext;
use factory_engine::solver::gpu::GpuSolver;
use factory_engine::solver::{step_cpu_with_pipeline, BodyModel, BodyState, Control, SolverConfig, WarmStart};
use glam::Vec3;

/// Descent after 1 s within 5% of the analytic value.
const DESCENT_TOL: f64 = 0.05;
/// Descent per turn within 2% of the pitch.
const LEAD_TOL: f64 = 0.02;
const G: f32 = 9.81;

/// What a released nut did in `frames` frames at the paper's settings (dt 1/60 s, 1 substep, 20 position
/// and 1 velocity iteration): descent [m], signed turns, and the nut's mass properties.
struct Run {
    descent: f64,
    /// Largest |z - z0| over all frames [m].
    excursion: f64,
    yaw: f64,
    mass: f64,
    inertia_axis: f64,
    pitch: f64,
    seconds: f64,
}

fn release_nut(mu: f32, frames: u32, on_gpu: bool, substeps: u32) -> Run {
    let cfg = SolverConfig { substeps, ..Default::default() };
    release_nut_with(mu, frames, on_gpu, cfg, &ThreadOptions::default(), &ContactConfig::default())
}

fn release_nut_with(
    mu: f32,
    frames: u32,
    on_gpu: bool,
    cfg: SolverConfig,
    thread: &ThreadOptions,
    contact: &ContactConfig,
) -> Run {
    let nb = nut_bolt(IsoSize::M16, Fit::Tight, thread).unwrap();
    let pair = PartPair::nut_bolt(&nb);
    let mut scene = ContactScene::with_thread_sdf(pair, nb.bolt_sdf(), 1.0e-3);
    scene.model.pairs[0].friction = mu;
    let gpu = GpuContext::global().unwrap();
    let p = nb.pitch;
    let lift = lower_until_touch(gpu, &scene, 5.0 * p, 5.0 * p - 0.1e-3, 0.2e-6).unwrap();
    let pipe = ContactPipeline::new(gpu, &scene.model, 1, contact).unwrap();
    let mp = nb.nut.mass_properties;
    let mut model = BodyModel { gravity: Vec3::new(0.0, 0.0, -G), ..Default::default() };
    model.add_dynamic(mp.mass, mp.inertia, mp.com);
    model.add_static();
    let mut state = BodyState { body_q: scene.poses(lift, &[0.0]), body_qd: vec![[Vec3::ZERO; 2]; 2] };
    let z0 = state.body_q[0].p[2];
    let mut excursion = 0.0f64;
    let mut yaw = TurnCounter::default();
    let solver = GpuSolver::new(gpu, &pipe, &model, &cfg).unwrap();
    solver.write_state(gpu, &pipe, &state);
    let mut warm = WarmStart::default();
    for _ in 0..frames {
        if on_gpu {
            // Contacts and solver in one submission; the state stays on the device (read here only to
            // track the turns).
            solver.submit_frame(gpu, &pipe);
            let (s, ok) = solver.read_state(gpu, &pipe);
            assert!(ok[0], "world diverged");
            state = s;
        } else {
            let ok = step_cpu_with_pipeline(gpu, &pipe, &model, &mut state, &cfg, &Control::default(), &mut warm);
            assert!(ok[0], "world diverged");
        }
        yaw.update(&state.body_q[0]);
        excursion = excursion.max((state.body_q[0].p[2] - z0).abs() as f64);
    }
    Run {
        descent: (z0 - state.body_q[0].p[2]) as f64,
        excursion,
        yaw: yaw.radians,
        mass: mp.mass as f64,
        inertia_axis: mp.inertia.z_axis.z as f64,
        pitch: p as f64,
        seconds: frames as f64 * cfg.dt as f64,
    }
}

#[test]
fn frictionless_m16_nut_descends_the_helix_at_the_analytic_rate() {
    for on_gpu in [false, true] {
        let who = if on_gpu { "GPU solver" } else { "CPU reference" };
        assert_analytic_descent(&release_nut(0.0, 60, on_gpu, 1), who);
    }
}

/// The frictionless descent against a = g m / (m + I (2 pi / p)^2) (DESCENT_TOL) and the lead against the
/// pitch (LEAD_TOL).
fn assert_analytic_descent(r: &Run, who: &str) {
    let k = std::f64::consts::TAU / r.pitch;
    let a = G as f64 * r.mass / (r.mass + r.inertia_axis * k * k);
    let expect = 0.5 * a * r.seconds * r.seconds;
    let turns = r.yaw.abs() / std::f64::consts::TAU;
    eprintln!(
        "{who}: descent {:.4} mm (analytic {:.4} mm), turns {turns:.4}, descent per turn {:.4} mm (pitch {:.4} mm)",
        r.descent * 1e3,
        expect * 1e3,
        r.descent / turns * 1e3,
        r.pitch * 1e3
    );
    assert!(
        (r.descent - expect).abs() <= DESCENT_TOL * expect,
        "{who}: descent {} m vs analytic {expect} m",
        r.descent
    );
    assert!(r.yaw < 0.0, "{who}: a right-hand nut turns clockwise (seen from +z) going down: yaw {}", r.yaw);
    assert!((r.descent / turns - r.pitch).abs() <= LEAD_TOL * r.pitch, "{who}: {} m per turn", r.descent / turns);
}

/// The nut of the speed figures (docs/BENCHMARKS.md, `factory-bench scene nut-bolt --segments-per-turn 48
/// --descent-iters 4 [--per 4 [--workgroup 32]]`: "Model only what the scene needs") at the paper's solver settings (1 substep, 20 + 1
/// iterations), on the GPU: the speed figures are quoted with the accuracy above, so this nut must meet
/// it too. Frictionless it descends at the analytic rate; at the paper's mu 0.05 (above the critical
/// 0.0375) it stays: its descent after 1 s within LOCKED_DRIFT (measured: 0.0055 mm). Its
/// excursion at every frame is not asserted: at 1 substep the fine nut jitters by up to 22 um inside its
/// axial play (see LOCK_SUBSTEPS).
#[test]
fn the_benchmarks_coarse_nut_keeps_the_analytic_descent_and_holds_at_the_papers_friction() {
    let thread = ThreadOptions { segments_per_turn: 48, ..Default::default() };
    // One candidate per invocation (the default) and four (`--per 4`, with 64 or 32 invocations per
    // workgroup: the speed figures' settings).
    for (workgroup_size, per) in [(64, 1), (64, 4), (32, 4)] {
        let contact =
            ContactConfig { iterations: 4, workgroup_size, candidates_per_invocation: per, ..Default::default() };
        let cfg = SolverConfig::default();
        let who = format!("coarse nut, {workgroup_size} invocations x {per} candidate(s)");
        assert_analytic_descent(&release_nut_with(0.0, 60, true, cfg.clone(), &thread, &contact), &who);
        let held = release_nut_with(0.05, 60, true, cfg, &thread, &contact);
        eprintln!("{who}, mu 0.05: descent {:.5} mm", held.descent * 1e3);
        assert!(held.descent.abs() < LOCKED_DRIFT, "{who}, mu 0.05: descent {} m in 1 s", held.descent);
    }
}

/// Self-locking (docs/ARCHITECTURE.md section 10): the nut holds when mu exceeds about tan(lead angle) cos(30 deg)
/// (M16: 0.0433 * 0.866 = 0.0375) and turns down the thread when mu is clearly below.
const LOCKED_DRIFT: f64 = 0.01e-3;

/// Held, the nut must stay within LOCKED_DRIFT at every frame, not only at 1 s. With the paper's 1 substep
/// and 20 iterations the held nut jitters inside its 22 um axial play: by up to 18 um without warm starting,
/// and still by 22 um with it (descent 0.011 mm in 1 s; 24 um with patch_iters 8; measured: its
/// ~200 contacts change slots from frame to frame, so few rows inherit impulses; 21.5 um with friction per
/// patch, SolverConfig::friction_per_patch); 4 substeps converge
/// (excursion 0.6 um), so this test runs at 4.
const LOCK_SUBSTEPS: u32 = 4;

#[test]
fn m16_nut_self_locks_above_the_critical_friction_and_turns_below() {
    let held = release_nut(0.1, 60, true, LOCK_SUBSTEPS);
    eprintln!("mu 0.1: descent {:.5} mm, largest excursion {:.5} mm", held.descent * 1e3, held.excursion * 1e3);
    assert!(held.excursion < LOCKED_DRIFT, "mu 0.1: the nut moved up to {} m", held.excursion);
    let free = release_nut(0.01, 60, true, LOCK_SUBSTEPS);
    eprintln!("mu 0.01: descent {:.4} mm", free.descent * 1e3);
    // Clearly turning: at least a fifth of the frictionless descent (4.6 mm) and along the thread.
    assert!(free.descent > 0.9e-3 && free.yaw < -0.4, "mu 0.01: descent {} m, yaw {}", free.descent, free.yaw);
}

/// A nut resting on a table drifts less than 1e-3 mm/s. The M16 nut (its full threaded mesh, 11.6k query
/// triangles) set down flat 0.1 mm above the table (the exact half-space), at the paper's settings (1
/// substep, 20 + 1 iterations), steel on steel; after 1 s to settle, its centre of mass moves less than
/// REST_DRIFT over the next 2 s. GPU solver and CPU reference.
#[test]
fn an_m16_nut_resting_on_a_table_drifts_less_than_1e_3_mm_per_s() {
    use factory_engine::contact::roles::{pair_spec, ShapeDesc, ShapeGeometry};
    use factory_engine::contact::{ContactModel, TransformGpu};
    use factory_engine::sdf::cache::SdfCache;
    use glam::Quat;
    use std::sync::Arc;
    /// 1e-3 mm/s over 2 s [m].
    const REST_DRIFT: f32 = 2e-6;
    let nut = nut_bolt(IsoSize::M16, Fit::Tight, &ThreadOptions::default()).unwrap().nut;
    let bottom = nut.mesh.positions.iter().map(|v| v.z).fold(f32::INFINITY, f32::min);
    let shape = ShapeDesc::new(0, ShapeGeometry::Mesh { mesh: Arc::new(nut.mesh.clone()), sdf_resolution: None });
    let table = ShapeDesc::fixed((Vec3::ZERO, Quat::IDENTITY), ShapeGeometry::Plane);
    let mut pair = pair_spec(&shape, &table, 1e-3, &SdfCache::new(SdfCache::default_dir())).unwrap();
    pair.friction = 0.5;
    let model = ContactModel { body_count: 1, pairs: vec![pair] };
    let mp = nut.mass_properties;
    let mut bodies = BodyModel { gravity: Vec3::new(0.0, 0.0, -G), ..Default::default() };
    bodies.add_dynamic(mp.mass, mp.inertia, mp.com);
    let cfg = SolverConfig::default();
    let start = BodyState {
        body_q: vec![TransformGpu::new(Vec3::new(0.0, 0.0, 0.1e-3 - bottom), Quat::IDENTITY)],
        body_qd: vec![[Vec3::ZERO; 2]],
    };
    let gpu = GpuContext::global().unwrap();
    let com = |s: &BodyState| Vec3::from_slice(&s.body_q[0].p[..3]) + Quat::from_array(s.body_q[0].q) * mp.com;
    for on_gpu in [true, false] {
        let pipe = ContactPipeline::new(gpu, &model, 1, &ContactConfig::default()).unwrap();
        let solver = GpuSolver::new(gpu, &pipe, &bodies, &cfg).unwrap();
        solver.write_state(gpu, &pipe, &start);
        let (mut state, mut warm) = (start.clone(), WarmStart::default());
        let mut settled = None;
        for f in 0..180 {
            if on_gpu {
                solver.submit_frame(gpu, &pipe);
                if f == 59 || f == 179 {
                    state = solver.read_state(gpu, &pipe).0;
                }
            } else {
                assert!(
                    step_cpu_with_pipeline(gpu, &pipe, &bodies, &mut state, &cfg, &Control::default(), &mut warm)[0]
                );
            }
            if f == 59 {
                settled = Some(com(&state));
            }
        }
        let drift = (com(&state) - settled.unwrap()).length();
        let height = state.body_q[0].p[2] + bottom;
        eprintln!(
            "{}: the nut's bottom face rests at z {:.2} um; drift over 2 s {:.3e} m ({:.2e} mm/s)",
            if on_gpu { "GPU solver" } else { "CPU reference" },
            height * 1e6,
            drift,
            drift * 1e3 / 2.0
        );
        assert!(drift < REST_DRIFT, "drifted {drift} m in 2 s");
        assert!(height.abs() < 20e-6, "rests at {height} m, not on the table");
    }
}

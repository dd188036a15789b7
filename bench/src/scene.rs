//! `factory-bench scene`: whole frames (contact handling + Gauss-Seidel solve, both on the GPU) of the
//! paper's scenes (section III-D, Table II), with the scene's accuracy figures. This module holds the nut-bolt
//! scene and the timing helpers the scenes share; the piles are [`crate::pile`], the Franka scene
//! [`crate::franka`]. Peg-in-hole is not a benchmark scene (its dynamics are tested in
//! bench/tests/peg_in_hole.rs).

use crate::contact_scene::{lower_until_touch, ContactScene, PartPair};
use anyhow::{ensure, Result};
use factory_assets::{nut_bolt, Fit, IsoSize, ThreadOptions};
use factory_engine::contact::{ContactConfig, ContactPipeline};
use factory_engine::gpu::GpuContext;
use factory_engine::sdf::cache::SdfCache;
use factory_engine::solver::gpu::GpuSolver;
use factory_engine::solver::{BodyModel, BodyState, SolverConfig};
use glam::{Quat, Vec3};
use std::time::Instant;

/// Settings of one nut-bolt run.
#[derive(Clone, Debug)]
pub struct NutBoltRun {
    pub size: IsoSize,
    pub fit: Fit,
    pub worlds: u32,
    /// Simulated time [s].
    pub seconds: f32,
    /// `None`: the exact analytic bolt SDF; `Some(r)`: a grid baked at resolution r.
    pub sdf_resolution: Option<u32>,
    pub contact: ContactConfig,
    pub solver: SolverConfig,
    /// Friction coefficient (the paper's nut-bolt scene: 0.05).
    pub mu: f32,
    /// Contact offset [m].
    pub contact_offset: f32,
    /// Thread columns per turn of the generated nut and bolt meshes (the nut's triangles are queried).
    pub segments_per_turn: usize,
}

/// What the run measured.
#[derive(Clone, Debug, serde::Serialize)]
pub struct NutBoltReport {
    pub scene: &'static str,
    pub size: String,
    pub fit: String,
    pub worlds: u32,
    pub seconds: f32,
    pub frames: u32,
    /// The solver settings (Table II's columns).
    #[serde(flatten)]
    pub solver: SolverColumns,
    pub sdf: String,
    pub max_patches: u32,
    /// Projected-gradient iterations per query triangle.
    pub descent_iters: u32,
    /// Candidates per invocation of the contact kernels (ContactConfig::candidates_per_invocation).
    pub candidates_per_invocation: u32,
    /// Invocations per contact workgroup (ContactConfig::workgroup_size).
    pub workgroup_size: u32,
    /// ContactConfig::interleaved_descent.
    pub interleaved_descent: bool,
    pub segments_per_turn: usize,
    /// Query (nut) triangles per pair.
    pub query_triangles: usize,
    pub mu: f32,
    /// Wall time of the frames (submission to completion; readbacks for the figures excluded) [s].
    pub wall_s: f64,
    pub ms_per_frame: f64,
    /// Where the time goes (paper Table I), timed after the run on its last state, each part alone over
    /// the same number of frames in one submission: contact generation + reduction [ms per frame] ...
    pub handling_ms_per_frame: f64,
    /// ... and the solver step on the last frame's contacts [ms per frame].
    pub solve_ms_per_frame: f64,
    pub pair_seconds_per_wall_second: f64,
    /// Real-time factor of one world.
    pub real_time_factor_per_world: f64,
    /// World 0: descent of the nut [mm] and signed turns (negative = clockwise seen from +z).
    pub nut_descent_mm: f64,
    pub nut_turns: f64,
    /// Frictionless analytic descent g m / (m + I (2 pi / p)^2) t^2 / 2 [mm] (for mu = 0 runs).
    pub analytic_descent_mm: f64,
    /// Deepest contact seen in any world at any frame start [mm] (positive: penetration).
    pub max_penetration_mm: f64,
    pub nut_mass_kg: f32,
    pub nut_inertia_axis_kgm2: f32,
    pub pitch_mm: f32,
    /// Every world stayed finite and below the solver's speed bound.
    pub finite: bool,
    pub adapter: String,
}

/// Runs the nut-bolt scene: each world's nut is released touching its bolt, 5 pitches above the seat.
pub fn run_nut_bolt(gpu: &GpuContext, run: &NutBoltRun) -> Result<NutBoltReport> {
    ensure!(run.worlds > 0, "--worlds must be at least 1");
    ensure!(run.seconds > 0.0 && run.seconds.is_finite(), "--seconds must be > 0, got {}", run.seconds);
    run.solver.validate()?;
    let nb =
        nut_bolt(run.size, run.fit, &ThreadOptions { segments_per_turn: run.segments_per_turn, ..Default::default() })?;
    let pair = PartPair::nut_bolt(&nb);
    let mut scene = match run.sdf_resolution {
        None => ContactScene::with_thread_sdf(pair, nb.bolt_sdf(), run.contact_offset),
        Some(r) => ContactScene::new(pair, r, run.contact_offset, &SdfCache::new(SdfCache::default_dir()))?,
    };
    scene.model.pairs[0].friction = run.mu;
    let p = nb.pitch;
    // Touching: lowered from the centred pose until the deepest contact is zero (when the grid's error
    // already reports penetration there, start from the centred pose).
    let lift = lower_until_touch(gpu, &scene, 5.0 * p, 5.0 * p - 0.1e-3, 0.2e-6).unwrap_or(5.0 * p);
    let pipe = ContactPipeline::new(gpu, &scene.model, run.worlds, &run.contact)?;
    let mp = nb.nut.mass_properties;
    let mut model = BodyModel { gravity: Vec3::new(0.0, 0.0, -9.81), ..Default::default() };
    model.add_dynamic(mp.mass, mp.inertia, mp.com);
    model.add_static();
    let solver = GpuSolver::new(gpu, &pipe, &model, &run.solver)?;
    let state = BodyState {
        body_q: scene.poses(lift, &vec![0.0; run.worlds as usize]),
        body_qd: vec![[Vec3::ZERO; 2]; 2 * run.worlds as usize],
    };
    warm_up(gpu, &pipe, &solver, &state);
    let frames = (run.seconds / run.solver.dt).round().max(1.0) as u32;
    let z0 = state.body_q[0].p[2];
    let (mut yaw, mut wall, mut deepest) = (TurnCounter::default(), 0.0f64, f32::INFINITY);
    let mut finite = true;
    for _ in 0..frames {
        let t = Instant::now();
        solver.submit_frame(gpu, &pipe);
        gpu.wait();
        wall += t.elapsed().as_secs_f64();
        // Figures (outside the timing): the frame's contacts and world 0's turn.
        if let Some(d) = min_depth_all(&pipe.read(gpu)) {
            deepest = deepest.min(d);
        }
        let (s, ok) = solver.read_state(gpu, &pipe);
        finite &= ok.iter().all(|&o| o);
        yaw.update(&s.body_q[0]);
    }
    let (s, _) = solver.read_state(gpu, &pipe);
    let (handling_ms, solve_ms) = time_split(gpu, &pipe, &solver, frames.min(10));
    let sim = frames as f64 * run.solver.dt as f64;
    let k = std::f64::consts::TAU / p as f64;
    let (m, i) = (mp.mass as f64, mp.inertia.z_axis.z as f64);
    Ok(NutBoltReport {
        scene: "nut-bolt",
        size: run.size.name().into(),
        fit: run.fit.name().into(),
        worlds: run.worlds,
        seconds: sim as f32,
        frames,
        solver: (&run.solver).into(),
        sdf: run.sdf_resolution.map_or("analytic".into(), |r| format!("grid {r}")),
        max_patches: run.contact.max_patches,
        descent_iters: run.contact.iterations,
        candidates_per_invocation: run.contact.candidates_per_invocation,
        workgroup_size: run.contact.workgroup_size,
        interleaved_descent: run.contact.interleaved_descent,
        segments_per_turn: run.segments_per_turn,
        query_triangles: nb.nut.mesh.triangle_count(),
        mu: run.mu,
        wall_s: wall,
        ms_per_frame: wall * 1e3 / frames as f64,
        handling_ms_per_frame: handling_ms,
        solve_ms_per_frame: solve_ms,
        pair_seconds_per_wall_second: run.worlds as f64 * sim / wall,
        real_time_factor_per_world: sim / wall,
        nut_descent_mm: (z0 - s.body_q[0].p[2]) as f64 * 1e3,
        nut_turns: yaw.radians / std::f64::consts::TAU,
        analytic_descent_mm: 0.5 * 9.81 * m / (m + i * k * k) * sim * sim * 1e3,
        max_penetration_mm: (-deepest as f64 * 1e3).max(0.0),
        nut_mass_kg: mp.mass,
        nut_inertia_axis_kgm2: mp.inertia.z_axis.z,
        pitch_mm: p * 1e3,
        finite,
        adapter: gpu.info.name.clone(),
    })
}

/// The solver settings of a scene report, as Table II gives them (flattened into the report's JSON).
#[derive(Clone, Debug, serde::Serialize)]
pub struct SolverColumns {
    /// Frame time step [s].
    pub dt: f32,
    pub substeps: u32,
    pub pos_iters: u32,
    pub vel_iters: u32,
    pub patch_iters: u32,
    pub friction_per_patch: bool,
}

impl From<&SolverConfig> for SolverColumns {
    fn from(c: &SolverConfig) -> Self {
        SolverColumns {
            dt: c.dt,
            substeps: c.substeps,
            pos_iters: c.pos_iters,
            vel_iters: c.vel_iters,
            patch_iters: c.patch_iters,
            friction_per_patch: c.friction_per_patch,
        }
    }
}

/// Accumulated rotation about z of a body sampled once per frame (less than half a turn per frame).
#[derive(Clone, Copy, Debug, Default)]
pub struct TurnCounter {
    /// Signed total angle [rad] (negative = clockwise seen from +z).
    pub radians: f64,
    last: f64,
}

impl TurnCounter {
    /// Adds the rotation since the previous sample of `pose`.
    pub fn update(&mut self, pose: &factory_engine::contact::TransformGpu) {
        let q = Quat::from_xyzw(pose.q[0], pose.q[1], pose.q[2], pose.q[3]);
        let (axis, angle) = q.to_axis_angle();
        let now = (angle * axis.z.signum()) as f64;
        let mut d = now - self.last;
        d -= std::f64::consts::TAU * (d / std::f64::consts::TAU).round();
        self.radians += d;
        self.last = now;
    }
}

/// Writes `state`, runs one untimed frame and writes `state` again: lavapipe compiles the kernels at their
/// first dispatch (for up to minutes on a cold shader cache), which must not count as a frame.
pub fn warm_up(gpu: &GpuContext, pipe: &ContactPipeline, solver: &GpuSolver, state: &BodyState) {
    solver.write_state(gpu, pipe, state);
    solver.submit_frame(gpu, pipe);
    gpu.wait();
    solver.write_state(gpu, pipe, state);
}

/// Table I's split of a frame, timed on the current state: contact handling alone, then the solver step
/// alone, each over `frames` frames recorded into one submission [ms per frame].
pub fn time_split(gpu: &GpuContext, pipe: &ContactPipeline, solver: &GpuSolver, frames: u32) -> (f64, f64) {
    time_parts(gpu, frames, &|enc| pipe.encode(enc), &|enc| solver.encode(enc))
}

/// Two parts of a frame, each alone over `frames` frames recorded into one submission [ms per frame].
pub fn time_parts(
    gpu: &GpuContext,
    frames: u32,
    a: &dyn Fn(&mut factory_engine::wgpu::CommandEncoder),
    b: &dyn Fn(&mut factory_engine::wgpu::CommandEncoder),
) -> (f64, f64) {
    let time = |record: &dyn Fn(&mut factory_engine::wgpu::CommandEncoder)| {
        let t = Instant::now();
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        for _ in 0..frames {
            record(&mut enc);
        }
        gpu.queue.submit([enc.finish()]);
        gpu.wait();
        t.elapsed().as_secs_f64() * 1e3 / frames as f64
    };
    (time(a), time(b))
}

/// Deepest contact over every pair and world.
pub fn min_depth_all(c: &factory_engine::contact::ContactsHost) -> Option<f32> {
    c.patches.iter().flat_map(|ps| ps.iter().flat_map(|p| p.contacts.iter().map(|c| c.depth))).reduce(f32::min)
}

//! Rigid bodies and an articulation stepped together on the GPU (articulated.wgsl): the device twin of
//! [`super::step_cpu_articulated`], so a Franka gripping a nut on its bolt steps without a round trip to
//! the host. `engine/tests/articulated_gpu.rs` checks it against the CPU reference.
//!
//! Algorithm: the host's, step for step (module docs of [`super`] and
//! [`crate::articulation::dynamics::ContactResponse`]); parity is a matter of float rounding. Two forms
//! differ: the CPU keeps each row's impulse directions with their effective masses and the twist change
//! they make on every body (`RowDirection`), computed once per sample; the kernel recomputes them from the K
//! blocks at every update, for rows with one link side (a pair of two link bodies is refused: the
//! pads of one hand never touch, and the kernel stays small enough for lavapipe to compile; written out
//! for both sides at once its LLVM compile runs past 10 minutes). On a GPU that is arithmetic on values in
//! registers and private memory, where a cache would be loads from device memory (solver_core.wgsl: on
//! lavapipe too, loads are what cost).
//!
//! Layout: one invocation per world ([`SOLVER_WG`] per workgroup). Bind group 0 the model: the solver's
//! uniform, pairs, SDF values and bodies (storage), the articulation's uniform, links and dofs (uniform
//! arrays sized [`MAX_LINKS`] and [`MAX_DOFS`]) and the coupling (which bodies are links); group 1 the
//! contacts (patches, counts); group 2 the state: body poses (the contact pipeline's `body_q`), body
//! velocities and the scratch buffer (status, wrenches, rows, then the joints' positions, velocities,
//! torques and drive targets). Storage buffers: 8, the engine's per-stage minimum.
//!
//! GPU cost, beyond solver.wgsl's: per substep and world the articulation's dynamics
//! (articulation/gpu.rs: ~5k flops), each link body's Jacobian and 6 Cholesky substitutions, and the
//! slot_count^2 K blocks (9 x 36 multiply-adds each for the Franka): ~10k flops. Per update of a row on
//! a link, per direction, slot_count products of a 6 x 6 block (~80 multiply-adds for two fingers) in
//! place of solver.wgsl's few cross products; the fingers' rows are few (a pad's one or two patches) but
//! swept `link_patch_iters` times. Private memory per invocation: the articulation's ~2 KiB touched plus
//! 4 KiB of Jacobians, Y and K for 4 slots: local memory on a GPU, cached in L1. A frame is one dispatch
//! per substep (state between them in storage), which also bounds the work one invocation does.
//!
//! On lavapipe (the CPU fallback) control flow does not skip: both sides of a branch run under a lane
//! mask, and a loop runs its body at least once. Hence K's columns, the links' twists and the impulse
//! tallies are read at constant indices only (a single run-time index puts a private array in memory),
//! and the sweeps visit only the pairs with patches (a pass over an empty pair would run a rigid and a
//! link pass, masked); together these make the step about 3 times faster at 128 worlds
//! (docs/BENCHMARKS.md).

use super::gpu::{
    bodies_gpu, clear_world_rows, control_range, rows_offset, solver_constants, solver_params, write_wrenches,
};
use super::gpu::{BodyGpu, ROW_VEC4, SOLVER_WG};
use super::{BodyModel, BodyState, Control, SolverConfig};
use crate::articulation::gpu::{
    chain_len, dofs_gpu, links_gpu, substep_loop_passes, ArticulationParamsGpu, DofGpu, LinkGpu, MAX_DOFS, MAX_LINKS,
};
use crate::articulation::{ArticulationControl, ArticulationModel, ArticulationState, Frame};
use crate::contact::generate::{compute_pipeline_with, shader_source, SdfKinds};
use crate::contact::{ContactPipeline, TransformGpu};
use crate::error::{EngineError, Result};
use crate::gpu::GpuContext;
use bytemuck::{Pod, Zeroable};
use glam::{Quat, Vec3};

pub(crate) const ARTICULATED_WGSL: &str = concat!(
    include_str!("articulated.wgsl"),
    include_str!("solver_sweep.wgsl"),
    include_str!("solver_core.wgsl"),
    include_str!("orthonormal.wgsl"),
    include_str!("../articulation/articulation_core.wgsl"),
    include_str!("../contact/sdf_sample.wgsl"),
    include_str!("../sdf/thread.wgsl"),
    include_str!("../sdf/revolved.wgsl")
);

/// Most link bodies (bodies that are articulation links) per world (articulated.wgsl's MAX_SLOTS).
pub const MAX_SLOTS: usize = 4;
/// Most contact pairs per world (articulated.wgsl's MAX_PAIRS).
pub const MAX_PAIRS: usize = 64;

/// GPU mirror of `Coupling` in articulated.wgsl (a uniform).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct CouplingGpu {
    /// Link bodies per world.
    pub slot_count: u32,
    /// vec4 index of world 0's joint positions in the scratch buffer.
    pub joint_base: u32,
    /// vec4s from the positions to the velocities, torques and targets (world_count * joint_vec4s).
    pub joint_plane: u32,
    /// vec4s per world's joint vector (ceil(dof_count / 4)).
    pub joint_vec4s: u32,
    /// Per slot its body index in the world and its link.
    pub slot_body: [u32; 4],
    pub slot_link: [u32; 4],
    /// Loop passes of one dispatch's articulation work ([`art_loop_passes`]).
    pub art_passes: u32,
    /// The substep the dispatch takes (0-based; a frame is one dispatch per substep).
    pub substep: u32,
    pub _pad: [u32; 2],
}

/// Where [`GpuArticulatedSolver::scratch`] keeps the contact rows (vec4 units): world w's rows of pair p start at
/// vec4 `rows_base + (w * rows_per_world + p * rows_per_pair) * row_vec4`. In a row, vec4 0's w is its pair
/// (u32 bits), vec4 1's xyz its impulses [N s] along the normal n, t1 = n's `any_orthonormal_vector` and n x
/// t1 over the last substep, vec4 2's xyz n (zero for an empty row), vec4 3's w the frame that built it
/// (u32 bits); the world's status (vec4 w of `scratch`) holds the last frame in its w. A pair's slots hold
/// rows of older frames where it had more patches then.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RowsLayout {
    pub rows_base: u32,
    pub rows_per_world: u32,
    pub rows_per_pair: u32,
    pub row_vec4: u32,
}

/// The summed impulse (world frame) of pair `pair`'s rows of frame `frame` among one pair's row slots (slots
/// of patches unused this frame hold older rows).
fn rows_impulse(rows: &[[[f32; 4]; 4]], pair: u32, frame: u32) -> Vec3 {
    rows.iter()
        .filter(|r| r[0][3].to_bits() == pair && r[3][3].to_bits() == frame)
        .map(|r| {
            let n = Vec3::from_slice(&r[2][..3]);
            if n == Vec3::ZERO {
                return Vec3::ZERO;
            }
            let t1 = n.any_orthonormal_vector();
            r[1][0] * n + r[1][1] * t1 + r[1][2] * n.cross(t1)
        })
        .sum()
}

/// Loop passes articulated.wgsl's articulation work takes in one dispatch (one substep: everything but the
/// rows, which the kernel adds from the frame's patch counts), each loop of p passes counted p + 1 as
/// llvmpipe counts them; keep it in step with the shader's loops.
pub fn art_loop_passes(model: &ArticulationModel, slot_links: &[u32]) -> u64 {
    let (nl, n, s) = (model.link_count() as u64, model.dof_count() as u64, slot_links.len() as u64);
    let (core, substitute) = substep_loop_passes(model);
    let chains: u64 = slot_links.iter().map(|&l| chain_len(model, l).0 + 1).sum();
    let build_response =
        (s + 1) + s * ((n + 1) + 7 + 6 * (2 * (n + 1) + substitute)) + chains + (s + 1) + s * (s + 1) + s * s * (n + 1);
    let twists = (s + 1) + s * (n + 1);
    let (fk, place) = (nl + 1, s + 1);
    // Load, the substep (forward kinematics and free velocity in `core`), the second forward kinematics,
    // the twists three times, the impulses twice, the stores and the last substep's checks.
    // find_active_pairs counts with the rows (the kernel's pairs term).
    (n + 1) + place + core + build_response + fk + place + 3 * twists + 2 * twists + 2 * (n + 1) + (s + 1)
}

/// The solver and the articulation of `world_count` worlds on the GPU, over one contact pipeline.
pub struct GpuArticulatedSolver {
    pub cfg: SolverConfig,
    /// Body velocities (linear, angular) [m/s, rad/s], shape [world_count * body_count * 2] vec4; link
    /// bodies get their twist at the step's end.
    pub body_qd: wgpu::Buffer,
    /// Status per world, wrenches, rows, then the joints (see [`CouplingGpu`]).
    pub scratch: wgpu::Buffer,
    pipeline: wgpu::ComputePipeline,
    /// Group 0 per substep (its coupling uniform names the substep), with the drives off and on (the flag
    /// is in the articulation's uniform).
    model_groups: Vec<[wgpu::BindGroup; 2]>,
    contact_group: wgpu::BindGroup,
    state_group: wgpu::BindGroup,
    drives: bool,
    world_count: u32,
    body_count: u32,
    dof_count: u32,
    max_rows: u32,
    pair_count: u32,
    max_patches: u32,
    coupling: CouplingGpu,
}

impl GpuArticulatedSolver {
    /// Builds the coupled step over `contacts` for bodies `model` (whose link bodies name links of
    /// `art`, [`BodyModel::add_articulated`]). Refuses what [`crate::articulation::gpu::validate`] and
    /// [`super::gpu::GpuSolver::new`] refuse, more than [`MAX_SLOTS`] link bodies, a contact pair between two
    /// link bodies, and on a software adapter a step whose loop passes exceed lavapipe's budget before any
    /// contact.
    pub fn new(
        gpu: &GpuContext,
        contacts: &ContactPipeline,
        model: &BodyModel,
        art: &ArticulationModel,
        cfg: &SolverConfig,
    ) -> Result<Self> {
        cfg.validate()?;
        model.validate()?;
        let world_count = contacts.world_count;
        let root = Frame { name: "root".into(), link: 0, offset: (Vec3::ZERO, Quat::IDENTITY) };
        crate::articulation::gpu::validate(art, world_count, &root, cfg.dt, cfg.substeps)?;
        let (slot_bodies, slot_links, pair_count) = link_slots(contacts, model, art)?;
        let max_rows = (pair_count * contacts.cfg.max_patches * 4).max(1);
        let art_passes = art_loop_passes(art, &slot_links);
        let loop_budget = loop_budget(gpu, model, cfg, pair_count, art_passes)?;
        let n = art.dof_count() as u32;
        let (coupling, scratch_bytes) =
            coupling_layout(gpu, contacts, n, max_rows, (&slot_bodies, &slot_links), art_passes)?;
        let sp = solver_params(cfg, model, world_count, pair_count, max_rows, loop_budget);
        let mut bodies: Vec<BodyGpu> = bodies_gpu(model);
        for (s, &b) in slot_bodies.iter().enumerate() {
            bodies[b].flags[1] = s as u32 + 1;
        }
        // The uniform arrays are declared at their bounds: pad the model to them.
        let mut links = links_gpu(art);
        links.resize(MAX_LINKS, LinkGpu::zeroed());
        let mut dofs = dofs_gpu(art);
        dofs.resize(MAX_DOFS, DofGpu::zeroed());
        let none = wgpu::BufferUsages::empty();
        let sp_buf = gpu.uniform_buffer("articulated-solver-params", bytemuck::bytes_of(&sp));
        let bodies_buf = gpu.storage_buffer("articulated-bodies", &bodies, none);
        let art_params = [false, true].map(|on| {
            gpu.uniform_buffer(
                "articulated-art-params",
                bytemuck::bytes_of(&articulation_params(art, cfg, world_count, on)),
            )
        });
        let links_buf = gpu.uniform_buffer("articulated-links", bytemuck::cast_slice(&links));
        let dofs_buf = gpu.uniform_buffer("articulated-dofs", bytemuck::cast_slice(&dofs));
        let coupling_bufs: Vec<wgpu::Buffer> = (0..cfg.substeps)
            .map(|substep| {
                gpu.uniform_buffer("articulated-coupling", bytemuck::bytes_of(&CouplingGpu { substep, ..coupling }))
            })
            .collect();
        let body_qd = gpu.storage_buffer_zeroed("articulated-body_qd", (world_count * contacts.body_count) as u64 * 32);
        let scratch = gpu.storage_buffer_zeroed("articulated-scratch", scratch_bytes);
        let mut constants = solver_constants(cfg).to_vec();
        constants.push(("SLOT_COUNT", slot_bodies.len() as f64));
        constants.push(("LINK_PATCH_ITERS", cfg.patch_iters.max(cfg.link_patch_iters) as f64));
        let pipeline = compute_pipeline_with(
            &gpu.device,
            "articulated-step",
            &shader_source(ARTICULATED_WGSL, contacts.cfg.max_patches, SdfKinds::of(&contacts.flat.pairs)),
            "step",
            &constants,
        );
        let model_groups = coupling_bufs
            .iter()
            .map(|coupling_buf| {
                [0, 1].map(|i| {
                    gpu.bind_group(
                        &pipeline,
                        0,
                        &[
                            &sp_buf,
                            &contacts.pairs,
                            &contacts.sdf_values,
                            &bodies_buf,
                            &art_params[i],
                            &links_buf,
                            &dofs_buf,
                            coupling_buf,
                        ],
                    )
                })
            })
            .collect();
        let contact_group = gpu.bind_group(&pipeline, 1, &[&contacts.patches, &contacts.patch_counts]);
        let state_group = gpu.bind_group(&pipeline, 2, &[&contacts.body_q, &body_qd, &scratch]);
        Ok(GpuArticulatedSolver {
            cfg: cfg.clone(),
            body_qd,
            scratch,
            pipeline,
            model_groups,
            contact_group,
            state_group,
            drives: false,
            world_count,
            body_count: contacts.body_count,
            dof_count: n,
            max_rows,
            pair_count,
            max_patches: contacts.cfg.max_patches,
            coupling,
        })
    }

    /// Where the contact rows sit in `scratch`, for kernels that read their impulses in place (an env's
    /// finger-force observation; [`pair_impulse`](Self::pair_impulse) is the host's reading).
    pub fn rows_layout(&self) -> RowsLayout {
        RowsLayout {
            rows_base: (rows_offset(self.world_count, self.body_count) / 16) as u32,
            rows_per_world: self.max_rows,
            rows_per_pair: self.max_patches * 4,
            row_vec4: ROW_VEC4 as u32,
        }
    }

    /// Where the joints sit in `scratch` (and the link slots): for kernels that read or write them in place
    /// (an env's resets, a hand-over to [`crate::articulation::gpu::ArticulationGpu`]).
    pub fn coupling(&self) -> &CouplingGpu {
        &self.coupling
    }

    fn joint_bytes(&self) -> (u64, u64) {
        (self.coupling.joint_base as u64 * 16, self.coupling.joint_plane as u64 * 16)
    }

    /// A joint vector of every world (shape [world_count * dof_count]) laid out as the kernel reads it.
    fn pack_joints(&self, field: &'static str, v: &[f32]) -> Result<Vec<f32>> {
        let (w, n) = (self.world_count as usize, self.dof_count as usize);
        if v.len() != w * n {
            return Err(EngineError::Config {
                field,
                value: format!("{} entries", v.len()),
                expected: format!("world_count x dof_count = {w} x {n} = {}", w * n),
            });
        }
        let per = 4 * self.coupling.joint_vec4s as usize;
        let mut out = vec![0.0f32; w * per];
        for (world, chunk) in v.chunks(n.max(1)).enumerate().take(w) {
            out[world * per..world * per + chunk.len()].copy_from_slice(chunk);
        }
        Ok(out)
    }

    /// Uploads bodies and joints without touching the warm-start rows (a state the host advanced or edited:
    /// the rows of worlds whose contacts changed are forgotten with [`forget_world`](Self::forget_world)).
    pub fn upload(
        &self,
        gpu: &GpuContext,
        contacts: &ContactPipeline,
        state: &BodyState,
        joints: &ArticulationState,
    ) -> Result<()> {
        let q = self.pack_joints("joint_q", &joints.joint_q)?;
        let qd = self.pack_joints("joint_qd", &joints.joint_qd)?;
        contacts.write_body_q(gpu, &state.body_q);
        let v = crate::gpu::pack_vec3_pairs(&state.body_qd);
        if !v.is_empty() {
            gpu.queue.write_buffer(&self.body_qd, 0, bytemuck::cast_slice(&v));
        }
        let (base, plane) = self.joint_bytes();
        if !q.is_empty() {
            gpu.queue.write_buffer(&self.scratch, base, bytemuck::cast_slice(&q));
            gpu.queue.write_buffer(&self.scratch, base + plane, bytemuck::cast_slice(&qd));
        }
        Ok(())
    }

    /// [`upload`](Self::upload), every world starting cold (a fresh [`super::WarmStart`] on the CPU).
    pub fn write_state(
        &self,
        gpu: &GpuContext,
        contacts: &ContactPipeline,
        state: &BodyState,
        joints: &ArticulationState,
    ) -> Result<()> {
        self.upload(gpu, contacts, state, joints)?;
        let (status, control) = control_range(self.world_count, self.body_count);
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        enc.clear_buffer(&self.scratch, 0, Some(status));
        let rows = self.world_count as u64 * self.max_rows as u64 * ROW_VEC4 * 16;
        enc.clear_buffer(&self.scratch, status + control, Some(rows));
        gpu.queue.submit([enc.finish()]);
        Ok(())
    }

    /// Forgets world `world`'s warm-start rows and status (after it was reset: last frame's impulses
    /// belong to contacts that no longer exist); [`super::WarmStart::clear_world`] on the CPU.
    pub fn forget_world(&self, gpu: &GpuContext, world: u32) {
        assert!(world < self.world_count, "world {world} of {}", self.world_count);
        clear_world_rows(gpu, &self.scratch, (self.world_count, self.body_count, self.max_rows), world);
    }

    /// Sets the body wrenches and the joint torques and drive targets held over the following steps, as
    /// [`super::step_cpu_articulated`] reads them: an empty `joint_tau` is zero torque, an empty
    /// `joint_target_q` turns the drives off.
    pub fn write_control(&mut self, gpu: &GpuContext, control: &Control, joints: &ArticulationControl) -> Result<()> {
        let (base, plane) = self.joint_bytes();
        let tau = if joints.joint_tau.is_empty() {
            vec![0.0; (plane / 4) as usize]
        } else {
            self.pack_joints("joint_tau", &joints.joint_tau)?
        };
        let target = if joints.joint_target_q.is_empty() {
            None
        } else {
            Some(self.pack_joints("joint_target_q", &joints.joint_target_q)?)
        };
        write_wrenches(gpu, &self.scratch, control_range(self.world_count, self.body_count), control);
        if !tau.is_empty() {
            gpu.queue.write_buffer(&self.scratch, base + 2 * plane, bytemuck::cast_slice(&tau));
        }
        if let Some(t) = &target {
            gpu.queue.write_buffer(&self.scratch, base + 3 * plane, bytemuck::cast_slice(t));
        }
        self.drives = target.is_some();
        Ok(())
    }

    /// Records one coupled step (after the contact pipeline's dispatches of the same frame): one dispatch
    /// per substep (within a pass, each dispatch sees the storage writes of the one before).
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder) {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("articulated-solver"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(1, &self.contact_group, &[]);
        pass.set_bind_group(2, &self.state_group, &[]);
        for groups in &self.model_groups {
            pass.set_bind_group(0, &groups[self.drives as usize], &[]);
            pass.dispatch_workgroups(self.world_count.div_ceil(SOLVER_WG), 1, 1);
        }
    }

    /// Per world, whether its last step was skipped for lavapipe's loop budget (as
    /// [`super::gpu::GpuSolver::worlds_over_loop_budget`]).
    pub fn worlds_over_loop_budget(&self, gpu: &GpuContext) -> Vec<bool> {
        super::gpu::worlds_over_loop_budget(gpu, &self.scratch, self.world_count)
    }

    /// The total contact impulse [N s] (normal and friction, world frame) the last substep of the last
    /// step applied to pair `pair`'s query body in world `world` ([`super::WarmStart::pair_impulse`]):
    /// reads that world's rows of the pair back (waits for the GPU).
    pub fn pair_impulse(&self, gpu: &GpuContext, world: u32, pair: u32) -> Vec3 {
        assert!(world < self.world_count && pair < self.pair_count, "world {world}, pair {pair}");
        let frame = gpu.read_buffer_range::<[u32; 4]>(&self.scratch, world as u64 * 16, 16)[0][3];
        let rows_per_pair = self.max_patches as u64 * 4;
        let first = rows_offset(self.world_count, self.body_count)
            + (world as u64 * self.max_rows as u64 + pair as u64 * rows_per_pair) * ROW_VEC4 * 16;
        let rows: Vec<[[f32; 4]; 4]> = gpu.read_buffer_range(&self.scratch, first, rows_per_pair * ROW_VEC4 * 16);
        rows_impulse(&rows, pair, frame)
    }

    /// [`pair_impulse`](Self::pair_impulse) of each of `pairs` in every world, shape [world_count *
    /// pairs.len()] (world-major), from one readback of the status and every world's rows.
    pub fn pair_impulses(&self, gpu: &GpuContext, pairs: &[usize]) -> Vec<Vec3> {
        assert!(pairs.iter().all(|&p| p < self.pair_count as usize), "pairs {pairs:?} of {}", self.pair_count);
        let status: Vec<[u32; 4]> = gpu.read_buffer_prefix(&self.scratch, self.world_count as u64 * 16);
        let rows_bytes = self.world_count as u64 * self.max_rows as u64 * ROW_VEC4 * 16;
        let rows: Vec<[[f32; 4]; 4]> =
            gpu.read_buffer_range(&self.scratch, rows_offset(self.world_count, self.body_count), rows_bytes);
        let rows_per_pair = self.max_patches as usize * 4;
        (0..self.world_count as usize)
            .flat_map(|w| pairs.iter().map(move |&p| (w, p)))
            .map(|(w, p)| {
                let first = w * self.max_rows as usize + p * rows_per_pair;
                rows_impulse(&rows[first..first + rows_per_pair], p as u32, status[w][3])
            })
            .collect()
    }

    /// Reads bodies, joints and per-world status back (waits for the GPU): ok is false for a world that
    /// went non-finite or over the speed bound (joints included), or was skipped.
    pub fn read_state(
        &self,
        gpu: &GpuContext,
        contacts: &ContactPipeline,
    ) -> (BodyState, ArticulationState, Vec<bool>) {
        let n = (self.world_count * self.body_count) as usize;
        let q: Vec<TransformGpu> = gpu.read_buffer(&contacts.body_q);
        let qd: Vec<[f32; 4]> = gpu.read_buffer(&self.body_qd);
        let status: Vec<[f32; 4]> = gpu.read_buffer_prefix(&self.scratch, self.world_count as u64 * 16);
        let (base, plane) = self.joint_bytes();
        let joints: Vec<f32> = gpu.read_buffer_range(&self.scratch, base, 2 * plane);
        let (w, dof, per) =
            (self.world_count as usize, self.dof_count as usize, 4 * self.coupling.joint_vec4s as usize);
        let unpack = |v: &[f32]| (0..w).flat_map(|i| v[i * per..i * per + dof].to_vec()).collect::<Vec<f32>>();
        let plane_f = (plane / 4) as usize;
        let art =
            ArticulationState { joint_q: unpack(&joints[..plane_f]), joint_qd: unpack(&joints[plane_f..2 * plane_f]) };
        let ok = status.iter().map(|s| s[0] == 1.0).collect();
        (BodyState { body_q: q[..n].to_vec(), body_qd: crate::gpu::unpack_vec3_pairs(&qd[..2 * n]) }, art, ok)
    }
}

/// The coupling's link bodies (in slot order) and their links, and the contact pairs per world; refuses
/// a body model that is not the contact model's, more than [`MAX_SLOTS`] link bodies, a link outside `art`,
/// a pair between two link bodies and more than [`MAX_PAIRS`] pairs.
fn link_slots(
    contacts: &ContactPipeline,
    model: &BodyModel,
    art: &ArticulationModel,
) -> Result<(Vec<usize>, Vec<u32>, u32)> {
    if model.body_count() as u32 != contacts.body_count {
        return Err(EngineError::Config {
            field: "body_count",
            value: model.body_count().to_string(),
            expected: format!("the contact model's {} bodies", contacts.body_count),
        });
    }
    let slot_bodies: Vec<usize> = (0..model.body_count()).filter(|&i| model.link(i).is_some()).collect();
    let slot_links: Vec<u32> = slot_bodies.iter().map(|&i| model.link(i).unwrap()).collect();
    if slot_bodies.len() > MAX_SLOTS {
        return Err(EngineError::Config {
            field: "body_link",
            value: format!("{} link bodies", slot_bodies.len()),
            expected: format!("at most {MAX_SLOTS} bodies that are articulation links (the GPU kernel's bound)"),
        });
    }
    if let Some(&l) = slot_links.iter().find(|&&l| l as usize >= art.link_count()) {
        return Err(EngineError::Config {
            field: "body_link",
            value: format!("link {l}"),
            expected: format!("a link of '{}' (0..{})", art.name, art.link_count()),
        });
    }
    let is_link = |b: u32| b != crate::contact::NO_BODY && model.link(b as usize).is_some();
    if let Some(p) = contacts.flat.pairs.iter().position(|p| is_link(p.body_a) && is_link(p.body_b)) {
        return Err(EngineError::Config {
            field: "pairs",
            value: format!("pair {p} between two link bodies"),
            expected: "at most one articulation link per contact pair on the GPU solver (filter the pair, or \
                       solve on the host with solver::step_cpu_articulated)"
                .into(),
        });
    }
    let pair_count = contacts.flat.pairs.len() as u32;
    if pair_count as usize > MAX_PAIRS {
        return Err(EngineError::Config {
            field: "pairs",
            value: format!("{pair_count} contact pairs per world"),
            expected: format!("at most {MAX_PAIRS} (articulated.wgsl's MAX_PAIRS)"),
        });
    }
    Ok((slot_bodies, slot_links, pair_count))
}

/// lavapipe's loop budget per invocation (0 on a hardware adapter), checked against the first substep's
/// dispatch with no contact (it also builds the rows; [`super::gpu::GpuSolver::new`]): refused here only what
/// no frame could take.
fn loop_budget(
    gpu: &GpuContext,
    model: &BodyModel,
    cfg: &SolverConfig,
    pair_count: u32,
    art_passes: u64,
) -> Result<u32> {
    let loop_budget = if gpu.is_software() { crate::contact::LOOP_ITERATION_LIMIT / 8 * 7 } else { 0 };
    if loop_budget > 0 {
        let (pairs, bodies) = (pair_count as u64 + 1, model.body_count() as u64 + 1);
        let sweeps = (cfg.pos_iters + cfg.vel_iters + 1) as u64;
        // The first substep's dispatch, which also builds the rows.
        let passes = 4 * pairs + (sweeps * (pairs + 2) + 4 * pairs + 2 * bodies + 1) + bodies + art_passes + 2;
        if passes > loop_budget as u64 {
            return Err(EngineError::Config {
                field: "substeps x (pos_iters + vel_iters) x pairs",
                value: format!(
                    "({} + {}) x {pair_count} = {passes} loop passes per substep with the articulation, before any contact",
                    cfg.pos_iters, cfg.vel_iters
                ),
                expected: format!(
                    "at most {loop_budget} on a software adapter (llvmpipe's loop limit); use fewer iterations or shape pairs per world"
                ),
            });
        }
    }
    Ok(loop_budget)
}

/// The coupling uniform (the joints after the rows in the scratch buffer) and the scratch buffer's size
/// [bytes] for `n` joints and `max_rows` rows per world; refuses a scratch buffer over the device's binding
/// limit.
fn coupling_layout(
    gpu: &GpuContext,
    contacts: &ContactPipeline,
    n: u32,
    max_rows: u32,
    (slot_bodies, slot_links): (&[usize], &[u32]),
    art_passes: u64,
) -> Result<(CouplingGpu, u64)> {
    let world_count = contacts.world_count;
    let joint_vec4s = n.div_ceil(4).max(1);
    let rows_end = rows_offset(world_count, contacts.body_count) + world_count as u64 * max_rows as u64 * ROW_VEC4 * 16;
    let joint_plane = world_count * joint_vec4s;
    let scratch_bytes = rows_end + 4 * joint_plane as u64 * 16;
    if scratch_bytes > gpu.limits().max_storage_buffer_binding_size {
        return Err(EngineError::TooLarge {
            what: format!("solver rows and joints for {world_count} worlds x {max_rows} contacts"),
            needed_bytes: scratch_bytes,
            limit_bytes: gpu.limits().max_storage_buffer_binding_size,
            hint: "use fewer worlds per pipeline or a smaller max_patches".into(),
        });
    }
    let mut slot_body = [0u32; 4];
    let mut slot_link = [0u32; 4];
    for (s, (&b, &l)) in slot_bodies.iter().zip(slot_links).enumerate() {
        slot_body[s] = b as u32;
        slot_link[s] = l;
    }
    let coupling = CouplingGpu {
        slot_count: slot_bodies.len() as u32,
        joint_base: (rows_end / 16) as u32,
        joint_plane,
        joint_vec4s,
        slot_body,
        slot_link,
        art_passes: art_passes.min(u32::MAX as u64) as u32,
        substep: 0,
        _pad: [0; 2],
    };
    Ok((coupling, scratch_bytes))
}

/// The articulation's uniform for the kernel, with the joint drives off or on.
fn articulation_params(
    art: &ArticulationModel,
    cfg: &SolverConfig,
    world_count: u32,
    drives: bool,
) -> ArticulationParamsGpu {
    ArticulationParamsGpu {
        world_count,
        link_count: art.link_count() as u32,
        dof_count: art.dof_count() as u32,
        frame_link: 0,
        frame_p: [0.0; 4],
        frame_q: [0.0, 0.0, 0.0, 1.0],
        gravity: art.gravity.extend(0.0).to_array(),
        dt: cfg.dt,
        substeps: cfg.substeps,
        drives: drives as u32,
        dynamics_stride: 0,
        jacobian_offset: 0,
        mass_offset: 0,
        gravity_offset: 0,
        coriolis_offset: 0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The kernel parses and validates with naga for every SDF-kind combination (no GPU needed).
    #[test]
    fn articulated_shader_validates_with_naga() {
        for kinds in SdfKinds::combinations() {
            let src = shader_source(ARTICULATED_WGSL, 8, kinds);
            if let Err(e) = crate::contact::shader_tests::validate(&src, false) {
                panic!("articulated.wgsl ({kinds:?}):\n{e}");
            }
        }
    }

    /// The Pod mirror has the size and field offsets naga lays `Coupling` out with.
    #[test]
    fn coupling_matches_its_mirror() {
        let module = naga::front::wgsl::parse_str(&shader_source(ARTICULATED_WGSL, 8, SdfKinds::default())).unwrap();
        let mut layouter = naga::proc::Layouter::default();
        layouter.update(module.to_ctx()).unwrap();
        let (h, ty) = module.types.iter().find(|(_, t)| t.name.as_deref() == Some("Coupling")).unwrap();
        let naga::TypeInner::Struct { members, .. } = &ty.inner else { panic!("Coupling is a struct") };
        assert_eq!(layouter[h].size as usize, std::mem::size_of::<CouplingGpu>());
        let offsets: Vec<u32> = members.iter().map(|m| m.offset).collect();
        assert_eq!(offsets, [0, 4, 8, 12, 16, 32, 48, 52, 56, 60]);
        assert_eq!(std::mem::offset_of!(CouplingGpu, substep), 52);
    }
}

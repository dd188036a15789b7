//! The many-body world on the GPU (near.wgsl, contacts.wgsl, solve.wgsl): buffers, pipelines and the
//! per-frame dispatches. The CPU twin is [`super::ManyBodyCpu`]; `engine/tests/many_body.rs` checks parity,
//! the colouring and bitwise determinism.

use super::{ManyBodyConfig, ManyBodyFlat, ManyBodyFrame, ManyBodyModel, NearPair, RestState, COLOUR_NONE, UNCOLOURED};
use crate::contact::model::{PairGpu, PatchGpu};
use crate::contact::pipeline::to_patches;
use crate::contact::{ContactConfig, Patch, TransformGpu};
use crate::error::Result;
use crate::gpu::GpuContext;
use crate::solver::{BodyModel, BodyState, Control, SolverConfig};
use bytemuck::{Pod, Zeroable};
use glam::Vec3;

const MANY_BODY_COMMON: &str = include_str!("many_body_common.wgsl");
const NEAR_WGSL: &str = include_str!("near.wgsl");
const CONTACTS_WGSL: &str = concat!(
    include_str!("contacts.wgsl"),
    include_str!("../contact/generate_core.wgsl"),
    include_str!("../contact/sdf_sample.wgsl"),
    include_str!("../sdf/thread.wgsl"),
    include_str!("../sdf/revolved.wgsl")
);
const MERGE_WGSL: &str = concat!(include_str!("merge.wgsl"), include_str!("../contact/merge_core.wgsl"));
const SOLVE_WGSL: &str = concat!(
    include_str!("solve.wgsl"),
    include_str!("../solver/solver_core.wgsl"),
    include_str!("../solver/orthonormal.wgsl"),
    include_str!("../contact/sdf_sample.wgsl"),
    include_str!("../sdf/thread.wgsl"),
    include_str!("../sdf/revolved.wgsl")
);

/// Words at the head of a world's meta block (many_body_common.wgsl's M_HEAD).
const M_HEAD: u32 = 64;
const M_COUNT: usize = 0;
const M_FLAGS: usize = 1;
const M_COLOURS: usize = 3;
const M_PATCHES: usize = 4;
/// Per-pair arrays of a world's meta block, by their place after the per-body arrays
/// (many_body_common.wgsl's m_colour, m_patch_count, m_candidates).
const P_COLOUR: u32 = 1;
const P_PATCH_COUNT: u32 = 5;
const P_CANDIDATES: u32 = 6;
/// Indirect arguments (many_body_common.wgsl's A_*): pairs, generate, merge, then 32 colours.
const A_PAIRS: u64 = 0;
const A_GENERATE: u64 = 3;
const A_MERGE: u64 = 6;
const A_COLOUR: u64 = 9;
const ARGS_WORDS: u64 = A_COLOUR + 3 * 32;
/// Solver pass phases [warm, bias, resample]: warm and resample pick the many_body_pass entry point, bias goes to
/// the phase's uniform slot (PassParams), one slot per phase and colour.
const PHASES: [[u32; 3]; 5] = [[1, 1, 0], [0, 1, 1], [0, 1, 0], [0, 0, 1], [0, 0, 0]];

/// GPU mirror of `ManyBodyParams` in many_body_common.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct ManyBodyParamsGpu {
    pub world_count: u32,
    pub body_count: u32,
    pub cap: u32,
    pub jobs_per_pair: u32,
    pub chunk: u32,
    pub class_count: u32,
    pub static_count: u32,
    pub max_colours: u32,
    pub meta_stride: u32,
    pub patch_budget: u32,
    pub sleep_frames: u32,
    pub sleep_distance: f32,
    pub sleep_half_cos: f32,
    /// vec4 index of the sleeping state in the solver scratch.
    pub rest_base: u32,
    pub _pad: [u32; 2],
}

/// GPU mirror of `PassParams` in many_body_common.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct PassParamsGpu {
    index: u32,
    bias: u32,
    _pad: [u32; 2],
}

/// Figures of one world's last frame, read back for reports.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ManyBodyStats {
    /// Near pairs in the list.
    pub pairs: u32,
    /// Near pairs with at least one patch.
    pub touching_pairs: u32,
    /// Contact candidates before reduction, all pairs.
    pub candidates: u64,
    /// Patches after reduction, all pairs.
    pub patches: u32,
    /// Contacts after reduction, all pairs.
    pub contacts: u32,
    pub colours: u32,
    pub flags: u32,
}

/// Buffers and pipelines of many-body worlds (see the module doc of [`super`]).
pub struct ManyBodyPipeline {
    pub flat: ManyBodyFlat,
    pub cfg: ManyBodyConfig,
    pub contact: ContactConfig,
    pub solver: SolverConfig,
    pub world_count: u32,
    pub body_count: u32,
    params: ManyBodyParamsGpu,
    /// Body poses, shape [world_count * body_count].
    pub body_q: wgpu::Buffer,
    /// Body velocities (linear, angular) [m/s, rad/s], shape [world_count * body_count * 2] vec4.
    pub body_qd: wgpu::Buffer,
    /// Status per world, external wrenches, two blocks of rows (solve.wgsl).
    pub scratch: wgpu::Buffer,
    /// Near-pair records, shape [world_count * max_pairs].
    pub many_body_pairs: wgpu::Buffer,
    /// Per-world bookkeeping (many_body_common.wgsl).
    pub meta: wgpu::Buffer,
    /// Reduced patches, shape [world_count * max_pairs * max_patches].
    pub patches: wgpu::Buffer,
    args: wgpu::Buffer,
    pass_stride: u64,
    near: [wgpu::ComputePipeline; 8],
    contacts: [wgpu::ComputePipeline; 2],
    merge: wgpu::ComputePipeline,
    solve: [wgpu::ComputePipeline; 9],
    near_groups: Vec<wgpu::BindGroup>,
    round_groups: Vec<wgpu::BindGroup>,
    contact_groups: Vec<wgpu::BindGroup>,
    merge_groups: Vec<wgpu::BindGroup>,
    solve_groups: Vec<wgpu::BindGroup>,
}

/// Byte offset of the sleeping state in a many-body world's scratch buffer: after the status, the wrenches and the two
/// blocks of rows (solve.wgsl's rest_index).
fn rest_offset(world_count: u32, body_count: u32, cfg: &ManyBodyConfig) -> u64 {
    crate::solver::gpu::rows_offset(world_count, body_count) + 2 * world_count as u64 * world_rows_bytes(cfg)
}

/// Bytes of one world's rows in one of the scratch buffer's two blocks.
fn world_rows_bytes(cfg: &ManyBodyConfig) -> u64 {
    cfg.max_patches_per_world as u64 * 4 * crate::solver::gpu::ROW_VEC4 * 16
}

mod setup;

use setup::{check_sizes, fit_jobs, many_body_params, Kernels, Storage, Uniforms};

impl ManyBodyPipeline {
    /// Validates the settings against the model and the device, uploads the model, builds the pipelines.
    pub fn new(
        gpu: &GpuContext,
        model: &ManyBodyModel,
        bodies: &BodyModel,
        world_count: u32,
        cfg: &ManyBodyConfig,
        contact: &ContactConfig,
        solver: &SolverConfig,
    ) -> Result<Self> {
        super::check_setup(model, bodies, cfg, solver)?;
        let flat = fit_jobs(gpu, model, world_count, cfg, contact)?;
        let n = model.body_count;
        check_sizes(gpu, &flat, world_count, n, cfg, contact)?;
        let params = many_body_params(model, &flat, world_count, cfg);
        let (uniforms, pass_stride) = Uniforms::new(gpu, &params, bodies, cfg, contact, solver);
        let storage = Storage::new(gpu, model, bodies, &flat, &params, cfg, contact);
        let kernels = Kernels::new(gpu, &flat, cfg, contact, solver);
        let [near_groups, round_groups, contact_groups, merge_groups, solve_groups] =
            kernels.bind_groups(gpu, &uniforms, &storage);
        let Storage { body_q, body_qd, scratch, many_body_pairs, meta, patches, args, .. } = storage;
        let Kernels { near, contacts, merge, solve, .. } = kernels;
        Ok(ManyBodyPipeline {
            flat,
            cfg: cfg.clone(),
            contact: contact.clone(),
            solver: solver.clone(),
            world_count,
            body_count: n,
            params,
            body_q,
            body_qd,
            scratch,
            many_body_pairs,
            meta,
            patches,
            args,
            pass_stride,
            near,
            contacts,
            merge,
            solve,
            near_groups,
            round_groups,
            contact_groups,
            merge_groups,
            solve_groups,
        })
    }

    /// Uploads a state; every world starts cold (no warm-start impulses, an empty last-frame list).
    pub fn write_state(&self, gpu: &GpuContext, state: &BodyState) {
        let n = (self.world_count * self.body_count) as usize;
        assert_eq!(state.body_q.len(), n, "body_q shape [world_count * body_count]");
        assert_eq!(state.body_qd.len(), n, "body_qd shape [world_count * body_count]");
        self.forget_warm_start(gpu);
        crate::solver::gpu::write_world_bodies(gpu, &self.body_q, &self.body_qd, 0, &state.body_q, &state.body_qd);
    }

    /// Forgets every world's warm-start impulses and last frame's pairs; the external wrenches stay.
    pub fn forget_warm_start(&self, gpu: &GpuContext) {
        let (status, control) = self.control_range();
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        enc.clear_buffer(&self.scratch, 0, Some(status));
        enc.clear_buffer(&self.scratch, status + control, None);
        enc.clear_buffer(&self.meta, 0, None);
        gpu.queue.submit([enc.finish()]);
    }

    /// Resets world `world` alone (the auto-reset of one finished or diverged world): its poses and
    /// velocities (shape [body_count] each), status, warm-start rows and last frame's pairs; every other
    /// world, and the external wrenches, stay as they are.
    pub fn reset_world(&self, gpu: &GpuContext, world: u32, body_q: &[TransformGpu], body_qd: &[[Vec3; 2]]) {
        assert!(world < self.world_count, "world {world} of {}", self.world_count);
        let n = self.body_count as usize;
        assert!(body_q.len() == n && body_qd.len() == n, "one world's bodies: shape [body_count = {n}]");
        crate::solver::gpu::write_world_bodies(gpu, &self.body_q, &self.body_qd, world, body_q, body_qd);
        let (w, wc) = (world as u64, self.world_count as u64);
        let rows = world_rows_bytes(&self.cfg);
        let rows_offset = crate::solver::gpu::rows_offset(self.world_count, self.body_count);
        let stride = self.params.meta_stride as u64 * 4;
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        enc.clear_buffer(&self.scratch, w * 16, Some(16));
        for block in 0..2 {
            enc.clear_buffer(&self.scratch, rows_offset + (block * wc + w) * rows, Some(rows));
        }
        let (rest, rest_world) = self.rest_range();
        enc.clear_buffer(&self.scratch, rest + w * rest_world, Some(rest_world));
        enc.clear_buffer(&self.meta, w * stride, Some(stride));
        gpu.queue.submit([enc.finish()]);
    }

    fn control_range(&self) -> (u64, u64) {
        crate::solver::gpu::control_range(self.world_count, self.body_count)
    }

    /// Byte offset of the sleeping state in the scratch buffer and its bytes per world.
    fn rest_range(&self) -> (u64, u64) {
        (rest_offset(self.world_count, self.body_count, &self.cfg), self.body_count as u64 * 32)
    }

    /// Every body's sleeping state, shape [world_count * body_count] (waits; for tests and reports).
    pub fn read_rest(&self, gpu: &GpuContext) -> Vec<RestState> {
        let (offset, per_world) = self.rest_range();
        let raw: Vec<[f32; 4]> = gpu.read_buffer_range(&self.scratch, offset, per_world * self.world_count as u64);
        raw.chunks_exact(2)
            .map(|r| RestState { com: Vec3::from_slice(&r[0][..3]), rot: glam::Vec4::from_array(r[1]), count: r[0][3] })
            .collect()
    }

    /// Sets the external wrenches (as [`crate::solver::gpu::GpuSolver::write_control`]).
    pub fn write_control(&self, gpu: &GpuContext, control: &Control) {
        crate::solver::gpu::write_wrenches(gpu, &self.scratch, self.control_range(), control);
    }

    fn pass_offset(&self, slot: u32) -> u32 {
        (slot as u64 * self.pass_stride) as u32
    }

    /// Records one frame: [`encode_handling`](Self::encode_handling), then [`encode_solve`](Self::encode_solve).
    pub fn encode(&self, enc: &mut wgpu::CommandEncoder) {
        self.encode_handling(enc);
        self.encode_solve(enc);
    }

    fn set(
        &self,
        pass: &mut wgpu::ComputePass,
        k: &wgpu::ComputePipeline,
        groups: &[wgpu::BindGroup],
        slot: Option<u32>,
    ) {
        pass.set_pipeline(k);
        for (i, g) in groups.iter().enumerate() {
            // Group 3 is the per-dispatch parameters (a dynamic offset into the pass slots).
            let offsets = [self.pass_offset(slot.unwrap_or(0))];
            pass.set_bind_group(i as u32, g, if i == 3 { &offsets[..] } else { &[] });
        }
    }

    /// Contact handling (paper Table I: pair finding, generation, reduction): near pairs, then contacts.
    pub fn encode_handling(&self, enc: &mut wgpu::CommandEncoder) {
        enc.clear_buffer(&self.args, 0, None);
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("many_body-handling"),
            timestamp_writes: None,
        });
        let (wc, bodies_x) = (self.world_count, self.body_count.div_ceil(64));
        let ng = &self.near_groups;
        let grid = [
            (self.cfg.max_pairs.div_ceil(64), wc), // keep_keys
            (bodies_x, wc),                        // near_count
            (wc, 1),                               // near_scan
            (bodies_x, wc),                        // near_emit
        ];
        for (k, (x, y)) in self.near[..4].iter().zip(grid) {
            self.set(&mut pass, k, ng, None);
            pass.dispatch_workgroups(x, y, 1);
        }
        if self.cfg.sleep.enabled() {
            // Wake sleepers near bodies that moved, then leave out the pairs whose bodies all sleep.
            self.set(&mut pass, &self.solve[7], &self.solve_groups, None);
            pass.dispatch_workgroups_indirect(&self.args, A_PAIRS * 4);
            // (Dispatched from many_body_args: it binds the stand-in, as the colouring rounds.)
            self.set(&mut pass, &self.near[7], &self.round_groups, None);
            pass.dispatch_workgroups_indirect(&self.args, A_PAIRS * 4);
        }
        let cg = &self.contact_groups;
        self.set(&mut pass, &self.contacts[0], cg, None);
        pass.dispatch_workgroups_indirect(&self.args, A_GENERATE * 4);
        self.set(&mut pass, &self.merge, &self.merge_groups, None);
        pass.dispatch_workgroups_indirect(&self.args, A_MERGE * 4);
        self.set(&mut pass, &self.contacts[1], cg, None);
        pass.dispatch_workgroups(wc.div_ceil(64), 1, 1);
    }

    /// Contact solution (Table I: constraint preparation, iterative solution, integration): the colouring,
    /// the rows, the coloured sweeps and integration, the status.
    pub fn encode_solve(&self, enc: &mut wgpu::CommandEncoder) {
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("many_body-solve"),
            timestamp_writes: None,
        });
        let (wc, bodies_x) = (self.world_count, self.body_count.div_ceil(64));
        let ng = &self.near_groups;
        self.set(&mut pass, &self.near[4], ng, None);
        pass.dispatch_workgroups(bodies_x, wc, 1);
        for r in 0..self.cfg.colour_rounds {
            self.set(&mut pass, &self.near[5], &self.round_groups, Some(r));
            pass.dispatch_workgroups_indirect(&self.args, A_PAIRS * 4);
        }
        self.set(&mut pass, &self.near[6], ng, None);
        pass.dispatch_workgroups(wc.div_ceil(64), 1, 1);
        let sg = &self.solve_groups;
        self.set(&mut pass, &self.solve[0], sg, None);
        pass.dispatch_workgroups_indirect(&self.args, A_PAIRS * 4);
        let sweep = |pass: &mut wgpu::ComputePass, phase: u32| {
            // The entry point for the phase's warm and resample flags (solve.wgsl many_body_pass*).
            let kernel = match PHASES[phase as usize] {
                [1, _, _] => &self.solve[6],
                [0, _, 1] => &self.solve[5],
                _ => &self.solve[2],
            };
            for c in 0..self.cfg.max_colours {
                self.set(pass, kernel, sg, Some(self.cfg.colour_rounds + phase * 32 + c));
                pass.dispatch_workgroups_indirect(&self.args, (A_COLOUR + 3 * c as u64) * 4);
            }
        };
        for _ in 0..self.solver.substeps {
            self.set(&mut pass, &self.solve[1], sg, None);
            pass.dispatch_workgroups(bodies_x, wc, 1);
            sweep(&mut pass, 0);
            for it in 0..self.solver.pos_iters {
                sweep(&mut pass, if it == 0 { 1 } else { 2 });
            }
            self.set(&mut pass, &self.solve[3], sg, None);
            pass.dispatch_workgroups(bodies_x, wc, 1);
            for it in 0..self.solver.vel_iters {
                sweep(&mut pass, if it == 0 { 3 } else { 4 });
            }
        }
        if self.cfg.sleep.enabled() {
            self.set(&mut pass, &self.solve[8], sg, None);
            pass.dispatch_workgroups(bodies_x, wc, 1);
        }
        self.set(&mut pass, &self.solve[4], sg, None);
        pass.dispatch_workgroups(wc.div_ceil(64), 1, 1);
    }

    /// Encodes and submits one frame.
    pub fn submit_frame(&self, gpu: &GpuContext) {
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        self.encode(&mut enc);
        gpu.queue.submit([enc.finish()]);
    }

    /// Poses, velocities and per world whether it is ok (stepped, finite, below max_speed); waits.
    pub fn read_state(&self, gpu: &GpuContext) -> (BodyState, Vec<bool>) {
        let q: Vec<TransformGpu> = gpu.read_buffer(&self.body_q);
        let qd: Vec<[f32; 4]> = gpu.read_buffer(&self.body_qd);
        let status: Vec<[f32; 4]> = gpu.read_buffer_prefix(&self.scratch, self.world_count as u64 * 16);
        let body_qd = crate::gpu::unpack_vec3_pairs(&qd);
        (BodyState { body_q: q, body_qd }, status.iter().map(|s| s[0] == 1.0).collect())
    }

    fn meta_words(&self, gpu: &GpuContext) -> Vec<u32> {
        gpu.read_buffer(&self.meta)
    }

    fn world_meta<'a>(&self, meta: &'a [u32], w: u32) -> &'a [u32] {
        let s = self.params.meta_stride as usize;
        &meta[w as usize * s..(w as usize + 1) * s]
    }

    /// Offset of the per-pair arrays in a world's meta block, and of array `k` among them.
    fn pair_array(&self, k: u32) -> usize {
        (M_HEAD + 4 * self.body_count + k * self.cfg.max_pairs) as usize
    }

    /// Each world's last frame: its near pairs, colours and flags (waits; for tests and reports).
    pub fn read_frames(&self, gpu: &GpuContext) -> Vec<ManyBodyFrame> {
        let meta = self.meta_words(gpu);
        let pairs: Vec<PairGpu> = gpu.read_buffer(&self.many_body_pairs);
        (0..self.world_count).map(|w| self.frame_of(&meta, &pairs, w)).collect()
    }

    /// World `w`'s frame from the bookkeeping words and pair records read back.
    fn frame_of(&self, meta: &[u32], pairs: &[PairGpu], w: u32) -> ManyBodyFrame {
        let m = self.world_meta(meta, w);
        let count = m[M_COUNT] as usize;
        let base = (w * self.cfg.max_pairs) as usize;
        let colour = &m[self.pair_array(P_COLOUR)..];
        ManyBodyFrame {
            pairs: pairs[base..base + count]
                .iter()
                .map(|p| NearPair { a: p.body_a, key: p.job_first, b: p.body_b, template: p.many_body_template })
                .collect(),
            colours: colour[..count].iter().map(|&c| if c == UNCOLOURED { COLOUR_NONE } else { c & 0xff }).collect(),
            colour_count: m[M_COLOURS],
            flags: m[M_FLAGS],
        }
    }

    /// Each world's last frame with the reduced patches of each of its near pairs, in list order (waits;
    /// for tests and reports; every buffer is read once). The many-body kernels compute no per-contact
    /// normals: each contact carries its patch's normal.
    pub fn read_patches(&self, gpu: &GpuContext) -> Vec<(ManyBodyFrame, Vec<Vec<Patch>>)> {
        let meta = self.meta_words(gpu);
        let pairs: Vec<PairGpu> = gpu.read_buffer(&self.many_body_pairs);
        let raw: Vec<PatchGpu> = gpu.read_buffer(&self.patches);
        let mp = self.contact.max_patches as usize;
        (0..self.world_count)
            .map(|w| {
                let frame = self.frame_of(&meta, &pairs, w);
                let pc = &self.world_meta(&meta, w)[self.pair_array(P_PATCH_COUNT)..];
                let base = w as usize * self.cfg.max_pairs as usize;
                let patches = (0..frame.pairs.len())
                    .map(|e| {
                        let first = (base + e) * mp;
                        let ps = &raw[first..first + pc[e] as usize];
                        to_patches(ps, |i, _| Vec3::from_slice(&ps[i].normal[..3]))
                    })
                    .collect();
                (frame, patches)
            })
            .collect()
    }

    /// Each world's contact figures of the last frame (waits; for reports).
    pub fn read_stats(&self, gpu: &GpuContext) -> Vec<ManyBodyStats> {
        let meta = self.meta_words(gpu);
        let patches: Vec<PatchGpu> = gpu.read_buffer(&self.patches);
        let mp = self.contact.max_patches as usize;
        (0..self.world_count)
            .map(|w| {
                let m = self.world_meta(&meta, w);
                let count = m[M_COUNT] as usize;
                let pc = &m[self.pair_array(P_PATCH_COUNT)..self.pair_array(P_PATCH_COUNT) + count];
                let cand = &m[self.pair_array(P_CANDIDATES)..self.pair_array(P_CANDIDATES) + count];
                let base = (w * self.cfg.max_pairs) as usize;
                let contacts = (0..count)
                    .map(|e| {
                        patches[(base + e) * mp..(base + e) * mp + pc[e] as usize]
                            .iter()
                            .map(|p| p.slots.iter().filter(|s| s[3] < 1e38).count() as u32)
                            .sum::<u32>()
                    })
                    .sum();
                ManyBodyStats {
                    pairs: count as u32,
                    touching_pairs: pc.iter().filter(|&&c| c > 0).count() as u32,
                    candidates: cand.iter().map(|&c| c as u64).sum(),
                    patches: m[M_PATCHES],
                    contacts,
                    colours: m[M_COLOURS],
                    flags: m[M_FLAGS],
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contact::generate::{shader_source_wg, SdfKinds};

    #[test]
    fn many_body_shaders_validate_with_naga() {
        for (name, body) in
            [("near", NEAR_WGSL), ("contacts", CONTACTS_WGSL), ("merge", MERGE_WGSL), ("solve", SOLVE_WGSL)]
        {
            for (max_patches, wg, per) in [(16, 64, 4), (64, 256, 1), (64, 128, 2)] {
                for kinds in SdfKinds::combinations() {
                    for subgroups in [false, true] {
                        let src = shader_source_wg(
                            &format!("{MANY_BODY_COMMON}\n{body}"),
                            max_patches,
                            wg,
                            per,
                            kinds,
                            subgroups,
                        );
                        if let Err(e) = crate::contact::shader_tests::validate(&src, subgroups) {
                            panic!(
                                "many_body {name}.wgsl, max_patches {max_patches}, workgroup {wg} x {per}, {kinds:?}, subgroups {subgroups}:\n{e}"
                            );
                        }
                    }
                }
            }
        }
    }
}

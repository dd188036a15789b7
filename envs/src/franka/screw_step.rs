//! The Screw env's whole step on the device (`screw_step.wgsl` with the engine's and the controllers'
//! kernels): from the policy's actions in a device buffer to observations, rewards and done flags in device
//! buffers, with the worlds that ended reset in place. Nothing comes back to the host per step; the host
//! [`FrankaNutBolt`] is the reference (envs/tests/franka_screw_device.rs steps both from the same start
//! with the same actions).
//!
//! One step, recorded into one command buffer (docs/ARCHITECTURE.md section 7: rollouts stay on the device):
//! 1. [`ActionGpu`]: actions to the controller's targets, relative to the fingertip in the articulation
//!    kernel's record ([`ArticulationGpu::world_dynamics`], computed at the end of the step before);
//! 2. [`TaskSpaceGpu`]: the controller's torques into the articulation kernel's `joint_tau`;
//! 3. `push_torque`: the arm's torques into the coupled solve's joints (its `scratch`); the fingers' stay
//!    zero, their drives (targets 0) close the hand, as [`FrankaNutBolt`]'s step does;
//! 4. the contact pipeline and the coupled solve (engine `GpuArticulatedSolver`), on the state they keep;
//! 5. `pull_joints` + the articulation kernel's `dynamics`: the fingertip's pose and twist after the step;
//! 6. `evaluate`: [`Screw`](super::nut_bolt::Screw)'s reward and outcome, the divergence flag of the solve,
//!    the time limit, and the masked reset of every world that ended;
//! 7. `pull_joints` + `dynamics` again (the reset worlds' new fingertips), then `observe`.
//!
//! Resets draw from a bank of start states built on the host at construction with the env's own reset
//! (its randomisation and inverse kinematics): a world that ends takes the bank entry a hash of (world,
//! episode number) picks. Without randomisation the bank holds the one start; with it, `bank_count`
//! draws, so episodes sample that finite set rather than fresh draws (4096 entries by default in the
//! device env). The pads' forces on the nut (`observe_finger_force`) are summed from the solve's rows in
//! place, as the host's `pair_forces` reads them.
//!
//! Layout of the env's buffers: `env_state` per world 4 vec4 (steps in the episode and episodes ended, as
//! whole numbers in f32; then the previous action, 12 floats); `step_out` 5 planes of world_count f32
//! (reward, terminated, truncated, success, [`CAUSES`] index); `obs` [world_count * observation_dim] f32.
//! Kernels: one invocation per world, 64 per workgroup, a few hundred flops each; the step's cost is the
//! contact pipeline's and the solve's.

use bytemuck::{Pod, Zeroable};
use factory_controllers::TaskSpaceGpu;
use factory_engine::articulation::gpu::ArticulationGpu;
use factory_engine::articulation::ArticulationControl;
use factory_engine::gpu::{dispatch_compute, Binding, ExplicitLayout, GpuContext};
use factory_engine::sim::{ArticulatedSim, CoupledSolve};
use factory_engine::solver::Control;
use factory_engine::wgpu;

use super::action_gpu::ActionGpu;
use super::nut_bolt::{FrankaNutBolt, ScrewRandomization, FINGERPAD_LENGTH};
use super::scene::{ARM_DOF, DOF};
use crate::env::{Env, StepBuffers};
use crate::error::{EnvError, Result};

/// The kernels' source: screw_step.wgsl, then the engine's `any_orthonormal`.
pub fn screw_step_wgsl() -> String {
    format!("{}{}", include_str!("screw_step.wgsl"), factory_engine::solver::ANY_ORTHONORMAL_WGSL)
}

/// Worlds per workgroup (`@workgroup_size` of screw_step.wgsl).
pub const SCREW_STEP_WG: u32 = 64;

/// How an episode ended, by the index `evaluate` writes in `step_out`'s last plane: running, success, then
/// the failures as [`FrankaNutBolt`] names them.
pub const CAUSES: [&str; 6] = ["running", "success", "far", "slipped", "fallen", "diverged"];

/// `ScrewParams` of screw_step.wgsl (a uniform; the shader documents each field).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct ScrewParamsGpu {
    pub world_count: u32,
    pub body_count: u32,
    pub nut_body: u32,
    pub dof_count: u32,
    pub arm_dof: u32,
    pub stride: u32,
    pub joint_base: u32,
    pub joint_plane: u32,
    pub joint_vec4s: u32,
    pub bank_count: u32,
    pub bank_stride: u32,
    pub max_episode_steps: u32,
    pub obs_dim: u32,
    pub flags: u32,
    pub rows_base: u32,
    pub rows_per_world: u32,
    pub rows_per_pair: u32,
    pub row_vec4: u32,
    pub pad_pair_left: u32,
    pub pad_pair_right: u32,
    pub _pad: [u32; 4],
    /// The nut's centre of mass in its frame [m] (xyz).
    pub com_local: [f32; 4],
    /// The seated centre of mass [m] (xyz).
    pub seated: [f32; 4],
    /// Pitch, nut height, bolt diameter, bolt top [m].
    pub geometry: [f32; 4],
    /// Failure distance [m], success bonus, failure penalty, finger pad length [m].
    pub scoring: [f32; 4],
    /// Impulse to force [1/s] (substeps / dt), the left and right pad pairs' signs (force on the nut), 0.
    pub forces: [f32; 4],
}

struct Kernel {
    pipeline: wgpu::ComputePipeline,
    groups: [wgpu::BindGroup; 3],
    _layout: ExplicitLayout,
}

/// The device step of a [`FrankaNutBolt`] whose coupled solve runs on the device.
pub struct ScrewStepGpu {
    pub world_count: u32,
    /// Floats per observation (the env's spec).
    pub obs_dim: usize,
    /// Start states in the reset bank.
    pub bank_count: u32,
    /// The articulation kernel: the fingertip's record for the actions, the controller and the observation.
    pub art: ArticulationGpu,
    pub controller: TaskSpaceGpu,
    /// The action kernel; the policy's actions go in its `actions` buffer.
    pub action: ActionGpu,
    /// Per world the episode's counters and the previous action (module docs).
    pub env_state: wgpu::Buffer,
    /// Reward, terminated, truncated, success and cause planes, f32, shape [5 * world_count].
    pub step_out: wgpu::Buffer,
    /// Observations, f32, shape [world_count * obs_dim].
    pub obs: wgpu::Buffer,
    push: Kernel,
    pull: Kernel,
    evaluate: Kernel,
    observe: Kernel,
}

impl ScrewStepGpu {
    /// The device step for `env`, whose coupled solve it moves to the device (lavapipe without a GPU).
    /// `bank_count` start states are drawn for resets when the env randomises them (one otherwise); this
    /// draws from the env's generator and leaves world 0 at the last draw (call [`reset`](Self::reset)).
    /// Refuses a controller without a device kernel (the joint-space ones, an analytic Jacobian) and arm
    /// joints with position drives (the step holds the drives' targets at 0).
    pub fn new(gpu: &GpuContext, env: &mut FrankaNutBolt, bank_count: usize) -> Result<Self> {
        let cfg = env.config().clone();
        let n = env.spec().env_count;
        let obs_dim = env.spec().observation_dim();
        env.scene_mut().sim.solve_on(gpu, CoupledSolve::Device)?;
        let sim = &env.scene().sim;
        let a = &sim.articulation;
        if let Some(d) = (0..ARM_DOF).find(|&d| a.dof_drive_stiffness[d] != 0.0 || a.dof_drive_damping[d] != 0.0) {
            return Err(EnvError::InvalidValue {
                field: "arm drives",
                reason: format!("arm joint {} has a position drive; the device step drives the fingers only", d + 1),
            });
        }
        let art = ArticulationGpu::new(gpu, a, n as u32, &env.scene().tip, cfg.dt, cfg.substeps)?;
        let controller = TaskSpaceGpu::new(gpu, env.controller(), &art)?;
        let action = ActionGpu::new(gpu, &cfg, &art, &controller)?;
        // The fingers' drive targets (closed) and no arm drive, held for every step.
        let zeros = vec![0.0f32; n * DOF];
        let hold = ArticulationControl { joint_tau: zeros.clone(), joint_target_q: zeros };
        let dev = env.scene_mut().sim.device_solver_mut().expect("solve_on(Device) built it");
        dev.write_control(gpu, &Control::default(), &hold)?;
        let bank_count = if cfg.randomize == ScrewRandomization::default() { 1 } else { bank_count.max(1) };
        let c = *dev.coupling();
        let bank = start_bank(env, bank_count, c.joint_vec4s as usize);
        let sim = &env.scene().sim;
        let dev = sim.device_solver().expect("built above");
        let rows = dev.rows_layout();
        let pads = env.pad_pairs();
        let sign = |nut_is_query: bool| if nut_is_query { 1.0 } else { -1.0 };
        let screw = env.screw();
        let body_count = sim.model.bodies.body_count() as u32;
        let params = ScrewParamsGpu {
            world_count: n as u32,
            body_count,
            nut_body: env.scene().nut as u32,
            dof_count: DOF as u32,
            arm_dof: ARM_DOF as u32,
            stride: art.layout.stride,
            joint_base: c.joint_base,
            joint_plane: c.joint_plane,
            joint_vec4s: c.joint_vec4s,
            bank_count: bank_count as u32,
            bank_stride: 2 * body_count + c.joint_vec4s,
            max_episode_steps: cfg.max_episode_steps,
            obs_dim: obs_dim as u32,
            flags: cfg.observe_previous_action as u32 | (cfg.observe_finger_force as u32) << 1,
            rows_base: rows.rows_base,
            rows_per_world: rows.rows_per_world,
            rows_per_pair: rows.rows_per_pair,
            row_vec4: rows.row_vec4,
            pad_pair_left: pads[0].0 as u32,
            pad_pair_right: pads[1].0 as u32,
            _pad: [0; 4],
            com_local: env.nut_com_local().extend(0.0).to_array(),
            seated: screw.target.extend(0.0).to_array(),
            geometry: [screw.pitch, screw.nut_height, screw.bolt_diameter, screw.bolt_top],
            scoring: [screw.far_error, cfg.success_bonus, cfg.failure_penalty, FINGERPAD_LENGTH],
            forces: [cfg.substeps as f32 / cfg.dt, sign(pads[0].1), sign(pads[1].1), 0.0],
        };
        let uniform = gpu.uniform_buffer("screw-step-params", bytemuck::bytes_of(&params));
        let bank = gpu.storage_buffer("screw-start-bank", &bank, wgpu::BufferUsages::empty());
        let env_state = gpu.storage_buffer_zeroed("screw-env-state", n as u64 * 64);
        let step_out = gpu.storage_buffer_zeroed("screw-step-out", 5 * n as u64 * 4);
        let obs = gpu.storage_buffer_zeroed("screw-obs", (n * obs_dim) as u64 * 4);
        let (ro, rw) = (Binding::Storage { read_only: true }, Binding::Storage { read_only: false });
        let model = [&uniform, &bank];
        let source = screw_step_wgsl();
        let kernel = |entry: &str, ins: &[&wgpu::Buffer], outs: &[&wgpu::Buffer]| {
            let (ins_b, outs_b) = (vec![ro; ins.len()], vec![rw; outs.len()]);
            let layout = gpu.explicit_layout(entry, &[&[Binding::Uniform, ro], &ins_b, &outs_b]);
            let pipeline = gpu.pipeline_on(&layout, entry, &source, entry);
            let groups = [
                gpu.bind_explicit(&layout, 0, &model, 0),
                gpu.bind_explicit(&layout, 1, ins, 0),
                gpu.bind_explicit(&layout, 2, outs, 0),
            ];
            Kernel { pipeline, groups, _layout: layout }
        };
        let push = kernel("push_torque", &[&art.joint_tau], &[&dev.scratch]);
        let pull = kernel("pull_joints", &[&dev.scratch], &[&art.joint_q, &art.joint_qd]);
        let evaluate = kernel(
            "evaluate",
            &[&art.world_dynamics, &action.actions],
            &[&sim.pipe.body_q, &dev.body_qd, &dev.scratch, &env_state, &step_out],
        );
        let observe = kernel(
            "observe",
            &[&art.world_dynamics, &sim.pipe.body_q, &dev.body_qd, &env_state, &dev.scratch],
            &[&obs],
        );
        Ok(ScrewStepGpu {
            world_count: n as u32,
            obs_dim,
            bank_count: bank_count as u32,
            art,
            controller,
            action,
            env_state,
            step_out,
            obs,
            push,
            pull,
            evaluate,
            observe,
        })
    }

    fn dispatch(&self, encoder: &mut wgpu::CommandEncoder, k: &Kernel, label: &str) {
        let mut pass =
            encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some(label), timestamp_writes: None });
        dispatch_compute(&mut pass, &k.pipeline, k.groups.each_ref(), self.world_count.div_ceil(SCREW_STEP_WG), 1);
    }

    /// Records the fingertip's record and the observation of the current state.
    fn encode_observe(&self, encoder: &mut wgpu::CommandEncoder) {
        self.dispatch(encoder, &self.pull, "screw-pull-joints");
        self.art.encode_dynamics(encoder);
        self.dispatch(encoder, &self.observe, "screw-observe");
    }

    /// Starts a new episode in every world: the env's own reset on the host (its draws), uploaded once;
    /// counters, previous actions and step outputs zero; the first observation in `obs`.
    pub fn reset(&self, gpu: &GpuContext, env: &mut FrankaNutBolt) -> Result<()> {
        let mut host = StepBuffers::new(env.spec());
        env.reset(&mut host);
        let sim = &env.scene().sim;
        let dev = sim.device_solver().expect("new() moved the solve to the device");
        dev.write_state(gpu, &sim.pipe, &sim.state, &sim.joints)?;
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        enc.clear_buffer(&self.env_state, 0, None);
        enc.clear_buffer(&self.step_out, 0, None);
        self.encode_observe(&mut enc);
        gpu.queue.submit([enc.finish()]);
        Ok(())
    }

    /// Records one step of every world (module docs) on the actions in `action.actions`.
    pub fn encode_step(&self, encoder: &mut wgpu::CommandEncoder, sim: &ArticulatedSim) {
        let dev = sim.device_solver().expect("new() moved the solve to the device");
        self.action.encode(encoder);
        self.controller.encode(encoder);
        self.dispatch(encoder, &self.push, "screw-push-torque");
        sim.pipe.encode(encoder);
        dev.encode(encoder);
        self.dispatch(encoder, &self.pull, "screw-pull-joints");
        self.art.encode_dynamics(encoder);
        self.dispatch(encoder, &self.evaluate, "screw-evaluate");
        self.encode_observe(encoder);
    }

    /// [`encode_step`](Self::encode_step) in a submission of its own.
    pub fn step(&self, gpu: &GpuContext, sim: &ArticulatedSim) {
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        self.encode_step(&mut enc, sim);
        gpu.queue.submit([enc.finish()]);
    }

    /// Sets each world's step count within its running episode (shape [world_count]; for staggering first
    /// episodes right after [`reset`](Self::reset): the episode numbers and previous actions go to zero).
    pub fn set_episode_steps(&self, gpu: &GpuContext, steps: &[u32]) -> Result<()> {
        if steps.len() != self.world_count as usize {
            return Err(EnvError::Shape {
                field: "episode_steps",
                len: steps.len(),
                expected: self.world_count as usize,
            });
        }
        let state: Vec<[f32; 4]> =
            steps.iter().flat_map(|&s| [[s as f32, 0.0, 0.0, 0.0], [0.0; 4], [0.0; 4], [0.0; 4]]).collect();
        gpu.queue.write_buffer(&self.env_state, 0, bytemuck::cast_slice(&state));
        Ok(())
    }

    /// Every world's state as bytes (read back from the device: for checkpoints, never per step): the bodies'
    /// poses and velocities, the solve's scratch (its warm-start rows, joints and status) and the episodes'
    /// counters and previous actions. The reset bank is not in it: an env built from the same config and
    /// seed draws the same one.
    pub fn save(&self, gpu: &GpuContext, sim: &ArticulatedSim) -> Vec<u8> {
        let dev = sim.device_solver().expect("new() moved the solve to the device");
        let read = [&sim.pipe.body_q, &dev.body_qd, &dev.scratch, &self.env_state].map(|b| gpu.read_buffer::<u8>(b));
        let mut bytes = Vec::new();
        crate::env::frame_sections(&mut bytes, &read.each_ref().map(|b| b.as_slice()));
        bytes
    }

    /// Restores what [`save`](Self::save) wrote for an env of the same config and world count, and the
    /// fingertip's record and the observation from it (queued: lands before the next submission).
    pub fn load(&self, gpu: &GpuContext, sim: &ArticulatedSim, bytes: &[u8]) -> Result<()> {
        let dev = sim.device_solver().expect("new() moved the solve to the device");
        let buffers = [&sim.pipe.body_q, &dev.body_qd, &dev.scratch, &self.env_state];
        let bad = |reason: String| EnvError::InvalidValue {
            field: "state",
            reason: format!("franka_nut_bolt (device): {reason}"),
        };
        let (sections, at) = crate::env::split_sections(bytes, buffers.len())
            .ok_or_else(|| bad(format!("truncated ({} bytes)", bytes.len())))?;
        for (k, (s, buffer)) in sections.iter().zip(buffers).enumerate() {
            if s.len() as u64 != buffer.size() {
                return Err(bad(format!(
                    "saved for another config or number of worlds (section {k}: {} bytes, the buffer holds {})",
                    s.len(),
                    buffer.size()
                )));
            }
        }
        if at != bytes.len() {
            return Err(bad(format!("{} bytes, {at} expected", bytes.len())));
        }
        for (buffer, section) in buffers.into_iter().zip(sections) {
            gpu.queue.write_buffer(buffer, 0, section);
        }
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        self.encode_observe(&mut enc);
        gpu.queue.submit([enc.finish()]);
        Ok(())
    }

    /// Reads the last step's outputs into `out` (waits for the GPU: for tests and evaluation, never in a
    /// rollout).
    pub fn read(&self, gpu: &GpuContext, out: &mut StepBuffers) {
        let n = self.world_count as usize;
        let obs: Vec<f32> = gpu.read_buffer(&self.obs);
        out.observation.copy_from_slice(&obs[..n * self.obs_dim]);
        let planes: Vec<f32> = gpu.read_buffer(&self.step_out);
        out.reward.copy_from_slice(&planes[..n]);
        out.terminated.copy_from_slice(&planes[n..2 * n]);
        out.truncated.copy_from_slice(&planes[2 * n..3 * n]);
        out.success.copy_from_slice(&planes[3 * n..4 * n]);
        for (f, &c) in out.failure.iter_mut().zip(&planes[4 * n..5 * n]) {
            *f = (c >= 2.0).then(|| CAUSES[(c as usize).min(CAUSES.len() - 1)]);
        }
    }
}

/// `count` start states from the env's reset (world 0's host state is the scratch): per state the world's
/// body poses (2 vec4 each, the link bodies where the joints put them), then the joint positions padded to
/// `joint_vec4s` vec4 (the solver's).
fn start_bank(env: &mut FrankaNutBolt, count: usize, joint_vec4s: usize) -> Vec<[f32; 4]> {
    let mut bank = Vec::new();
    for _ in 0..count {
        env.reset_world(0);
        let sim = &mut env.scene_mut().sim;
        sim.sync_world_links(0);
        let nb = sim.model.bodies.body_count();
        for t in &sim.state.body_q[..nb] {
            bank.push(t.p);
            bank.push(t.q);
        }
        let mut q = sim.joints.joint_q[..DOF].to_vec();
        q.resize(4 * joint_vec4s, 0.0);
        bank.extend(q.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]));
    }
    bank
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The kernels parse and validate with naga (no GPU needed), and the check can fail.
    #[test]
    fn screw_step_shader_validates_with_naga() {
        let check = |src: &str| factory_engine::gpu::validate_wgsl(src, false);
        if let Err(e) = check(&screw_step_wgsl()) {
            panic!("screw_step.wgsl:\n{e}");
        }
        assert!(check(&screw_step_wgsl().replace("obs[o + k] = head[k];", "obs[o + k] = head;")).is_err());
    }

    /// The Pod mirror has the size naga lays `ScrewParams` out with (a regression: two pad words short, the
    /// uniform was bound 8 bytes smaller than the shader's struct).
    #[test]
    fn screw_params_match_their_mirror() {
        let module = naga::front::wgsl::parse_str(&screw_step_wgsl()).unwrap();
        let mut layouter = naga::proc::Layouter::default();
        layouter.update(module.to_ctx()).unwrap();
        let (h, _) = module.types.iter().find(|(_, t)| t.name.as_deref() == Some("ScrewParams")).unwrap();
        assert_eq!(layouter[h].size as usize, std::mem::size_of::<ScrewParamsGpu>());
    }
}

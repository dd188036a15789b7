//! FrankaNutBolt's action mapping on the device (`action.wgsl`): every world's 12 actions, clipped to
//! [-1, 1], to the controller kernel's targets relative to the fingertip pose the articulation kernel
//! computed ([`ArticulationGpu::world_dynamics`]), written where [`TaskSpaceGpu`] reads them
//! ([`TaskSpaceGpu::inputs`]). With the controller kernel it closes the policy-to-torque path on the device,
//! a piece of the device-resident Franka env (docs/ARCHITECTURE.md section 7). [`action_targets`] is the CPU
//! reference (a test below checks the two on seeded Franka states).
//!
//! Layout: group 0 an [`ActionParamsGpu`] uniform (scales, the yaw mapping, the fingers' targets), group 1
//! the articulation record and the actions (f32, shape [world_count * 12]), group 2 the controller's inputs.
//! One invocation per world, 64 per workgroup; a few dozen flops each. The measured wrench in the inputs is
//! written zero: a closed-loop force controller on the device would need the pads' forces there, which
//! this kernel does not write.
//!
//! [`action_targets`]: super::nut_bolt::action_targets

use bytemuck::{Pod, Zeroable};
use factory_controllers::TaskSpaceGpu;
use factory_engine::articulation::gpu::ArticulationGpu;
use factory_engine::gpu::{dispatch_compute, Binding, ExplicitLayout, GpuContext};
use factory_engine::wgpu;

use super::nut_bolt::FrankaNutBoltConfig;
use crate::error::{EnvError, Result};

/// The kernel's source: the controller's input struct, then action.wgsl.
pub fn action_wgsl() -> String {
    format!("{}{}", factory_controllers::task_space_gpu::CONTROLLER_INPUT_WGSL, include_str!("action.wgsl"))
}

/// Worlds per workgroup (`@workgroup_size` of action.wgsl).
pub const ACTION_WG: u32 = 64;

/// `ActionParams` of action.wgsl (a uniform).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct ActionParamsGpu {
    pub world_count: u32,
    /// Floats per world in the articulation record.
    pub stride: u32,
    /// 1: the yaw action maps to -(a + 1) / 2.
    pub unidirectional_rot: u32,
    pub _pad: u32,
    /// Action scales (xyz; w unused) [m, rad, N, N m].
    pub pos_scale: [f32; 4],
    pub rot_scale: [f32; 4],
    pub force_scale: [f32; 4],
    pub torque_scale: [f32; 4],
    /// The fingers' targets [m] (closed: 0).
    pub gripper_q: [f32; 4],
}

/// The action kernel bound to an articulation's record and a controller kernel's inputs.
pub struct ActionGpu {
    pub world_count: u32,
    /// The policy's actions, f32, shape [world_count * 12] ([`write_actions`](Self::write_actions), or a
    /// copy from the learner's tensor).
    pub actions: wgpu::Buffer,
    pipeline: wgpu::ComputePipeline,
    groups: [wgpu::BindGroup; 3],
    _layout: ExplicitLayout,
}

impl ActionGpu {
    /// The kernel for `cfg`'s action mapping on `art`'s worlds, writing `controller`'s inputs. Refuses a
    /// controller kernel for another number of worlds.
    pub fn new(
        gpu: &GpuContext,
        cfg: &FrankaNutBoltConfig,
        art: &ArticulationGpu,
        controller: &TaskSpaceGpu,
    ) -> Result<Self> {
        if controller.world_count != art.world_count {
            return Err(EnvError::InvalidValue {
                field: "world_count",
                reason: format!("controller for {} worlds, articulation {}", controller.world_count, art.world_count),
            });
        }
        let v4 = |v: [f32; 3]| [v[0], v[1], v[2], 0.0];
        let params = ActionParamsGpu {
            world_count: art.world_count,
            stride: art.layout.stride,
            unidirectional_rot: cfg.unidirectional_rot as u32,
            _pad: 0,
            pos_scale: v4(cfg.pos_action_scale),
            rot_scale: v4(cfg.rot_action_scale),
            force_scale: v4(cfg.force_action_scale),
            torque_scale: v4(cfg.torque_action_scale),
            gripper_q: [0.0; 4],
        };
        let uniform = gpu.uniform_buffer("action-params", bytemuck::bytes_of(&params));
        let actions = gpu.storage_buffer_zeroed("actions", art.world_count as u64 * 12 * 4);
        let ro = Binding::Storage { read_only: true };
        let layout =
            gpu.explicit_layout("action", &[&[Binding::Uniform], &[ro, ro], &[Binding::Storage { read_only: false }]]);
        let pipeline = gpu.pipeline_on(&layout, "action", &action_wgsl(), "screw_targets");
        let groups = [
            gpu.bind_explicit(&layout, 0, &[&uniform], 0),
            gpu.bind_explicit(&layout, 1, &[&art.world_dynamics, &actions], 0),
            gpu.bind_explicit(&layout, 2, &[&controller.inputs], 0),
        ];
        Ok(ActionGpu { world_count: art.world_count, actions, pipeline, groups, _layout: layout })
    }

    /// Uploads every world's actions (shape [world_count * 12]), queued before the next submission.
    pub fn write_actions(&self, gpu: &GpuContext, action: &[f32]) -> Result<()> {
        let want = self.world_count as usize * 12;
        if action.len() != want {
            return Err(EnvError::InvalidValue {
                field: "action",
                reason: format!("{} values, expected world_count x 12 = {want}", action.len()),
            });
        }
        gpu.queue.write_buffer(&self.actions, 0, bytemuck::cast_slice(action));
        Ok(())
    }

    /// Records the dispatch (after the articulation's `dynamics`, before the controller's).
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder) {
        let mut pass =
            encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("action"), timestamp_writes: None });
        dispatch_compute(&mut pass, &self.pipeline, self.groups.each_ref(), self.world_count.div_ceil(ACTION_WG), 1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::franka::nut_bolt::action_targets;
    use factory_controllers::task_space_gpu::ControllerInputGpu;
    use factory_controllers::{build, ArmBatch, ControllerConfig};
    use factory_engine::articulation::{ArticulationModel, ArticulationState};
    use factory_engine::rng::SplitMix64;
    use glam::{Quat, Vec3};

    /// The kernel parses and validates with naga (no GPU needed), and the check can fail.
    #[test]
    fn action_shader_validates_with_naga() {
        let check = |src: &str| factory_engine::gpu::validate_wgsl(src, false);
        if let Err(e) = check(&action_wgsl()) {
            panic!("action.wgsl:\n{e}");
        }
        assert!(check(&action_wgsl().replace("inputs[w] = out;", "inputs[w] = q;")).is_err());
    }

    /// On 70 seeded Franka states (the articulation kernel's records) and actions in [-1.5, 1.5] (clipped),
    /// both yaw mappings: the device writes the inputs the host's `action_targets` gives.
    #[test]
    fn the_device_maps_actions_as_the_host_does() {
        let gpu = GpuContext::global().unwrap();
        let path = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../assets/franka/franka_panda.urdf");
        let urdf = factory_engine::urdf::load_urdf(&path).unwrap();
        let m = ArticulationModel::from_urdf(&urdf, (Vec3::ZERO, Quat::IDENTITY), Vec3::new(0.0, 0.0, -9.81)).unwrap();
        let frame = m.frame("panda_fingertip_centered").unwrap();
        let worlds = 70;
        let art = ArticulationGpu::new(gpu, &m, worlds as u32, &frame, 1.0 / 60.0, 2).unwrap();
        let mut rng = SplitMix64(5);
        let mut sym = move || 2.0 * rng.unit() - 1.0;
        let mut state = ArticulationState::replicate(&crate::franka::scene::Q_START, worlds);
        for (i, q) in state.joint_q.iter_mut().enumerate() {
            if i % 9 < 7 {
                *q += 0.5 * sym();
            }
        }
        art.write_state(gpu, &state).unwrap();
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        art.encode_dynamics(&mut enc);
        gpu.queue.submit([enc.finish()]);
        let arm = ArmBatch::from_dynamics(&art.read_dynamics(gpu), &state, 7, &[]);
        let osc = build(&ControllerConfig::from_toml_str("type = \"osc\"").unwrap(), 9, 7).unwrap();
        let controller = TaskSpaceGpu::new(gpu, osc.as_ref(), &art).unwrap();
        let action: Vec<f32> = (0..worlds * 12).map(|_| 1.5 * sym()).collect();
        for unidirectional_rot in [true, false] {
            let cfg = FrankaNutBoltConfig { unidirectional_rot, ..Default::default() };
            let kernel = ActionGpu::new(gpu, &cfg, &art, &controller).unwrap();
            kernel.write_actions(gpu, &action).unwrap();
            let mut enc = gpu.device.create_command_encoder(&Default::default());
            kernel.encode(&mut enc);
            gpu.queue.submit([enc.finish()]);
            let got: Vec<ControllerInputGpu> = gpu.read_buffer(&controller.inputs);
            let want = ControllerInputGpu::from_targets(&action_targets(&cfg, &arm, &action), &[], 2);
            let mut worst = 0.0f32;
            for (g, w) in got.iter().zip(&want) {
                let (g, w): (&[f32; 28], &[f32; 28]) = (bytemuck::cast_ref(g), bytemuck::cast_ref(w));
                for (a, b) in g.iter().zip(w) {
                    worst = worst.max((a - b).abs());
                }
            }
            eprintln!("unidirectional_rot {unidirectional_rot}: worst difference {worst:.2e}");
            // Rounding of sin, cos and the products (targets are metres, unit quaternions, N and N m).
            assert!(worst < 1e-5, "unidirectional_rot {unidirectional_rot}: inputs differ by {worst}");
        }
        assert!(kernel_refuses_wrong_lengths(gpu, &art, &controller));
    }

    fn kernel_refuses_wrong_lengths(gpu: &GpuContext, art: &ArticulationGpu, controller: &TaskSpaceGpu) -> bool {
        let kernel = ActionGpu::new(gpu, &FrankaNutBoltConfig::default(), art, controller).unwrap();
        let e = kernel.write_actions(gpu, &[0.0; 12]).unwrap_err().to_string();
        e.contains("action") && e.contains("840")
    }
}

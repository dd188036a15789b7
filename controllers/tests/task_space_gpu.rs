//! The task-space controllers' device kernel (`TaskSpaceGpu`, task_space.wgsl) against their CPU reference
//! (`Controller::compute`) on the Franka: seeded joint states, the articulation kernel's dynamics records,
//! targets up to 10 cm and 30 degrees away, wrench targets and measurements; every law, with and without
//! gravity compensation. Runs on lavapipe where there is no GPU.

use factory_controllers::{build, ArmBatch, Controller, ControllerConfig, Targets, TaskSpaceGpu};
use factory_engine::articulation::gpu::ArticulationGpu;
use factory_engine::articulation::{ArticulationModel, ArticulationState};
use factory_engine::gpu::GpuContext;
use factory_engine::rng::SplitMix64;
use factory_engine::urdf::load_urdf;
use glam::{Quat, Vec3};
use std::path::PathBuf;

/// Worlds: more than one workgroup of 64, and not a multiple of it (the kernel's bounds test).
const WORLDS: usize = 70;
/// Factory's Screw reset pose (the hand points down), fingers closed.
const Q_SCREW: [f32; 9] = [1.5178e-3, -0.19651, -1.4364e-3, -1.9761, -2.7717e-4, 1.7796, 0.78556, 0.0, 0.0];

fn franka() -> ArticulationModel {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../assets/franka/franka_panda.urdf");
    let mut m = ArticulationModel::from_urdf(
        &load_urdf(&path).unwrap(),
        (Vec3::ZERO, Quat::IDENTITY),
        Vec3::new(0.0, 0.0, -9.81),
    )
    .unwrap();
    m.set_armature(0.01);
    m
}

fn controller(toml: &str) -> Box<dyn Controller> {
    build(&ControllerConfig::from_toml_str(toml).unwrap(), 9, 7).unwrap()
}

/// Symmetric in [-1, 1).
fn sym(rng: &mut SplitMix64) -> f32 {
    2.0 * rng.unit() - 1.0
}

/// Seeded joint states around the Screw pose (arm within 0.4 rad, fingers 0-4 cm, moving).
fn states(rng: &mut SplitMix64) -> ArticulationState {
    let mut s = ArticulationState::replicate(&Q_SCREW, WORLDS);
    for w in 0..WORLDS {
        for d in 0..9 {
            let i = w * 9 + d;
            if d < 7 {
                s.joint_q[i] += 0.4 * sym(rng);
                s.joint_qd[i] = 0.5 * sym(rng);
            } else {
                s.joint_q[i] = 0.02 + 0.02 * sym(rng);
                s.joint_qd[i] = 0.05 * sym(rng);
            }
        }
    }
    s
}

/// Targets up to 10 cm and 30 degrees from each world's fingertip, wrench targets up to 10 N / 1 N m, finger
/// targets 0-4 cm; and measured wrenches.
fn targets(arm: &ArmBatch, rng: &mut SplitMix64) -> (Targets, Vec<[f32; 6]>) {
    let mut t = Targets::hold(arm);
    let mut measured = Vec::new();
    for w in 0..WORLDS {
        let dir = Vec3::new(sym(rng), sym(rng), sym(rng)).normalize_or(Vec3::Z);
        t.ee_pos[w] += dir * 0.1 * rng.unit();
        let axis = Vec3::new(sym(rng), sym(rng), sym(rng)).normalize_or(Vec3::X);
        t.ee_quat[w] = Quat::from_axis_angle(axis, 30f32.to_radians() * rng.unit()) * t.ee_quat[w];
        t.ee_wrench[w] = [10.0 * sym(rng), 10.0 * sym(rng), 10.0 * sym(rng), sym(rng), sym(rng), sym(rng)];
        for f in 0..2 {
            t.gripper_q[w * 2 + f] = 0.02 + 0.02 * sym(rng);
        }
        measured.push([10.0 * sym(rng), 10.0 * sym(rng), 10.0 * sym(rng), sym(rng), sym(rng), sym(rng)]);
    }
    (t, measured)
}

#[test]
fn every_task_space_law_matches_its_cpu_reference() {
    let gpu = GpuContext::global().unwrap();
    let m = franka();
    let frame = m.frame("panda_fingertip_centered").unwrap();
    let art = ArticulationGpu::new(gpu, &m, WORLDS as u32, &frame, 1.0 / 60.0, 2).unwrap();
    let mut rng = SplitMix64(2026);
    let state = states(&mut rng);
    art.write_state(gpu, &state).unwrap();
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    art.encode_dynamics(&mut enc);
    gpu.queue.submit([enc.finish()]);
    // The host reads the same records the kernel reads: differences are the two codes' rounding only.
    let arm = ArmBatch::from_dynamics(&art.read_dynamics(gpu), &state, 7, &[]);
    let (t, measured) = targets(&arm, &mut rng);
    let mut arm_measured = arm.clone();
    arm_measured.ee_wrench.copy_from_slice(&measured);
    let laws = [
        // configs/screw.toml's: OSC on z and yaw.
        "type = \"osc\"\nkp = [1, 1, 1, 1, 1, 200]\nkd = 1\nmotion_axes = [0, 0, 1, 0, 0, 1]\ngripper_kp = 100\ngripper_kd = 1",
        "type = \"osc\"",
        "type = \"osc\"\ngravity_compensation = false",
        "type = \"task_space_impedance\"",
        "type = \"open_loop_force\"",
        "type = \"closed_loop_force\"",
        "type = \"hybrid_force_motion\"",
        "type = \"hybrid_force_motion\"\nmotion = \"impedance\"\nforce = \"open\"",
    ];
    for law in laws {
        let ctrl = controller(law);
        let dev = TaskSpaceGpu::new(gpu, ctrl.as_ref(), &art).unwrap();
        dev.write_inputs(gpu, &t, &measured).unwrap();
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        dev.encode(&mut enc);
        gpu.queue.submit([enc.finish()]);
        let got: Vec<f32> = gpu.read_buffer(&art.joint_tau);
        let mut want = vec![0.0f32; WORLDS * 9];
        ctrl.compute(&arm_measured, &t, &mut want);
        let (mut worst, mut scale) = (0.0f32, 0.0f32);
        for (g, w) in got.iter().zip(&want) {
            worst = worst.max((g - w).abs() / w.abs().max(1.0));
            scale = scale.max(w.abs());
        }
        eprintln!(
            "{}: worst |device - host| / max(|host|, 1 N m) = {worst:.2e} (largest torque {scale:.1})",
            law.replace('\n', "; ")
        );
        // f32 rounding in another order (sums, atan2, OSC's Cholesky and 6 x 6 solves): measured 0 to 9.3e-5
        // on lavapipe.
        assert!(worst < 5e-4, "{law}: device and host torques differ by {worst} (relative)");
        assert!(scale > 1.0, "{law}: the torques are not trivially zero");
    }
}

#[test]
fn the_device_kernel_refuses_what_it_cannot_run() {
    let gpu = GpuContext::global().unwrap();
    let m = franka();
    let frame = m.frame("panda_fingertip_centered").unwrap();
    let art = ArticulationGpu::new(gpu, &m, 4, &frame, 1.0 / 60.0, 2).unwrap();
    let err = |toml: &str| TaskSpaceGpu::new(gpu, controller(toml).as_ref(), &art).err().unwrap().to_string();
    let e = err("type = \"joint_space_ik\"");
    assert!(e.contains("type") && e.contains("joint_space_ik") && e.contains("osc"), "{e}");
    let e = err("type = \"osc\"\njacobian = \"analytic\"");
    assert!(e.contains("jacobian") && e.contains("geometric"), "{e}");
    let dev = TaskSpaceGpu::new(gpu, controller("type = \"osc\"").as_ref(), &art).unwrap();
    let arm = ArmBatch::zeros(3, 9, 7);
    let e = dev.write_inputs(gpu, &Targets::hold(&arm), &[]).unwrap_err().to_string();
    assert!(e.contains("ee_pos") && e.contains('3') && e.contains('4'), "{e}");
}

//! The Franka env's Rust-side GPU mirrors against naga's layout of the WGSL structs they mirror, in the
//! sources the kernels compile: the same size and every member at the same offset
//! ([`factory_engine::gpu::layout`]). No GPU needed.

use factory_engine::gpu::layout::{assert_mirror, check_mirror};
use factory_engine::gpu_mirror;
use factory_envs::franka::action_gpu::{action_wgsl, ActionParamsGpu};
use factory_envs::franka::screw_step::{screw_step_wgsl, ScrewParamsGpu};

/// `ActionParams`, the action kernel's uniform (action.wgsl).
#[test]
fn action_params_match_their_wgsl_struct() {
    assert_mirror(
        &action_wgsl(),
        "ActionParams",
        &gpu_mirror!(ActionParamsGpu {
            world_count,
            stride,
            unidirectional_rot,
            _pad,
            pos_scale,
            rot_scale,
            force_scale,
            torque_scale,
            gripper_q,
        }),
    );
}

/// The mirror of `ScrewParams` as [`ScrewParamsGpu`] lists its fields (both spell them alike).
macro_rules! screw_params_mirror {
    ($ty:ty) => {
        gpu_mirror!($ty {
            world_count,
            body_count,
            nut_body,
            dof_count,
            arm_dof,
            stride,
            joint_base,
            joint_plane,
            joint_vec4s,
            bank_count,
            bank_stride,
            max_episode_steps,
            obs_dim,
            flags,
            rows_base,
            rows_per_world,
            rows_per_pair,
            row_vec4,
            pad_pair_left,
            pad_pair_right,
            com_local,
            seated,
            geometry,
            scoring,
            forces,
        })
    };
}

/// `ScrewParams`, the device Screw step's uniform (screw_step.wgsl).
#[test]
fn screw_params_match_their_wgsl_struct() {
    assert_mirror(&screw_step_wgsl(), "ScrewParams", &screw_params_mirror!(ScrewParamsGpu));
}

/// [`ScrewParamsGpu`] as it once was: two pad words short after the twenty u32 words, so its vec4s sat 8
/// bytes early and the uniform was bound 8 bytes smaller than the shader's struct.
#[repr(C)]
#[allow(dead_code)]
struct ScrewParamsGpuTwoPadWordsShort {
    world_count: u32,
    body_count: u32,
    nut_body: u32,
    dof_count: u32,
    arm_dof: u32,
    stride: u32,
    joint_base: u32,
    joint_plane: u32,
    joint_vec4s: u32,
    bank_count: u32,
    bank_stride: u32,
    max_episode_steps: u32,
    obs_dim: u32,
    flags: u32,
    rows_base: u32,
    rows_per_world: u32,
    rows_per_pair: u32,
    row_vec4: u32,
    pad_pair_left: u32,
    pad_pair_right: u32,
    _pad: [u32; 2],
    com_local: [f32; 4],
    seated: [f32; 4],
    geometry: [f32; 4],
    scoring: [f32; 4],
    forces: [f32; 4],
}

/// The regression the check exists for: a `ScrewParams` mirror 8 bytes short is reported, with the
/// shortfall and every vec4 member it moved (WGSL: 24 words = 96 bytes before `com_local`, 176 in all).
#[test]
fn screw_params_mirror_8_bytes_short_is_reported() {
    let e = check_mirror(&screw_step_wgsl(), "ScrewParams", &screw_params_mirror!(ScrewParamsGpuTwoPadWordsShort))
        .expect_err("a mirror 8 bytes short must not pass");
    assert!(e.contains("is 176 bytes, Rust `ScrewParamsGpuTwoPadWordsShort` is 168 (8 bytes short)"), "{e}");
    for (field, wgsl, rust) in [("com_local", 96, 88), ("seated", 112, 104), ("forces", 160, 152)] {
        assert!(e.contains(&format!("field `{field}`: WGSL offset {wgsl}, Rust offset {rust}")), "{e}");
    }
}

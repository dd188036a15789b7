//! Every Rust-side GPU mirror of the engine (the `#[repr(C)]` Pod structs uploaded as uniforms or as
//! storage-buffer elements) against naga's layout of the WGSL struct it mirrors, read from the file that
//! declares it: the same size and every member at the same offset ([`factory_engine::gpu::layout`]). No GPU
//! needed.
//!
//! Not here: many_body::gpu's `PassParamsGpu` (`PassParams`), private to its module, so no test outside it can
//! take its field offsets.

use factory_engine::articulation::gpu::{ArticulationParamsGpu, DofGpu, LinkGpu};
use factory_engine::contact::model::{JobGpu, PairGpu, ParamsGpu, PatchGpu};
use factory_engine::contact::TransformGpu;
use factory_engine::gpu::layout::assert_mirror;
use factory_engine::gpu_mirror;
use factory_engine::many_body::gpu::ManyBodyParamsGpu;
use factory_engine::solver::articulated::CouplingGpu;
use factory_engine::solver::gpu::{BodyGpu, SolverParamsGpu};

const CONTACT_COMMON: &str = include_str!("../src/contact/common.wgsl");
const CONTACT_GENERATE: &str = include_str!("../src/contact/generate.wgsl");
const SOLVER_CORE: &str = include_str!("../src/solver/solver_core.wgsl");
const ARTICULATED: &str = include_str!("../src/solver/articulated.wgsl");
const ARTICULATION_CORE: &str = include_str!("../src/articulation/articulation_core.wgsl");
const MANY_BODY_COMMON: &str = include_str!("../src/many_body/many_body_common.wgsl");

/// The contact pipeline's uniform and storage elements (common.wgsl, generate.wgsl).
#[test]
fn contact_mirrors_match_their_wgsl_structs() {
    assert_mirror(
        CONTACT_COMMON,
        "Params",
        &gpu_mirror!(ParamsGpu {
            world_count,
            body_count,
            pair_count,
            job_count,
            normal_cos,
            iterations,
            world_offset,
            job_base,
        }),
    );
    assert_mirror(
        CONTACT_COMMON,
        "Pair",
        &gpu_mirror!(PairGpu {
            a_pos,
            a_rot,
            b_pos,
            b_rot,
            sdf_origin,
            sdf_dims,
            body_a,
            body_b,
            tri_first,
            tri_count,
            sdf_kind,
            job_first,
            job_count,
            sdf_scale,
            contact_offset,
            radius,
            area_unit,
            min_separation,
            friction,
            many_body_template,
            a_bound,
            b_bound,
        }),
    );
    assert_mirror(CONTACT_COMMON, "Transform", &gpu_mirror!(TransformGpu { p, q }));
    assert_mirror(CONTACT_COMMON, "PatchOut", &gpu_mirror!(PatchGpu { normal, slots }));
    assert_mirror(CONTACT_GENERATE, "Job", &gpu_mirror!(JobGpu { pair, tri_first, tri_count, slot }));
}

/// The rigid-body solver's uniform and body records (solver_core.wgsl), and the articulated solver's
/// coupling uniform (articulated.wgsl).
#[test]
fn solver_mirrors_match_their_wgsl_structs() {
    assert_mirror(
        SOLVER_CORE,
        "SolverParams",
        &gpu_mirror!(SolverParamsGpu {
            world_count,
            body_count,
            pair_count,
            max_rows,
            dt,
            substeps,
            pos_iters,
            vel_iters,
            max_depenetration_velocity,
            rest_offset,
            max_speed,
            patch_iters,
            gravity,
            loop_budget,
        }),
    );
    assert_mirror(SOLVER_CORE, "Body", &gpu_mirror!(BodyGpu { inv_inertia, com_inv_mass, flags }));
    assert_mirror(
        ARTICULATED,
        "Coupling",
        &gpu_mirror!(CouplingGpu {
            slot_count,
            joint_base,
            joint_plane,
            joint_vec4s,
            slot_body,
            slot_link,
            art_passes,
            substep,
        }),
    );
}

/// The articulation kernel's uniform and its per-link and per-dof records (articulation_core.wgsl).
#[test]
fn articulation_mirrors_match_their_wgsl_structs() {
    assert_mirror(
        ARTICULATION_CORE,
        "ArtParams",
        &gpu_mirror!(ArticulationParamsGpu {
            world_count,
            link_count,
            dof_count,
            frame_link,
            frame_p,
            frame_q,
            gravity,
            dt,
            substeps,
            drives,
            dynamics_stride,
            jacobian_offset,
            mass_offset,
            gravity_offset,
            coriolis_offset,
        }),
    );
    assert_mirror(
        ARTICULATION_CORE,
        "Link",
        &gpu_mirror!(LinkGpu { origin_p, origin_q, axis, com_mass, inertia, parent, joint, dof, _pad }),
    );
    assert_mirror(
        ARTICULATION_CORE,
        "Dof",
        &gpu_mirror!(DofGpu {
            lower,
            upper,
            velocity_limit,
            effort_limit,
            damping,
            armature,
            drive_stiffness,
            drive_damping,
        }),
    );
}

/// The many-body kernels' shared uniform (many_body_common.wgsl).
#[test]
fn many_body_mirrors_match_their_wgsl_structs() {
    assert_mirror(
        MANY_BODY_COMMON,
        "ManyBodyParams",
        &gpu_mirror!(ManyBodyParamsGpu {
            world_count,
            body_count,
            cap,
            jobs_per_pair,
            chunk,
            class_count,
            static_count,
            max_colours,
            meta_stride,
            patch_budget,
            sleep_frames,
            sleep_distance,
            sleep_half_cos,
            rest_base,
        }),
    );
}

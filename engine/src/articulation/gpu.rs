//! The articulation's dynamics on the GPU (articulation.wgsl): the device twin of [`super::dynamics`], so
//! the controllers and the env read M, g, c and the fingertip Jacobian where they are computed, and the
//! joints step without a round trip to the host. `engine/tests/articulation_gpu.rs` checks it against the
//! CPU reference ([`super::dynamics::world_dynamics`], [`super::dynamics::step_cpu`]).
//!
//! Algorithm (the same as the host's, step for step, so parity is a matter of float rounding only): per
//! world, forward kinematics walks the links parent before child composing joint transforms; the geometric
//! Jacobian of a point gathers, from its link to the root, (a x (p - o); a) for a revolute joint with world
//! axis a through o and (a; 0) for a prismatic one; the mass matrix is M = sum over links of
//! m Jc^T Jc + Jw^T I Jw (Siciliano et al., "Robotics: Modelling, Planning and Control", 2009, eq. 7.32)
//! plus the armature; g(q) and c(q, qd) come from the recursive Newton-Euler algorithm (Featherstone,
//! "Rigid Body Dynamics Algorithms", 2008, table 5.1, in world-frame vectors: a forward loop over the
//! links for velocities and accelerations, a backward loop accumulating each subtree's force and moment;
//! WGSL has no recursion, and parent-before-child order makes both passes plain loops). A step substep
//! solves (M + h (D + Kd)) qdd = clamp(tau + Kp (q_t - q) - Kd qd, effort) - c - g - D qd by Cholesky
//! (damping implicit), then clamps the velocity, integrates q and stops joints at their limits
//! ([`super::dynamics::free_velocity`], [`super::dynamics::integrate_positions`]).
//!
//! Layout: one invocation per world, [`ARTICULATION_WG`] worlds per workgroup; bind group 0 the model
//! (params uniform, [`LinkGpu`] and [`DofGpu`] arrays), group 1 the control (`joint_tau`,
//! `joint_target_q`, read-only), group 2 the state and outputs (`joint_q`, `joint_qd`, `link_pose`,
//! `world_dynamics`, read-write). Both entry points share one explicit pipeline layout and the same bind
//! groups: 8 storage buffers, the engine's minimum per stage ([`crate::gpu::REQUIRED_LIMITS`]), which is
//! why a world's frame pose, twist, Jacobian, M, g and c share one record ([`DynamicsLayout`]).
//!
//! GPU cost. A world's working set lives in private (per-invocation) arrays sized for the bounds
//! ([`MAX_DOFS`] = 16, [`MAX_LINKS`] = 32): M / its Cholesky factor (1 KiB), link poses (1 KiB),
//! Newton-Euler's five vectors per link (2.5 KiB), Jacobian columns and joint vectors (0.8 KiB): about
//! 5.3 KiB per invocation, of which the Franka (13 links, 9 dofs) touches about 2 KiB. Arrays indexed at
//! run time do not fit in registers, so on a GPU they live in per-thread local memory (device memory
//! cached in L1): registers stay few and do not limit occupancy, but every access is a cached memory
//! access. At 64 invocations per workgroup the Franka's touched set is ~128 KiB per workgroup, about an
//! SM's L1 (192-256 KiB on recent NVIDIA GPUs): one or two resident workgroups per SM stay cached, more
//! spill to L2.
//! The arithmetic is small (per substep ~5k flops per world: M over the links' Jacobian columns,
//! O(links x dof^2); Newton-Euler O(links); Cholesky O(dof^3 / 3)), so a step is latency-bound on these
//! dependent local-memory accesses and needs thousands of worlds to fill a GPU, which RL training has.
//! For few worlds, one workgroup per world (a lane per dof for the Jacobian columns, M's rows and the
//! Cholesky updates, scratch in workgroup memory) would cut the latency; the composite-rigid-body
//! algorithm (Featherstone 2008, ch. 6, O(dof x depth)) would cut M's work; neither changes results beyond
//! rounding, and neither pays at the Franka's size yet. A scratch storage buffer instead of private arrays
//! would cost a binding (none left) and the same memory traffic. On lavapipe the worlds run 8 to a SIMD
//! register; the worlds share the model, so their control flow diverges only at limits, but every
//! run-time index into a private array becomes a per-lane gather or scatter. Measured on a 2-core
//! CPU with the Franka: a step of 2 substeps takes 0.76 / 6.4 / 22 ms at 64 / 1024 / 4096
//! worlds, `dynamics` 0.44 / 2.9 / 12 ms, where the rayon CPU reference steps in 0.17 / 2.4 / 9.3 ms. So on
//! the CPU fallback this kernel is 2.4-4.5x slower than the host code; it exists for the GPU, where the state
//! then never leaves the device (docs/ARCHITECTURE.md section 7).
//!
//! Loops: lavapipe's per-invocation loop budget ([`crate::contact::LOOP_ITERATION_LIMIT`]) is checked on
//! the host from [`loop_passes`]; a software adapter refuses substep counts that would pass it.

use super::dynamics::WorldDynamics;
use super::{ArticulationControl, ArticulationModel, ArticulationState, Frame, JointKind, NO_DOF, NO_LINK};
use crate::error::{EngineError, Result};
use crate::gpu::{Binding, ExplicitLayout, GpuContext};
use bytemuck::{Pod, Zeroable};
use glam::{Quat, Vec3, Vec4};

pub(crate) const ARTICULATION_WGSL: &str =
    concat!(include_str!("articulation.wgsl"), include_str!("articulation_core.wgsl"));

/// Invocations (worlds) per workgroup (articulation.wgsl's `@workgroup_size`).
pub const ARTICULATION_WG: u32 = 64;
/// Most degrees of freedom per articulation (articulation_core.wgsl's MAX_DOFS: private arrays are sized by it).
pub const MAX_DOFS: usize = 16;
/// Most links per articulation (articulation_core.wgsl's MAX_LINKS).
pub const MAX_LINKS: usize = 32;

/// Joint codes of [`LinkGpu::joint`].
const JOINT_FIXED: u32 = 0;
const JOINT_REVOLUTE: u32 = 1;
const JOINT_PRISMATIC: u32 = 2;

/// Stand-in for an infinite limit: WGSL lets an implementation assume that no value is infinite (WGSL
/// spec, "Floating point evaluation"), so absent limits go to the device as the largest finite f32, which
/// clamps and compares the same as infinity on every finite value.
const NO_LIMIT: f32 = f32::MAX;

/// GPU mirror of `ArtParams` in articulation_core.wgsl (a uniform).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct ArticulationParamsGpu {
    /// Worlds in the batch.
    pub world_count: u32,
    /// Links per world (1 ..= [`MAX_LINKS`]).
    pub link_count: u32,
    /// Degrees of freedom per world (0 ..= [`MAX_DOFS`]).
    pub dof_count: u32,
    /// The link carrying the frame whose pose, twist and Jacobian `dynamics` writes.
    pub frame_link: u32,
    /// The frame's position in its link [m]; w unused.
    pub frame_p: [f32; 4],
    /// The frame's rotation in its link (unit quaternion x, y, z, w).
    pub frame_q: [f32; 4],
    /// Gravity [m/s^2]; w unused.
    pub gravity: [f32; 4],
    /// Frame time step [s].
    pub dt: f32,
    /// Substeps per frame (>= 1).
    pub substeps: u32,
    /// 1: the position drives act (the host set joint targets), 0: effort only (as an empty
    /// [`ArticulationControl::joint_target_q`] on the CPU).
    pub drives: u32,
    /// Floats per world in `world_dynamics` ([`DynamicsLayout::stride`]).
    pub dynamics_stride: u32,
    /// Offsets [f32] in a world's record of the Jacobian, M, g and c ([`DynamicsLayout`]).
    pub jacobian_offset: u32,
    pub mass_offset: u32,
    pub gravity_offset: u32,
    pub coriolis_offset: u32,
}

/// GPU mirror of `Link` in articulation_core.wgsl: one link of the model, shared by every world (128 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct LinkGpu {
    /// The joint frame in the parent link at joint position 0 [m] (the base pose for the root); w unused.
    pub origin_p: [f32; 4],
    /// Its rotation (unit quaternion x, y, z, w).
    pub origin_q: [f32; 4],
    /// Unit joint axis in the link frame; w unused.
    pub axis: [f32; 4],
    /// Centre of mass in the link frame [m] (xyz) and mass [kg] (w; 0 for a massless link).
    pub com_mass: [f32; 4],
    /// Inertia about the centre of mass in link axes [kg m^2], columns (a WGSL mat3x3: each column padded
    /// to 16 bytes).
    pub inertia: [[f32; 4]; 3],
    /// Parent link index, [`NO_LINK`] for the root.
    pub parent: u32,
    /// 0 fixed, 1 revolute, 2 prismatic.
    pub joint: u32,
    /// The link's degree of freedom, [`NO_DOF`] for a fixed joint.
    pub dof: u32,
    pub _pad: u32,
}

/// GPU mirror of `Dof` in articulation_core.wgsl: one degree of freedom's limits and joint parameters (32 bytes).
/// Absent limits are [`f32::MAX`] (see `NO_LIMIT`).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct DofGpu {
    /// Position limits [rad or m].
    pub lower: f32,
    pub upper: f32,
    /// Speed limit [rad/s or m/s].
    pub velocity_limit: f32,
    /// Effort limit [N m or N].
    pub effort_limit: f32,
    /// Viscous joint damping [N m s/rad or N s/m].
    pub damping: f32,
    /// Armature added to M's diagonal [kg m^2 or kg].
    pub armature: f32,
    /// Position-drive stiffness [N m/rad or N/m] and damping [N m s/rad or N s/m].
    pub drive_stiffness: f32,
    pub drive_damping: f32,
}

/// Where a world's quantities sit in its `world_dynamics` record (all in f32 units from the record's
/// start; the record of world w starts at w * stride). Offsets 0..16 hold the frame: position (xyz, 0),
/// rotation (x, y, z, w), linear velocity (xyz, 0) [m/s], angular velocity (xyz, 0) [rad/s].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DynamicsLayout {
    /// Floats per world, a multiple of 4 (so a reader may view records as vec4 arrays).
    pub stride: u32,
    /// The frame's geometric Jacobian, 6 x dof_count row-major, rows (vx, vy, vz, wx, wy, wz).
    pub jacobian: u32,
    /// The mass matrix with armature, dof_count x dof_count row-major (symmetric).
    pub mass_matrix: u32,
    /// g(q) [N m or N], shape [dof_count].
    pub gravity_torque: u32,
    /// c(q, qd) [N m or N], shape [dof_count].
    pub coriolis_torque: u32,
}

impl DynamicsLayout {
    /// The layout for `dof_count` degrees of freedom.
    pub fn new(dof_count: u32) -> Self {
        let n = dof_count;
        let jacobian = 16;
        let mass_matrix = jacobian + 6 * n;
        let gravity_torque = mass_matrix + n * n;
        let coriolis_torque = gravity_torque + n;
        DynamicsLayout {
            stride: (coriolis_torque + n).next_multiple_of(4),
            jacobian,
            mass_matrix,
            gravity_torque,
            coriolis_torque,
        }
    }
}

/// The model's links as the kernel reads them.
pub fn links_gpu(model: &ArticulationModel) -> Vec<LinkGpu> {
    (0..model.link_count())
        .map(|l| {
            let (p, r) = model.link_origin[l];
            let i = model.link_inertia[l];
            LinkGpu {
                origin_p: p.extend(0.0).to_array(),
                origin_q: r.to_array(),
                axis: model.link_axis[l].extend(0.0).to_array(),
                com_mass: model.link_com[l].extend(model.link_mass[l]).to_array(),
                inertia: [
                    i.x_axis.extend(0.0).to_array(),
                    i.y_axis.extend(0.0).to_array(),
                    i.z_axis.extend(0.0).to_array(),
                ],
                parent: model.link_parent[l],
                joint: match model.link_joint[l] {
                    JointKind::Fixed => JOINT_FIXED,
                    JointKind::Revolute => JOINT_REVOLUTE,
                    JointKind::Prismatic => JOINT_PRISMATIC,
                },
                dof: model.link_dof[l],
                _pad: 0,
            }
        })
        .collect()
}

/// The model's degrees of freedom as the kernel reads them (infinite limits made finite, see `NO_LIMIT`).
pub fn dofs_gpu(model: &ArticulationModel) -> Vec<DofGpu> {
    let finite = |v: f32| v.clamp(-NO_LIMIT, NO_LIMIT);
    (0..model.dof_count())
        .map(|d| DofGpu {
            lower: finite(model.dof_lower[d]),
            upper: finite(model.dof_upper[d]),
            velocity_limit: finite(model.dof_velocity_limit[d]),
            effort_limit: finite(model.dof_effort_limit[d]),
            damping: model.dof_damping[d],
            armature: model.dof_armature[d],
            drive_stiffness: model.dof_drive_stiffness[d],
            drive_damping: model.dof_drive_damping[d],
        })
        .collect()
}

/// Refuses what the kernel cannot run, naming the field: array shapes that disagree with the link and dof
/// counts, more than [`MAX_LINKS`] links or [`MAX_DOFS`] dofs, links out of parent-before-child order, a
/// fixed joint with a dof or a dof index out of range, a frame on a missing link, no worlds, a non-positive
/// `dt` or zero `substeps`. Needs no GPU.
pub fn validate(model: &ArticulationModel, world_count: u32, frame: &Frame, dt: f32, substeps: u32) -> Result<()> {
    let bad =
        |field: &'static str, value: String, expected: String| Err(EngineError::Config { field, value, expected });
    let (nl, n) = (model.link_count(), model.dof_count());
    if nl == 0 || nl > MAX_LINKS {
        return bad("link_count", nl.to_string(), format!("1 ..= {MAX_LINKS} links (the GPU kernel's bound)"));
    }
    if n > MAX_DOFS {
        return bad(
            "dof_count",
            n.to_string(),
            format!("at most {MAX_DOFS} degrees of freedom (the GPU kernel's bound)"),
        );
    }
    let link_lens = [
        ("link_parent", model.link_parent.len()),
        ("link_joint", model.link_joint.len()),
        ("link_dof", model.link_dof.len()),
        ("link_origin", model.link_origin.len()),
        ("link_axis", model.link_axis.len()),
        ("link_mass", model.link_mass.len()),
        ("link_com", model.link_com.len()),
        ("link_inertia", model.link_inertia.len()),
    ];
    let dof_lens = [
        ("dof_lower", model.dof_lower.len()),
        ("dof_upper", model.dof_upper.len()),
        ("dof_velocity_limit", model.dof_velocity_limit.len()),
        ("dof_effort_limit", model.dof_effort_limit.len()),
        ("dof_damping", model.dof_damping.len()),
        ("dof_armature", model.dof_armature.len()),
        ("dof_drive_stiffness", model.dof_drive_stiffness.len()),
        ("dof_drive_damping", model.dof_drive_damping.len()),
    ];
    let per_link = link_lens.iter().map(|&(f, len)| (f, len, nl, "link"));
    for (field, len, want, per) in per_link.chain(dof_lens.iter().map(|&(f, len)| (f, len, n, "degree of freedom"))) {
        if len != want {
            return bad(field, format!("{len} entries"), format!("{want}, one per {per}"));
        }
    }
    for l in 0..nl {
        let parent = model.link_parent[l];
        if parent != NO_LINK && parent as usize >= l {
            return bad(
                "link_parent",
                format!("link {l} ({}) has parent {parent}", model.link_name[l]),
                "a parent listed before its child (or NO_LINK for the root)".into(),
            );
        }
        let d = model.link_dof[l];
        let fixed = model.link_joint[l] == JointKind::Fixed;
        if d != NO_DOF && (d as usize >= n || fixed) {
            return bad(
                "link_dof",
                format!("link {l} ({}) with a {:?} joint has dof {d}", model.link_name[l], model.link_joint[l]),
                format!("a dof index below {n} for a moving joint, NO_DOF for a fixed one"),
            );
        }
    }
    if frame.link as usize >= nl {
        return bad(
            "frame.link",
            format!("{} (frame '{}')", frame.link, frame.name),
            format!("a link index below {nl}"),
        );
    }
    if world_count == 0 {
        return bad("world_count", "0".into(), "at least 1".into());
    }
    if !(dt.is_finite() && dt > 0.0) {
        return bad("dt", dt.to_string(), "a time step > 0 [s]".into());
    }
    if substeps == 0 {
        return bad("substeps", "0".into(), "at least 1".into());
    }
    Ok(())
}

/// Loop passes of one substep of articulation_core.wgsl (forward kinematics, free_velocity,
/// integrate_positions) and of one cholesky_substitute, counted as [`loop_passes`] counts.
pub(crate) fn substep_loop_passes(model: &ArticulationModel) -> (u64, u64) {
    let (nl, n) = (model.link_count() as u64, model.dof_count() as u64);
    let cholesky: u64 = (n + 1) + (0..n).map(|j| (j + 1) + (n - j) + (n - j - 1) * (j + 1)).sum::<u64>();
    let substitute: u64 = 2 * ((n + 1) + (0..n).map(|i| i + 1).sum::<u64>());
    let substep = (nl + 1) + mass_matrix_passes(model) + 2 * (nl + 1) + (n + 1) + cholesky + substitute + 2 * (n + 1);
    (substep, substitute)
}

/// Links on the path from `l` to the root, and the dofs among them.
pub(crate) fn chain_len(model: &ArticulationModel, l: u32) -> (u64, u64) {
    let (mut links, mut dofs, mut a) = (0, 0, l);
    while a != NO_LINK {
        links += 1;
        dofs += (model.link_dof[a as usize] != NO_DOF) as u64;
        a = model.link_parent[a as usize];
    }
    (links, dofs)
}

fn mass_matrix_passes(model: &ArticulationModel) -> u64 {
    let (nl, n) = (model.link_count() as u64, model.dof_count() as u64);
    (n * n + 1)
        + (nl + 1)
        + (0..nl as u32)
            .filter(|&l| model.link_mass[l as usize] > 0.0)
            .map(|l| {
                let (links, k) = chain_len(model, l);
                (links + 1) + (k + 1) + k * (k + 1) / 2 + k
            })
            .sum::<u64>()
        + (n + 1)
}

/// Loop passes one invocation makes in articulation.wgsl (and articulation_core.wgsl): (one `step` of `substeps` substeps, one
/// `dynamics` at `frame`), each loop of p passes counted p + 1 as llvmpipe counts them; keep it in step
/// with the shader's loops. For the Franka: 885 per substep (1791 for a step of 2) and 760 for `dynamics`.
/// Checked on lavapipe with the budget lifted: a Franka step matches the CPU up to 72
/// substeps (counted 63741) and is cut short from 73 (counted 64626), so the count runs at most ~1.5%
/// under llvmpipe's, well inside the 1/8 of the limit [`ArticulationGpu::new`] keeps in reserve.
pub fn loop_passes(model: &ArticulationModel, frame: &Frame, substeps: u32) -> (u64, u64) {
    let (nl, n) = (model.link_count() as u64, model.dof_count() as u64);
    let chain = |l: u32| chain_len(model, l);
    let mass_matrix = mass_matrix_passes(model);
    let inverse_dynamics = 2 * (nl + 1);
    let (substep, _) = substep_loop_passes(model);
    let step = 2 * (n + 1) + substeps as u64 * substep + substeps as u64 + 1;
    let (frame_links, frame_dofs) = chain(frame.link);
    let dynamics = (n + 1)
        + 2 * (nl + 1)
        + (6 * n + 1)
        + (frame_links + 1)
        + 4 * frame_dofs
        + 5
        + mass_matrix
        + (n + 1)
        + (0..n).map(|i| i + 2).sum::<u64>()
        + 2 * (inverse_dynamics + n + 1);
    (step, dynamics)
}

/// The articulation of `world_count` worlds on the GPU: model, state, control and output buffers, and the
/// `dynamics` and `step` pipelines. The buffers are public so other kernels (controllers, the env) bind
/// them directly.
pub struct ArticulationGpu {
    /// Worlds in the batch (one articulation each).
    pub world_count: u32,
    /// Links and degrees of freedom per world.
    pub link_count: u32,
    pub dof_count: u32,
    /// Frame time step [s] and substeps per frame of [`encode_step`](Self::encode_step).
    pub dt: f32,
    pub substeps: u32,
    /// Layout of the records in `world_dynamics`.
    pub layout: DynamicsLayout,
    /// Joint positions [rad or m], f32, shape [world_count * dof_count].
    pub joint_q: wgpu::Buffer,
    /// Joint velocities [rad/s or m/s], f32, shape [world_count * dof_count].
    pub joint_qd: wgpu::Buffer,
    /// Joint torques or forces [N m or N], f32, shape [world_count * dof_count], held over a step.
    pub joint_tau: wgpu::Buffer,
    /// Position-drive targets [rad or m], f32, shape [world_count * dof_count]; read only while the
    /// drives are on ([`set_drives`](Self::set_drives)).
    pub joint_target_q: wgpu::Buffer,
    /// Link poses in the world written by `dynamics`: per link a position vec4 (xyz [m], 0) and a
    /// rotation vec4 (x, y, z, w), shape [world_count * link_count * 2] vec4.
    pub link_pose: wgpu::Buffer,
    /// Per world a record of f32 ([`DynamicsLayout`]) written by `dynamics`: the frame's pose and twist,
    /// its Jacobian, M, g, c; shape [world_count * layout.stride].
    pub world_dynamics: wgpu::Buffer,
    drives: bool,
    dynamics_pipeline: wgpu::ComputePipeline,
    step_pipeline: wgpu::ComputePipeline,
    /// Group 0 with the drives off and on (the flag is in the uniform, which is immutable; choosing the bind
    /// group at encode time needs no uniform write).
    model_groups: [wgpu::BindGroup; 2],
    control_group: wgpu::BindGroup,
    state_group: wgpu::BindGroup,
    _layout: ExplicitLayout,
}

impl ArticulationGpu {
    /// Uploads `model` for `world_count` worlds (every world at q = 0, at rest, no torque, drives off),
    /// with `frame` the frame `dynamics` reports and `dt` [s], `substeps` the step's. Refuses what
    /// [`validate`] refuses, buffers beyond the device's binding size ([`EngineError::TooLarge`]), and on a
    /// software adapter a step or dynamics pass beyond lavapipe's loop budget (field `substeps`).
    pub fn new(
        gpu: &GpuContext,
        model: &ArticulationModel,
        world_count: u32,
        frame: &Frame,
        dt: f32,
        substeps: u32,
    ) -> Result<Self> {
        validate(model, world_count, frame, dt, substeps)?;
        if gpu.is_software() {
            let budget = crate::contact::LOOP_ITERATION_LIMIT as u64 / 8 * 7;
            let (step, dynamics) = loop_passes(model, frame, substeps);
            if step.max(dynamics) > budget {
                return Err(EngineError::Config {
                    field: "substeps",
                    value: format!("{substeps}: {step} loop passes per step, {dynamics} per dynamics pass"),
                    expected: format!(
                        "at most {budget} loop passes on a software adapter (llvmpipe's loop limit); use fewer substeps"
                    ),
                });
            }
        }
        let (nl, n) = (model.link_count() as u32, model.dof_count() as u32);
        let layout = DynamicsLayout::new(n);
        let limit = gpu.limits().max_storage_buffer_binding_size;
        let record_bytes = world_count as u64 * layout.stride as u64 * 4;
        let pose_bytes = world_count as u64 * nl as u64 * 32;
        if record_bytes.max(pose_bytes) > limit {
            return Err(EngineError::TooLarge {
                what: format!("articulation outputs for {world_count} worlds"),
                needed_bytes: record_bytes.max(pose_bytes),
                limit_bytes: limit,
                hint: "use fewer worlds per ArticulationGpu".into(),
            });
        }
        let (fp, fq) = frame.offset;
        let params = |drives: bool| ArticulationParamsGpu {
            world_count,
            link_count: nl,
            dof_count: n,
            frame_link: frame.link,
            frame_p: fp.extend(0.0).to_array(),
            frame_q: fq.to_array(),
            gravity: model.gravity.extend(0.0).to_array(),
            dt,
            substeps,
            drives: drives as u32,
            dynamics_stride: layout.stride,
            jacobian_offset: layout.jacobian,
            mass_offset: layout.mass_matrix,
            gravity_offset: layout.gravity_torque,
            coriolis_offset: layout.coriolis_torque,
        };
        let none = wgpu::BufferUsages::empty();
        let links = gpu.storage_buffer("articulation-links", &links_gpu(model), none);
        // A model without dofs still binds one (unread) entry: a binding must hold at least one element.
        let mut dof_entries = dofs_gpu(model);
        if dof_entries.is_empty() {
            dof_entries.push(DofGpu::zeroed());
        }
        let dofs = gpu.storage_buffer("articulation-dofs", &dof_entries, none);
        let uniforms =
            [false, true].map(|on| gpu.uniform_buffer("articulation-params", bytemuck::bytes_of(&params(on))));
        let joint_bytes = world_count as u64 * n as u64 * 4;
        let joint_q = gpu.storage_buffer_zeroed("joint_q", joint_bytes);
        let joint_qd = gpu.storage_buffer_zeroed("joint_qd", joint_bytes);
        let joint_tau = gpu.storage_buffer_zeroed("joint_tau", joint_bytes);
        let joint_target_q = gpu.storage_buffer_zeroed("joint_target_q", joint_bytes);
        let link_pose = gpu.storage_buffer_zeroed("link_pose", pose_bytes);
        let world_dynamics = gpu.storage_buffer_zeroed("world_dynamics", record_bytes);
        let ro = Binding::Storage { read_only: true };
        let rw = Binding::Storage { read_only: false };
        let pipeline_layout =
            gpu.explicit_layout("articulation", &[&[Binding::Uniform, ro, ro], &[ro, ro], &[rw, rw, rw, rw]]);
        let dynamics_pipeline =
            gpu.pipeline_on(&pipeline_layout, "articulation-dynamics", ARTICULATION_WGSL, "dynamics");
        let step_pipeline = gpu.pipeline_on(&pipeline_layout, "articulation-step", ARTICULATION_WGSL, "step");
        let model_groups = [0, 1].map(|i| gpu.bind_explicit(&pipeline_layout, 0, &[&uniforms[i], &links, &dofs], 0));
        let control_group = gpu.bind_explicit(&pipeline_layout, 1, &[&joint_tau, &joint_target_q], 0);
        let state_group =
            gpu.bind_explicit(&pipeline_layout, 2, &[&joint_q, &joint_qd, &link_pose, &world_dynamics], 0);
        Ok(ArticulationGpu {
            world_count,
            link_count: nl,
            dof_count: n,
            dt,
            substeps,
            layout,
            joint_q,
            joint_qd,
            joint_tau,
            joint_target_q,
            link_pose,
            world_dynamics,
            drives: false,
            dynamics_pipeline,
            step_pipeline,
            model_groups,
            control_group,
            state_group,
            _layout: pipeline_layout,
        })
    }

    fn check_shape(&self, field: &'static str, len: usize) -> Result<()> {
        let want = self.world_count as usize * self.dof_count as usize;
        if len == want {
            return Ok(());
        }
        Err(EngineError::Config {
            field,
            value: format!("{len} entries"),
            expected: format!("world_count x dof_count = {} x {} = {want}", self.world_count, self.dof_count),
        })
    }

    /// Uploads every world's joint state (queued: it lands before the next submission's commands).
    pub fn write_state(&self, gpu: &GpuContext, state: &ArticulationState) -> Result<()> {
        self.check_shape("joint_q", state.joint_q.len())?;
        self.check_shape("joint_qd", state.joint_qd.len())?;
        if !state.joint_q.is_empty() {
            gpu.queue.write_buffer(&self.joint_q, 0, bytemuck::cast_slice(&state.joint_q));
            gpu.queue.write_buffer(&self.joint_qd, 0, bytemuck::cast_slice(&state.joint_qd));
        }
        Ok(())
    }

    /// Sets the control held over the following steps, as [`super::dynamics::step_cpu`] reads it: an
    /// empty `joint_tau` is zero torque, an empty `joint_target_q` turns the drives off, a full one writes
    /// the targets and turns them on. The buffers are written by queue (before the next submission); the
    /// drive flag applies to steps encoded after this call.
    pub fn write_control(&mut self, gpu: &GpuContext, control: &ArticulationControl) -> Result<()> {
        if !control.joint_tau.is_empty() {
            self.check_shape("joint_tau", control.joint_tau.len())?;
        }
        if !control.joint_target_q.is_empty() {
            self.check_shape("joint_target_q", control.joint_target_q.len())?;
        }
        if control.joint_tau.is_empty() {
            let mut enc = gpu.device.create_command_encoder(&Default::default());
            enc.clear_buffer(&self.joint_tau, 0, None);
            gpu.queue.submit([enc.finish()]);
        } else {
            gpu.queue.write_buffer(&self.joint_tau, 0, bytemuck::cast_slice(&control.joint_tau));
        }
        if !control.joint_target_q.is_empty() {
            gpu.queue.write_buffer(&self.joint_target_q, 0, bytemuck::cast_slice(&control.joint_target_q));
        }
        self.drives = !control.joint_target_q.is_empty();
        Ok(())
    }

    /// Turns the position drives on or off for steps encoded from now on (for targets a kernel writes into
    /// `joint_target_q` on the device).
    pub fn set_drives(&mut self, on: bool) {
        self.drives = on;
    }

    /// Whether steps encoded now use the position drives.
    pub fn drives(&self) -> bool {
        self.drives
    }

    fn encode(&self, encoder: &mut wgpu::CommandEncoder, label: &str, pipeline: &wgpu::ComputePipeline) {
        let mut pass =
            encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some(label), timestamp_writes: None });
        pass.set_pipeline(pipeline);
        pass.set_bind_group(0, &self.model_groups[self.drives as usize], &[]);
        pass.set_bind_group(1, &self.control_group, &[]);
        pass.set_bind_group(2, &self.state_group, &[]);
        pass.dispatch_workgroups(self.world_count.div_ceil(ARTICULATION_WG), 1, 1);
    }

    /// Records the `dynamics` pass: link poses and each world's record in `world_dynamics` at the current
    /// joint state ([`super::dynamics::world_dynamics`] for every world).
    pub fn encode_dynamics(&self, encoder: &mut wgpu::CommandEncoder) {
        self.encode(encoder, "articulation-dynamics", &self.dynamics_pipeline);
    }

    /// Records one frame of `dt` in `substeps` substeps for every world ([`super::dynamics::step_world`]),
    /// in place on `joint_q` and `joint_qd`.
    pub fn encode_step(&self, encoder: &mut wgpu::CommandEncoder) {
        self.encode(encoder, "articulation-step", &self.step_pipeline);
    }

    /// Reads the joint state back (waits for the GPU; for tests and logging, never in a step loop).
    pub fn read_state(&self, gpu: &GpuContext) -> ArticulationState {
        let len = self.world_count as usize * self.dof_count as usize;
        let mut joint_q: Vec<f32> = gpu.read_buffer(&self.joint_q);
        let mut joint_qd: Vec<f32> = gpu.read_buffer(&self.joint_qd);
        // Buffers hold at least 4 bytes, so a model without dofs reads one float too many.
        joint_q.truncate(len);
        joint_qd.truncate(len);
        ArticulationState { joint_q, joint_qd }
    }

    /// Reads what the last `dynamics` pass wrote, one [`WorldDynamics`] per world (waits for the GPU).
    pub fn read_dynamics(&self, gpu: &GpuContext) -> Vec<WorldDynamics> {
        let (nl, n) = (self.link_count as usize, self.dof_count as usize);
        let poses: Vec<[f32; 4]> = gpu.read_buffer(&self.link_pose);
        let records: Vec<f32> = gpu.read_buffer(&self.world_dynamics);
        let lay = self.layout;
        let v3 = |s: &[f32]| Vec3::new(s[0], s[1], s[2]);
        (0..self.world_count as usize)
            .map(|w| {
                let r = &records[w * lay.stride as usize..(w + 1) * lay.stride as usize];
                let at = |offset: u32, len: usize| r[offset as usize..offset as usize + len].to_vec();
                WorldDynamics {
                    link_pose: (0..nl)
                        .map(|l| {
                            let i = 2 * (w * nl + l);
                            (Vec4::from_array(poses[i]).truncate(), Quat::from_array(poses[i + 1]))
                        })
                        .collect(),
                    frame_pose: (v3(&r[0..3]), Quat::from_slice(&r[4..8])),
                    frame_linvel: v3(&r[8..11]),
                    frame_angvel: v3(&r[12..15]),
                    jacobian: at(lay.jacobian, 6 * n),
                    mass_matrix: at(lay.mass_matrix, n * n),
                    gravity_torque: at(lay.gravity_torque, n),
                    coriolis_torque: at(lay.coriolis_torque, n),
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::articulation::JointKind;
    use glam::Mat3;

    /// A chain of `links` links (a fixed root, then revolute joints about y, 0.1 m apart, 1 kg each).
    fn chain(links: usize) -> ArticulationModel {
        let n = links - 1;
        ArticulationModel {
            name: "chain".into(),
            link_name: (0..links).map(|l| format!("l{l}")).collect(),
            link_parent: (0..links as u32).map(|l| if l == 0 { NO_LINK } else { l - 1 }).collect(),
            link_joint: (0..links).map(|l| if l == 0 { JointKind::Fixed } else { JointKind::Revolute }).collect(),
            link_dof: (0..links as u32).map(|l| if l == 0 { NO_DOF } else { l - 1 }).collect(),
            link_origin: (0..links).map(|l| (Vec3::X * 0.1 * (l > 0) as u32 as f32, Quat::IDENTITY)).collect(),
            link_axis: vec![Vec3::Y; links],
            link_mass: vec![1.0; links],
            link_com: vec![Vec3::X * 0.05; links],
            link_inertia: vec![Mat3::from_diagonal(Vec3::splat(1e-3)); links],
            dof_name: (0..n).map(|d| format!("j{d}")).collect(),
            dof_link: (1..links as u32).collect(),
            dof_lower: vec![-1.0; n],
            dof_upper: vec![1.0; n],
            dof_velocity_limit: vec![f32::INFINITY; n],
            dof_effort_limit: vec![f32::INFINITY; n],
            dof_damping: vec![0.0; n],
            dof_armature: vec![0.0; n],
            dof_drive_stiffness: vec![0.0; n],
            dof_drive_damping: vec![0.0; n],
            frames: vec![],
            gravity: Vec3::new(0.0, 0.0, -9.81),
        }
    }

    fn tip(model: &ArticulationModel) -> Frame {
        Frame { name: "tip".into(), link: model.link_count() as u32 - 1, offset: (Vec3::ZERO, Quat::IDENTITY) }
    }

    /// Both entry points parse and validate with naga, without subgroup operations (no GPU needed).
    #[test]
    fn articulation_shader_validates_with_naga() {
        if let Err(e) = crate::contact::shader_tests::validate(ARTICULATION_WGSL, false) {
            panic!("articulation.wgsl:\n{e}");
        }
    }

    /// The Pod mirrors have the sizes and field offsets naga lays the WGSL structs out with.
    #[test]
    fn articulation_shader_structs_match_their_mirrors() {
        let module = naga::front::wgsl::parse_str(ARTICULATION_WGSL).expect("parses");
        let mut layouter = naga::proc::Layouter::default();
        layouter.update(module.to_ctx()).expect("lays out");
        let layout_of = |name: &str| {
            let (h, ty) = module.types.iter().find(|(_, t)| t.name.as_deref() == Some(name)).expect(name);
            let naga::TypeInner::Struct { members, .. } = &ty.inner else { panic!("{name} is a struct") };
            (layouter[h].size as usize, members.iter().map(|m| m.offset as usize).collect::<Vec<_>>())
        };
        let (size, offsets) = layout_of("Link");
        assert_eq!(size, std::mem::size_of::<LinkGpu>());
        assert_eq!(offsets, [0, 16, 32, 48, 64, 112, 116, 120, 124]);
        assert_eq!(layout_of("Dof").0, std::mem::size_of::<DofGpu>());
        let (size, offsets) = layout_of("ArtParams");
        assert_eq!(size, std::mem::size_of::<ArticulationParamsGpu>());
        assert_eq!(offsets, [0, 4, 8, 12, 16, 32, 48, 64, 68, 72, 76, 80, 84, 88, 92]);
    }

    #[test]
    fn models_beyond_the_kernel_bounds_are_refused_by_name() {
        let field = |r: Result<()>| match r {
            Err(EngineError::Config { field, .. }) => field,
            other => panic!("expected a Config error, got {other:?}"),
        };
        let ok = chain(4);
        assert!(validate(&ok, 1, &tip(&ok), 1.0 / 60.0, 2).is_ok());
        // 17 dofs in 18 links.
        let big = chain(MAX_DOFS + 2);
        assert_eq!(field(validate(&big, 1, &tip(&big), 1.0 / 60.0, 2)), "dof_count");
        // 33 links, 16 dofs (the rest fixed).
        let mut long = chain(MAX_LINKS + 1);
        for l in MAX_DOFS + 1..=MAX_LINKS {
            long.link_joint[l] = JointKind::Fixed;
            long.link_dof[l] = NO_DOF;
        }
        let n = MAX_DOFS;
        long.dof_name.truncate(n);
        for v in [
            &mut long.dof_lower,
            &mut long.dof_upper,
            &mut long.dof_velocity_limit,
            &mut long.dof_effort_limit,
            &mut long.dof_damping,
            &mut long.dof_armature,
            &mut long.dof_drive_stiffness,
            &mut long.dof_drive_damping,
        ] {
            v.truncate(n);
        }
        long.dof_link.truncate(n);
        assert_eq!(field(validate(&long, 1, &tip(&long), 1.0 / 60.0, 2)), "link_count");
        let frame = Frame { link: 4, ..tip(&ok) };
        assert_eq!(field(validate(&ok, 1, &frame, 1.0 / 60.0, 2)), "frame.link");
        let mut swapped = ok.clone();
        swapped.link_parent[1] = 2;
        assert_eq!(field(validate(&swapped, 1, &tip(&ok), 1.0 / 60.0, 2)), "link_parent");
        let mut fixed_with_dof = ok.clone();
        fixed_with_dof.link_joint[1] = JointKind::Fixed;
        assert_eq!(field(validate(&fixed_with_dof, 1, &tip(&ok), 1.0 / 60.0, 2)), "link_dof");
        let mut short = ok.clone();
        short.dof_armature.pop();
        assert_eq!(field(validate(&short, 1, &tip(&ok), 1.0 / 60.0, 2)), "dof_armature");
        assert_eq!(field(validate(&ok, 0, &tip(&ok), 1.0 / 60.0, 2)), "world_count");
        assert_eq!(field(validate(&ok, 1, &tip(&ok), 0.0, 2)), "dt");
        assert_eq!(field(validate(&ok, 1, &tip(&ok), 1.0 / 60.0, 0)), "substeps");
        let e = validate(&big, 1, &tip(&big), 1.0 / 60.0, 2).unwrap_err().to_string();
        assert!(e.contains("17") && e.contains("16"), "{e}");
    }

    /// The largest model the kernel takes still fits lavapipe's loop budget for a `dynamics` pass and a
    /// few substeps, so the bounds are usable on the CPU fallback.
    #[test]
    fn the_largest_model_fits_the_software_loop_budget() {
        let mut m = chain(MAX_DOFS + 1);
        // A long fixed tail up to MAX_LINKS, every link massive: the worst case of the mass-matrix loops.
        for l in MAX_DOFS + 1..MAX_LINKS {
            m.link_name.push(format!("l{l}"));
            m.link_parent.push(l as u32 - 1);
            m.link_joint.push(JointKind::Fixed);
            m.link_dof.push(NO_DOF);
            m.link_origin.push((Vec3::X * 0.1, Quat::IDENTITY));
            m.link_axis.push(Vec3::Y);
            m.link_mass.push(1.0);
            m.link_com.push(Vec3::ZERO);
            m.link_inertia.push(Mat3::IDENTITY);
        }
        let budget = crate::contact::LOOP_ITERATION_LIMIT as u64 / 8 * 7;
        let (step, dynamics) = loop_passes(&m, &tip(&m), 4);
        assert!(step <= budget && dynamics <= budget, "step {step}, dynamics {dynamics}, budget {budget}");
    }

    #[test]
    fn dynamics_records_are_vec4_aligned_and_disjoint() {
        for n in 0..=MAX_DOFS as u32 {
            let l = DynamicsLayout::new(n);
            assert_eq!(l.stride % 4, 0);
            assert!(l.jacobian >= 16 && l.mass_matrix >= l.jacobian + 6 * n);
            assert!(l.gravity_torque >= l.mass_matrix + n * n && l.coriolis_torque >= l.gravity_torque + n);
            assert!(l.stride >= l.coriolis_torque + n);
        }
    }
}

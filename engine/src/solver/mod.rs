//! Rigid-body dynamics with a Gauss-Seidel contact solver (paper III-B: after contact reduction, a
//! Gauss-Seidel solver converges in 1 substep and ~16-20 iterations at dt = 1/60 s where Jacobi needs 8
//! substeps and 64 iterations).
//!
//! The plain-Rust reference is [`step_cpu`]: each world on its own, contacts in a fixed order, so results
//! are bitwise reproducible (worlds run in parallel on rayon and do not depend on the thread count). The
//! GPU kernels mirror it ([`gpu`], [`articulated`]: one invocation per world, as Gauss-Seidel is serial
//! inside a world and parallel across worlds).
//!
//! Scheme, per substep of length h = dt / substeps (a TGS-style "soft step" in the spirit of PhysX TGS and
//! Box2D v3): (1) integrate velocities (gravity); (2) `pos_iters` Gauss-Seidel sweeps over the contacts
//! with a position bias; (3) integrate positions; (4) `vel_iters` sweeps without the penetration bias
//! (v_n >= 0 for touching contacts, restitution 0). A contact is the reduced contact's point anchored in
//! the query body; at every substep (positions) and after it (velocities) its separation s and normal n
//! are re-evaluated by sampling the SDF shape at the anchor's current position (the SDF is at hand, so no
//! linearisation: a nut that turns 27 degrees in one 1/60 s frame would otherwise see its flank contacts,
//! projected on frame-start tangent planes, penetrate by ~0.4 mm and be pushed back). The normal velocity is driven to v_n >= -s/h when
//! separated (speculative: approach at most the gap) or to v_n >= min(-s/h, max_depenetration_velocity)
//! when penetrating.
//! Friction: Coulomb per contact, the two tangential impulses clamped to mu times the normal impulse (or,
//! with `friction_per_patch`, to mu times the patch's normal impulse per contact).
//! Accumulated impulses are clamped per substep (Catto 2005, "Iterative dynamics with temporal coherence").
//!
//! Warm starting: each substep starts by re-applying the previous substep's impulses, and each frame's
//! rows inherit impulses from last frame's: contacts are generated afresh every frame, so a row looks for
//! itself among the rows of the same patch of the same pair last frame (anchor on a and point on b within
//! a tenth of the contact offset, normals within ~10 deg) and takes over the closest one's impulses.
//! Without it a 3-box stack slides about a millimetre in 5 s at 20 sweeps (80 are needed); with it, well
//! under a fifth of a millimetre (engine/tests/solver_stability.rs).
//!
//! Patch iterations: a tall, narrow body (a 4 mm peg, 50 mm long, standing on its 3 mm bottom face)
//! rests on one patch whose contacts push almost alike (their lever arms differ by millimetres against a
//! 25 mm height), which makes the patch's tilting mode converge ~100 times slower than its lift under
//! Gauss-Seidel: at 2 x 16 sweeps the peg rocks at 0.2-0.5 rad/s and topples off a table within 1.5 s.
//! Re-sweeping each patch alone `patch_iters` times per sweep (cheap: the geometry is already sampled)
//! solves the patch almost exactly: at 10 the peg stands still.
//!
//! PGS, not TGS, by measurement on the tests of engine/tests: a TGS variant (a position update after
//! every position sweep, PhysX TGS / Macklin et al. 2019 "Small steps in physics simulation", with
//! per-step impulses and warm starting) lets a box resting on the table creep at 3.9e-2 mm/s (PGS: 2e-7),
//! breaks the depenetration-velocity bound and only halves the stack's slide; the contact rows are
//! anchored at the frame's start and re-sampled at every sweep, which is what TGS's linearised
//! separation buys elsewhere.
//!
//! Files: `model.rs` the bodies, state, control and settings; `cpu.rs` the CPU step over worlds;
//! `rows.rs` the contact rows and what their update reads; `sweep.rs` the Gauss-Seidel sweeps;
//! `warm_start.rs` the rows carried across frames; [`gpu`] and [`articulated`] the device steps.

pub mod articulated;
mod cpu;
pub mod gpu;
mod model;
mod rows;
mod sweep;
mod warm_start;

pub use cpu::{
    step_cpu, step_cpu_articulated, step_cpu_articulated_with, step_cpu_with_pipeline, ArticulationStep, PatchSweep,
};
pub use model::{transform, BodyModel, BodyState, Control, SolverConfig};
pub use warm_start::WarmStart;

/// WGSL: `any_orthonormal(n)`, the contact rows' first tangent (glam's `any_orthonormal_vector`), for kernels
/// outside the engine that read the rows' impulses ([`articulated::RowsLayout`]).
pub const ANY_ORTHONORMAL_WGSL: &str = include_str!("orthonormal.wgsl");

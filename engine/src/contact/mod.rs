//! Contact generation and reduction (paper III-A and III-C).
//!
//! A shape pair is an SDF shape `b` (a baked [`SdfGrid`] or an analytic half-space) and a query shape `a`
//! given as triangles with a radius: a triangle mesh (radius 0), a box (its 12 triangles), a sphere (one
//! degenerate triangle at its centre) or a capsule (a degenerate triangle along its segment). For every
//! query triangle the GPU finds the point of least signed distance by projected gradient descent
//! ([`generate`]), keeps it when within the contact offset, and bins the candidates into patches in
//! workgroup memory; [`merge`] combines the per-job patches of each pair into at most `max_patches`
//! patches of at most 4 contacts each. [`reduce`] is the CPU twin of the reduction.
//!
//! Conventions for the solver: a contact's `point` lies on shape `a`'s surface in world coordinates, its
//! `depth` is the signed distance to shape `b` (negative = penetration) and the patch `normal` points out of
//! `b` towards `a`. The matching point on `b` is `point - depth * normal`.
//!
//! Pair roles follow Factory (PhysX SDF collisions): both shapes tagged with an SDF -> the one with more
//! triangles is the SDF and the other's triangles are queried; one tagged -> the untagged shape's convex
//! hull is queried against the tagged one's SDF; none tagged -> convex-convex ([`pair_role`]).

pub mod generate;
pub mod merge;
pub mod model;
pub mod normals;
pub mod pipeline;
pub mod reduce;
pub mod roles;

pub use model::{ContactModel, PairSpec, QueryShape, SdfShape, NO_BODY};
pub use pipeline::{contacts_cpu, ContactPipeline, ContactsHost, TransformGpu};

use crate::error::{EngineError, Result};
use glam::Vec3;

/// Settings of the contact pipeline. Build the pipeline once per configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct ContactConfig {
    /// Patch budget per shape pair (paper: 128..256); 16..=256.
    pub max_patches: u32,
    /// Two normals belong to one patch when their dot product is at least this (cosine of the angle).
    pub normal_cos: f32,
    /// Projected-gradient iterations per triangle.
    pub iterations: u32,
    /// Query triangles per generation workgroup; 0 picks a value from the world count at build time.
    pub chunk_triangles: u32,
}

impl Default for ContactConfig {
    fn default() -> Self {
        ContactConfig { max_patches: 64, normal_cos: 10f32.to_radians().cos(), iterations: 12, chunk_triangles: 0 }
    }
}

impl ContactConfig {
    /// Refuses out-of-range values, naming the field.
    pub fn validate(&self) -> Result<()> {
        if !(16..=256).contains(&self.max_patches) {
            return Err(EngineError::Config {
                field: "max_patches",
                value: self.max_patches.to_string(),
                expected: "an integer in 16..=256".into(),
            });
        }
        if !(self.normal_cos > -1.0 && self.normal_cos < 1.0) {
            return Err(EngineError::Config {
                field: "normal_cos",
                value: self.normal_cos.to_string(),
                expected: "a cosine strictly between -1 and 1".into(),
            });
        }
        if self.iterations > 256 {
            return Err(EngineError::Config {
                field: "iterations",
                value: self.iterations.to_string(),
                expected: "0..=256".into(),
            });
        }
        if self.chunk_triangles != 0 && self.chunk_triangles % 256 != 0 {
            return Err(EngineError::Config {
                field: "chunk_triangles",
                value: self.chunk_triangles.to_string(),
                expected: "0 (automatic) or a multiple of 256".into(),
            });
        }
        Ok(())
    }

    /// Bytes of workgroup memory the kernels need for this patch budget (see common.wgsl).
    pub fn workgroup_bytes(&self) -> u32 {
        let cap = self.max_patches + 1;
        256 * 16 * 2 + 256 * 4 + cap * (16 + 4 + 4 * 16 + 4) + 12
    }
}

/// One reduced contact.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Contact {
    /// Point on shape a's surface, world frame [m].
    pub point: Vec3,
    /// Signed distance to shape b [m]; negative when penetrating.
    pub depth: f32,
    /// Outward normal of shape b at the contact, world frame (the patch's `normal` is shared by its
    /// contacts; this one is local, so curved surfaces keep their exact normal).
    pub normal: Vec3,
}

/// A patch: contacts that share a normal.
#[derive(Clone, Debug, PartialEq)]
pub struct Patch {
    /// Unit normal out of shape b, world frame.
    pub normal: Vec3,
    /// Summed area of the query triangles binned into the patch [m^2].
    pub area: f32,
    /// At most 4 contacts: the deepest first.
    pub contacts: Vec<Contact>,
}

/// What the narrow phase does for a pair of shapes (Factory's rules).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PairRole {
    /// Query `query`'s triangles against `sdf`'s SDF (indices 0 = first shape, 1 = second).
    SdfMesh { sdf: usize, query: usize },
    /// Query the convex hull of `hull` against `sdf`'s SDF.
    ConvexMesh { sdf: usize, hull: usize },
    /// Neither shape has an SDF.
    ConvexConvex,
}

/// Factory's pair roles from the SDF tags and triangle counts of two shapes.
pub fn pair_role(tagged: [bool; 2], triangles: [usize; 2]) -> PairRole {
    match tagged {
        [true, true] => {
            let sdf = if triangles[1] > triangles[0] { 1 } else { 0 };
            PairRole::SdfMesh { sdf, query: 1 - sdf }
        }
        [true, false] => PairRole::ConvexMesh { sdf: 0, hull: 1 },
        [false, true] => PairRole::ConvexMesh { sdf: 1, hull: 0 },
        [false, false] => PairRole::ConvexConvex,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roles_follow_factory() {
        assert_eq!(pair_role([true, true], [15078, 25672]), PairRole::SdfMesh { sdf: 1, query: 0 });
        assert_eq!(pair_role([true, true], [900, 100]), PairRole::SdfMesh { sdf: 0, query: 1 });
        assert_eq!(pair_role([false, true], [12, 100]), PairRole::ConvexMesh { sdf: 1, hull: 0 });
        assert_eq!(pair_role([false, false], [12, 12]), PairRole::ConvexConvex);
    }

    #[test]
    fn config_is_validated() {
        assert!(ContactConfig::default().validate().is_ok());
        let e = ContactConfig { max_patches: 300, ..Default::default() }.validate().unwrap_err().to_string();
        assert!(e.contains("max_patches") && e.contains("16..=256"), "{e}");
        // The budget of 256 patches fits the 32 KiB of workgroup memory most GPUs offer.
        assert!(ContactConfig { max_patches: 256, ..Default::default() }.workgroup_bytes() <= 32768);
        assert!(ContactConfig::default().workgroup_bytes() <= 16384);
    }
}
#[cfg(test)]
mod shader_tests;

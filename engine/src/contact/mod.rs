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
    /// At most [`max_chunk_triangles`](Self::max_chunk_triangles).
    pub chunk_triangles: u32,
    /// With `chunk_triangles = 0`: the world count the automatic split assumes; 0 (the default) takes the
    /// pipeline's own. The split gives a pair more, shorter jobs the fewer worlds there are (to fill the
    /// device), and it decides which candidates share a reduction batch, hence which patches are kept: with
    /// the split left to the world count, a world's contacts (and its trajectory) depend on how many worlds
    /// are stepped with it. Fixing it (any value of 64 or more gives one job per pair where the loop budget
    /// allows) makes a world's physics the same in a batch of any size.
    pub chunk_world_count: u32,
    /// Invocations per workgroup of the generate and merge kernels (32, 64, 128 or 256); a reduction batch
    /// holds [`batch_size`](Self::batch_size) candidates, and the CPU twin cuts its batches to that size.
    /// Default 64: on lavapipe (which runs a workgroup as width/8 coroutines) it is faster (M16 nut-bolt grid SDF: GPU/twin time
    /// 0.74 vs 1.31 at 1 world, 1.33 vs 1.57 at 64 worlds), except with the analytic bolt SDF at 64
    /// worlds (1.13 vs 0.87); on a GPU 64 is two warps or one wave64.
    pub workgroup_size: u32,
    /// Candidates each invocation of the generate and merge kernels holds per batch (1, 2 or 4), so a batch
    /// holds `workgroup_size * candidates_per_invocation` (at most 256) candidates. lavapipe runs every
    /// workgroup-memory instruction lane by lane, so the reduction costs its memory instructions per lane;
    /// an invocation with several candidates (consecutive query triangles, which the pipelines then order
    /// by normal within each job: [`model::normal_ordered`]) reads the patch list once for all of them
    /// (common.wgsl). Default 1. With 4 the M16 nut-bolt pair's contact handling is faster on lavapipe
    /// (docs/BENCHMARKS.md) and its descent and self-locking keep their accuracy, but larger
    /// batches in another order keep other contacts, and the single-seed rest tests of the peg and the
    /// piles came out otherwise (the aligned peg rocking at a median 1.18e-3 m/s against the bound of
    /// 1e-3; the seed-1 torus and 64-nut piles creeping 8.8 and 2.0 mm in their last second).
    pub candidates_per_invocation: u32,
    /// Use subgroup operations in the reduction where the device has them, with at least 8 lanes
    /// (reduce_subgroup.wgsl; lavapipe has 8: about 1.1x faster there, see docs/BENCHMARKS.md); false: the
    /// portable kernels. The results are bitwise the same either way.
    pub subgroups: bool,
    /// With 4 candidates per invocation and analytic thread SDFs only: run an invocation's four query
    /// triangles' descents side by side, as vectors across the triangles (generate_core.wgsl
    /// `triangles4`); false: one after another. The results are bitwise the same either way; on lavapipe
    /// side by side is about 1.25x faster (the samples' division and square-root chains overlap; see
    /// docs/BENCHMARKS.md).
    pub interleaved_descent: bool,
}

impl Default for ContactConfig {
    fn default() -> Self {
        ContactConfig {
            max_patches: 64,
            normal_cos: 10f32.to_radians().cos(),
            iterations: 12,
            chunk_triangles: 0,
            chunk_world_count: 0,
            workgroup_size: 64,
            candidates_per_invocation: 1,
            subgroups: true,
            interleaved_descent: true,
        }
    }
}

/// Loop iterations a lavapipe (llvmpipe) shader invocation may run in total: one counter shared by all
/// the loops of the invocation, decremented on every back edge; once spent, every loop exits after one
/// pass and the kernel silently skips work (Mesa's `LP_MAX_TGSI_LOOP_ITERATIONS`).
pub const LOOP_ITERATION_LIMIT: u32 = 65535;

/// The share of [`LOOP_ITERATION_LIMIT`] the contact kernels plan for (the counts below are upper bounds;
/// the rest is slack for loops a compiler might add).
const LOOP_BUDGET: u32 = LOOP_ITERATION_LIMIT / 8 * 7;

impl ContactConfig {
    /// `for (var p = lid; p < n; p += WG)`: its iterations plus the final test (llvmpipe counts a loop of
    /// n passes as n + 1 back edges, and one for a loop that runs no pass).
    fn strided(&self, n: u32) -> u32 {
        n.div_ceil(self.workgroup_size) + 1
    }

    /// Candidates per reduction batch: `workgroup_size * candidates_per_invocation` (`BATCH` in
    /// common.wgsl); the CPU twin cuts its batches to this size.
    pub fn batch_size(&self) -> u32 {
        self.workgroup_size * self.candidates_per_invocation
    }

    /// Whether the pipelines order each job's query triangles by normal ([`model::normal_ordered`]): with
    /// several candidates per invocation, so that an invocation's consecutive candidates tend to share a
    /// patch.
    pub fn orders_by_normal(&self) -> bool {
        self.candidates_per_invocation > 1
    }

    /// Worst-case loop back edges of one `reduce_batch` (common.wgsl) per invocation: the stores of its
    /// candidates, Assign (the portable one's, unrolled by 4 in reduce_plain.wgsl; the subgroup one takes 8
    /// patches per pass), at most one new-patch round per candidate plus the last of each of the two round
    /// loops, each with the eviction's strided arg-min, and the loops over the distinct patches of the
    /// invocation's candidates (Assign's posts, slot 0, two per slot round, the last reset: 9, each with at
    /// most one pass per candidate plus the exit), the slot rounds' loops over the candidates in a patch
    /// (at most one per candidate and round).
    fn reduce_batch_loops(&self) -> u32 {
        let per = self.candidates_per_invocation;
        let stores = per + 1;
        let assign = self.max_patches.div_ceil(4) + 1;
        let rounds = (self.batch_size() + 2) * (1 + self.strided(self.max_patches + 1));
        let groups = 9 * (per + 1);
        let members = 3 * per * (per + 1);
        stores + assign + rounds + groups + members
    }

    /// Once per workgroup: reset_patches and the output loop, each with a 4-slot loop per patch.
    fn patch_list_loops(&self) -> u32 {
        2 * self.strided(self.max_patches + 1) * 5
    }

    /// Worst-case loop back edges of one generate workgroup (generate.wgsl) over a job of `triangles`.
    pub fn generate_loop_iterations(&self, triangles: u32) -> u64 {
        // Per batch: the batch loop, the loop over the invocation's triangles, per triangle the
        // projected-gradient loop and its 3 corners, the reduction.
        let per = self.candidates_per_invocation;
        let per_batch = 1 + (per + 1) + per * ((self.iterations + 1) + 4) + self.reduce_batch_loops();
        triangles.div_ceil(self.batch_size()) as u64 * per_batch as u64 + self.patch_list_loops() as u64 + 1
    }

    /// Worst-case loop back edges of one merge workgroup (merge.wgsl) over a pair of `jobs` jobs.
    pub fn merge_loop_iterations(&self, jobs: u32) -> u64 {
        // The stream holds at most 4 slots per patch of every job; per batch: the batch loop, the search
        // of its first job, the loop over the invocation's entries, their walk to their jobs (a batch spans
        // at most BATCH / 4 + 1 jobs that hold slots, plus the empty ones between them, counted once below;
        // one more exit per entry), 5 per entry for its 4-slot count (written out, not a loop, but still
        // counted, on the safe side), the reduction.
        let per = self.candidates_per_invocation;
        let batches = (jobs as u64 * self.max_patches as u64 * 4).div_ceil(self.batch_size() as u64);
        let per_batch = 1 + 1 + (per + 1) + (self.batch_size() / 4 + 2 + per) + 5 * per + self.reduce_batch_loops();
        batches * per_batch as u64 + 3 * (jobs as u64 + 1) + self.patch_list_loops() as u64
    }

    /// The longest job (query triangles per generate workgroup, a multiple of 256) whose worst-case loop
    /// count stays within lavapipe's limit (see [`LOOP_ITERATION_LIMIT`]); 0 if not even 256 fit.
    pub fn max_chunk_triangles(&self) -> u32 {
        let mut chunk = 0;
        while chunk < (1 << 20) && self.generate_loop_iterations(chunk + 256) <= LOOP_BUDGET as u64 {
            chunk += 256;
        }
        chunk
    }

    /// The most jobs per pair one merge workgroup can take within lavapipe's loop limit.
    pub fn max_jobs_per_pair(&self) -> u32 {
        let mut jobs = 0;
        while jobs < (1 << 20) && self.merge_loop_iterations(jobs + 1) <= LOOP_BUDGET as u64 {
            jobs += 1;
        }
        jobs
    }

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
        if ![32, 64, 128, 256].contains(&self.workgroup_size) {
            return Err(EngineError::Config {
                field: "workgroup_size",
                value: self.workgroup_size.to_string(),
                expected: "32, 64, 128 or 256".into(),
            });
        }
        if ![1, 2, 4].contains(&self.candidates_per_invocation) || self.batch_size() > 256 {
            return Err(EngineError::Config {
                field: "candidates_per_invocation",
                value: self.candidates_per_invocation.to_string(),
                expected: format!(
                    "1, 2 or 4, with at most 256 candidates per batch (workgroup_size {} x candidates_per_invocation)",
                    self.workgroup_size
                ),
            });
        }
        let max_chunk = self.max_chunk_triangles();
        if max_chunk == 0 || self.max_jobs_per_pair() == 0 {
            return Err(EngineError::Config {
                field: "iterations",
                value: self.iterations.to_string(),
                expected: "fewer iterations, a smaller max_patches or workgroup_size: one batch exceeds the kernels' loop budget".into(),
            });
        }
        if self.chunk_triangles > max_chunk {
            return Err(EngineError::Config {
                field: "chunk_triangles",
                value: self.chunk_triangles.to_string(),
                expected: format!(
                    "at most {max_chunk} with these settings (lavapipe ends a shader's loops after {LOOP_ITERATION_LIMIT} iterations in all)"
                ),
            });
        }
        Ok(())
    }

    /// Bytes of workgroup memory the generate and merge kernels declare (common.wgsl): the batch (`cand_pd`,
    /// `cand_n`: 2 x 16 bytes per candidate), the patch list (`patch_data` 5 x 16,
    /// `patch_ak` 2 x 4, `slot_keys` 2 x 4 per patch, budget + 1 patches), `wg_best`, `wg_victim` (12 bytes) and
    /// generate.wgsl's `wg_retry` (16).
    pub fn workgroup_bytes(&self) -> u32 {
        let cap = self.max_patches + 1;
        self.batch_size() * 16 * 2 + cap * (5 * 16 + 2 * 4 + 2 * 4) + 12 + 16
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
        // The budget of 256 patches fits the 32 KiB of workgroup memory most GPUs offer with batches of up
        // to 128 candidates.
        let c = ContactConfig { max_patches: 256, candidates_per_invocation: 2, ..Default::default() };
        assert!(c.workgroup_bytes() <= 32768);
        assert!(ContactConfig::default().workgroup_bytes() <= 16384);
        let e = ContactConfig { workgroup_size: 96, ..Default::default() }.validate().unwrap_err().to_string();
        assert!(e.contains("workgroup_size"), "{e}");
        for (wg, per) in [(64, 3), (64, 8), (128, 4), (256, 2)] {
            let c = ContactConfig { workgroup_size: wg, candidates_per_invocation: per, ..Default::default() };
            let e = c.validate().unwrap_err().to_string();
            assert!(e.contains("candidates_per_invocation") && e.contains(&per.to_string()), "{e}");
        }
        for wg in [32, 64, 128, 256] {
            for max_patches in [16, 64, 256] {
                let per = (256 / wg).min(4);
                let c = ContactConfig {
                    workgroup_size: wg,
                    max_patches,
                    candidates_per_invocation: per,
                    ..Default::default()
                };
                assert!(c.validate().is_ok(), "{c:?}");
                // With budgets up to the default, our M16 and Factory's M16 nut (11512, 15078 triangles)
                // fit one merge workgroup (a budget of 256 at 32 wide takes 10752 triangles per pair).
                let per_pair = c.max_chunk_triangles() as u64 * c.max_jobs_per_pair() as u64;
                assert!(max_patches > 64 || per_pair >= 15078, "{c:?}");
                assert!(per_pair >= 10752, "{c:?}");
            }
        }
        let c = ContactConfig::default();
        let e = ContactConfig { chunk_triangles: c.max_chunk_triangles() + 256, ..c.clone() }.validate().unwrap_err();
        assert!(e.to_string().contains("chunk_triangles"), "{e}");
    }
}
#[cfg(test)]
pub(crate) mod shader_tests;

//! CPU twin of the workgroup contact reduction in common.wgsl (paper III-C, Algorithm 1). It reproduces
//! the kernel's decisions step by step (the same keys, tie-breaks and arg-max rounds), so GPU and CPU agree
//! up to floating-point rounding.

use super::model::{PatchGpu, EMPTY_DEPTH};
use glam::{Vec3, Vec4, Vec4Swizzles};

/// Most candidates per batch: the largest workgroup size of the kernels (`WG` in common.wgsl, set by
/// `ContactConfig::workgroup_size`; the callers cut batches of that size). Candidate codes `i + 1` must
/// fit `IDX_MASK`.
pub const MAX_BATCH: usize = 256;
const VALID_BELOW: f32 = 1.0e38;
const NEG_INF: f32 = -3.0e38;
const IDX_MASK: u32 = 0x3ff;
/// Slots 1-3 of a patch take no contact more than this fraction of the contact offset above both its
/// deepest contact and the surface (as `DEPTH_BAND` in common.wgsl).
pub const DEPTH_BAND: f32 = 0.25;
/// ... and no more than the deepest contact's distance from the surface (penetration or gap), or this [m]
/// if that is less (as `MIN_DEPTH_BAND` in common.wgsl): a patch that rests on its surface keeps its slots
/// on what carries the load. Regression: a chamfered 4 mm peg standing on a table at a 10 mm contact offset
/// (band 2.5 mm) got one contact on its bottom face and three on the chamfer's upper rim, 0.5 mm higher and
/// wider apart, every frame; it stood on that single point and toppled. A falling or deeply penetrating
/// patch still takes corners up to its deepest contact's distance above it (a tilted box landing).
/// A patch whose deepest contact is still more than this above the surface is landing, not resting: its
/// slots take any contact within the offset, so the side that swings down in the frame has one.
/// Without this rule a ring landing tilted on the ground keeps all four slots within 0.3 mm of its
/// lowest point, and its far side slaps 8 mm into the ground in the next frame (4.4 mm with the rule,
/// `factory-bench scene pile-toruses`).
pub const MIN_DEPTH_BAND: f32 = 1e-4;
const UNASSIGNED: u32 = u32::MAX - 1;
const NONE: u32 = u32::MAX;

/// A contact candidate: point xyz + depth w [m]; unit normal xyz + area units w.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Candidate {
    pub pd: Vec4,
    pub n: Vec4,
}

impl Candidate {
    /// The "no candidate" marker.
    pub const EMPTY: Candidate = Candidate { pd: Vec4::new(0.0, 0.0, 0.0, EMPTY_DEPTH), n: Vec4::ZERO };
    fn valid(&self) -> bool {
        self.pd.w < VALID_BELOW
    }
}

/// Order-preserving f32 -> u32 with the low 10 bits cleared for an index (as `ordered` in WGSL).
pub fn ordered(f: f32) -> u32 {
    let b = f.to_bits();
    let m = if b & 0x8000_0000 != 0 { 0xffff_ffff } else { 0x8000_0000 };
    (b ^ m) & !IDX_MASK
}

/// The patch list of one workgroup.
#[derive(Clone, Debug)]
pub struct Reducer {
    max_patches: usize,
    normal: Vec<Vec3>,
    area: Vec<u32>,
    slots: Vec<[Vec4; 4]>,
    count: usize,
}

impl Reducer {
    pub fn new(max_patches: u32) -> Self {
        let cap = max_patches as usize + 1;
        Reducer {
            max_patches: max_patches as usize,
            normal: vec![Vec3::ZERO; cap],
            area: vec![0; cap],
            slots: vec![[Vec4::new(0.0, 0.0, 0.0, EMPTY_DEPTH); 4]; cap],
            count: 0,
        }
    }

    /// Number of patches.
    pub fn count(&self) -> usize {
        self.count
    }

    fn measure(&self, p: usize, offset: f32) -> f32 {
        self.area[p] as f32 * (offset - self.slots[p][0].w)
    }

    fn slot_metric(&self, k: usize, p: usize, x: Vec3, depth: f32, min_sep: f32, band: f32) -> f32 {
        if k == 0 {
            return -depth;
        }
        let s0 = self.slots[p][0];
        if s0.w <= MIN_DEPTH_BAND && depth > s0.w.max(0.0) + band.min(s0.w.abs().max(MIN_DEPTH_BAND)) {
            return NEG_INF;
        }
        if k == 1 {
            let d = x.distance(s0.xyz());
            return if d > min_sep { d } else { NEG_INF };
        }
        let s1 = self.slots[p][1];
        if s1.w >= VALID_BELOW {
            return NEG_INF;
        }
        let dir = (s1.xyz() - s0.xyz()).normalize();
        if k == 2 {
            let l = (x - s0.xyz()).cross(dir).length();
            return if l > min_sep { l } else { NEG_INF };
        }
        let s2 = self.slots[p][2];
        if s2.w >= VALID_BELOW {
            return NEG_INF;
        }
        let r = s2.xyz() - s0.xyz();
        let perp = (r - r.dot(dir) * dir).normalize();
        let m = -(x - s0.xyz()).dot(perp);
        if m > min_sep {
            m
        } else {
            NEG_INF
        }
    }

    /// Reduces one batch (at most [`MAX_BATCH`] candidates, slot i = invocation i).
    pub fn reduce_batch(&mut self, cand: &[Candidate], normal_cos: f32, offset: f32, min_sep: f32) {
        assert!(cand.len() <= MAX_BATCH);
        let mut patch = vec![NONE; cand.len()];
        // Assign.
        for (i, c) in cand.iter().enumerate() {
            if !c.valid() {
                continue;
            }
            let mut best = normal_cos;
            let mut assigned = UNASSIGNED;
            for p in 0..self.count {
                let d = c.n.xyz().dot(self.normal[p]);
                if d >= best {
                    best = d;
                    assigned = p as u32;
                }
            }
            patch[i] = assigned;
            if assigned != UNASSIGNED {
                self.area[assigned as usize] += c.n.w as u32;
            }
        }
        // FindDeepest, BinReduce, AddPatch.
        loop {
            let best = (0..cand.len())
                .filter(|&i| patch[i] == UNASSIGNED)
                .map(|i| ordered(-cand[i].pd.w) | (i as u32 + 1))
                .max()
                .unwrap_or(0);
            if best == 0 {
                break;
            }
            let seed = ((best & IDX_MASK) - 1) as usize;
            let idx = self.count.min(self.max_patches);
            self.normal[idx] = cand[seed].n.xyz();
            self.area[idx] = 0;
            self.slots[idx] = [
                cand[seed].pd,
                Vec4::new(0.0, 0.0, 0.0, EMPTY_DEPTH),
                Vec4::new(0.0, 0.0, 0.0, EMPTY_DEPTH),
                Vec4::new(0.0, 0.0, 0.0, EMPTY_DEPTH),
            ];
            for i in 0..cand.len() {
                if patch[i] == UNASSIGNED && cand[i].n.xyz().dot(self.normal[idx]) >= normal_cos {
                    patch[i] = idx as u32;
                    self.area[idx] += cand[i].n.w as u32;
                }
            }
            if idx < self.max_patches {
                self.count = idx + 1;
            } else {
                // The arg-min of ordered(measure) | code: code p + 1 for existing patches, 0 for the new one
                // (index max_patches), which thus loses ties.
                let key = (0..=self.max_patches)
                    .map(|p| {
                        let code = if p == self.max_patches { 0 } else { p as u32 + 1 };
                        ordered(self.measure(p, offset)) | code
                    })
                    .min()
                    .unwrap();
                let code = key & IDX_MASK;
                let victim = if code != 0 {
                    let v = (code - 1) as usize;
                    self.normal[v] = self.normal[self.max_patches];
                    self.area[v] = self.area[self.max_patches];
                    self.slots[v] = self.slots[self.max_patches];
                    v as u32
                } else {
                    NONE
                };
                for c in patch.iter_mut() {
                    if *c == self.max_patches as u32 {
                        *c = victim;
                    } else if *c == victim {
                        *c = NONE;
                    }
                }
            }
        }
        // Four arg-max rounds choose the slots, over every patch. (The kernel works only on the patches with
        // members in the batch, by the members; the others' slots come out the same here, since they were
        // chosen against the same slots before them.)
        let band = DEPTH_BAND * offset;
        for k in 0..4 {
            let mut key: Vec<u32> = (0..self.count)
                .map(|p| {
                    let s = self.slots[p][k];
                    if s.w < VALID_BELOW {
                        let m = self.slot_metric(k, p, s.xyz(), s.w, min_sep, band);
                        if m > NEG_INF {
                            return ordered(m);
                        }
                    }
                    0
                })
                .collect();
            for (i, c) in cand.iter().enumerate() {
                let p = patch[i];
                if (p as usize) < self.max_patches && p != NONE && p != UNASSIGNED {
                    let m = self.slot_metric(k, p as usize, c.pd.xyz(), c.pd.w, min_sep, band);
                    if m > NEG_INF {
                        key[p as usize] = key[p as usize].max(ordered(m) | (i as u32 + 1));
                    }
                }
            }
            for (p, &kk) in key.iter().enumerate() {
                let code = kk & IDX_MASK;
                if code != 0 {
                    self.slots[p][k] = cand[code as usize - 1].pd;
                } else if kk == 0 && k > 0 {
                    self.slots[p][k] = Vec4::new(0.0, 0.0, 0.0, EMPTY_DEPTH);
                }
            }
        }
    }

    /// The patches in the GPU output layout (normal xyz + area [m^2] w), slots untransformed.
    pub fn patches(&self, area_unit: f32) -> Vec<PatchGpu> {
        (0..self.count)
            .map(|p| {
                let n = self.normal[p];
                PatchGpu {
                    normal: [n.x, n.y, n.z, self.area[p] as f32 * area_unit],
                    slots: self.slots[p].map(|s| s.to_array()),
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ordered_keys_sort_like_floats() {
        let xs = [-1e30f32, -2.5, -1e-6, 0.0, 1e-6, 0.75, 3.0, 1e30];
        for w in xs.windows(2) {
            assert!(ordered(w[0]) < ordered(w[1]), "{} {}", w[0], w[1]);
        }
        assert!(ordered(-3.0e38) > 0);
    }

    /// Two flat faces at right angles in one batch: two patches, each keeping its four corners.
    #[test]
    fn two_faces_give_two_patches_with_corner_slots() {
        let mut cands = Vec::new();
        for i in 0..5 {
            for j in 0..5 {
                let (u, v) = (i as f32 * 0.2, j as f32 * 0.2);
                cands.push(Candidate { pd: Vec4::new(u, v, 0.0, -0.01), n: Vec4::new(0.0, 0.0, 1.0, 1.0) });
                cands.push(Candidate { pd: Vec4::new(0.0, u, 1.0 + v, -0.02), n: Vec4::new(1.0, 0.0, 0.0, 1.0) });
            }
        }
        assert!(cands.len() <= MAX_BATCH);
        let mut r = Reducer::new(16);
        r.reduce_batch(&cands, 0.9, 0.05, 0.01);
        let p = r.patches(1.0);
        assert_eq!(p.len(), 2);
        // The deeper face opens first.
        assert_eq!(p[0].normal[0], 1.0);
        assert_eq!(p[0].normal[3], 25.0);
        for patch in &p {
            let pts: Vec<Vec3> = patch.slots.iter().map(|s| Vec4::from_array(*s).xyz()).collect();
            assert!(patch.slots.iter().all(|s| s[3] < 1.0), "all four slots used");
            // The four slots span the 0.8 x 0.8 face: the quad's area is the face's.
            let area = 0.5
                * ((pts[1] - pts[0]).cross(pts[2] - pts[0]).length()
                    + (pts[1] - pts[0]).cross(pts[3] - pts[0]).length());
            assert!((area - 0.64).abs() < 1e-4, "{area}");
        }
    }

    /// With a budget of 16, 40 distinct normals keep the 16 of largest measure.
    #[test]
    fn budget_keeps_the_largest_patches() {
        let mut cands = Vec::new();
        for k in 0..40 {
            let a = k as f32 * std::f32::consts::TAU / 40.0;
            let n = Vec3::new(a.cos(), a.sin(), 0.0);
            // Patch k gets k+1 candidates of area 1.
            for m in 0..=k.min(5) {
                cands.push(Candidate {
                    pd: (n * (1.0 + m as f32 * 0.01)).extend(-0.001 * k as f32),
                    n: n.extend(1.0 + k as f32),
                });
            }
        }
        let mut r = Reducer::new(16);
        for chunk in cands.chunks(MAX_BATCH) {
            r.reduce_batch(chunk, 0.999, 0.01, 1e-4);
        }
        assert_eq!(r.count(), 16);
        let kept: Vec<f32> = r.patches(1.0).iter().map(|p| p.normal[3]).collect();
        let smallest_kept = kept.iter().cloned().fold(f32::MAX, f32::min);
        // Measures grow with k, so the 16 largest (k = 24..39) survive.
        assert!(smallest_kept >= 6.0 * 25.0, "{kept:?}");
    }

    /// Regression (box dropped with a 30 mm contact offset sank 3 mm: its patch's slots 1-3 went to the top
    /// corners, 21 mm up): points of the same normal far above the deepest do not take slots.
    #[test]
    fn slots_skip_points_far_above_the_deepest() {
        let n = Vec4::new(0.0, 0.0, 1.0, 1.0);
        let mut cands = Vec::new();
        for (x, y) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            cands.push(Candidate { pd: Vec4::new(0.02 * x, 0.015 * y, 0.0, -0.002), n });
            cands.push(Candidate { pd: Vec4::new(0.03 * x, 0.025 * y, 0.021, 0.021), n });
        }
        let mut r = Reducer::new(16);
        r.reduce_batch(&cands, 0.9, 0.03, 1e-3);
        let p = r.patches(1.0);
        assert_eq!(p.len(), 1);
        let depths: Vec<f32> = p[0].slots.iter().map(|s| s[3]).collect();
        assert_eq!(depths, vec![-0.002; 4], "{:?}", p[0].slots);
    }

    /// A landing patch (deepest contact 3 mm above the surface) spreads its slots over the whole bin: the
    /// near corners and the far ones 21 mm higher alike, so the far side has a contact before it swings down.
    #[test]
    fn a_landing_patch_spreads_its_slots_over_the_whole_bin() {
        let n = Vec4::new(0.0, 0.0, 1.0, 1.0);
        let mut cands = Vec::new();
        for (x, y) in [(-1.0, -1.0), (1.0, -1.0)] {
            cands.push(Candidate { pd: Vec4::new(0.02 * x, 0.015 * y, 0.003, 0.003), n });
            cands.push(Candidate { pd: Vec4::new(0.02 * x, 0.015 * -y, 0.024, 0.024), n });
        }
        let mut r = Reducer::new(16);
        r.reduce_batch(&cands, 0.9, 0.03, 1e-3);
        let p = r.patches(1.0);
        assert_eq!(p.len(), 1);
        let mut depths: Vec<f32> = p[0].slots.iter().map(|s| s[3]).collect();
        depths.sort_by(f32::total_cmp);
        assert_eq!(depths, vec![0.003, 0.003, 0.024, 0.024], "{:?}", p[0].slots);
    }
}

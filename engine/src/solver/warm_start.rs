//! Warm starting across frames: contacts are generated afresh every frame, so each new row looks for
//! itself among last frame's rows of the same patch of the same pair and takes over the closest match's
//! impulses ([`take_over`]). [`WarmStart`] carries the rows from one frame of the CPU step to the next.

use super::rows::Row;
use glam::Vec3;

/// Warm-start match (solver.wgsl's WARM_DISTANCE, WARM_COS): a row takes over the impulses of the row in
/// the same slot last frame when that was the same contact: same pair, anchor on a and point on b within
/// this fraction of the pair's contact offset, and normals within acos(WARM_COS) (about 10 deg).
pub(super) const WARM_DISTANCE: f32 = 0.1;
pub(super) const WARM_COS: f32 = 0.985;

/// What one frame of [`step_cpu`] hands to the next: each world's rows with their last impulses (the CPU
/// twin of the rows the GPU solver keeps in its scratch buffer). Start from `Default` (no warm start).
#[derive(Clone, Debug, Default)]
pub struct WarmStart {
    /// Each world's rows, sorted by (pair, patch), then slot.
    pub(super) rows: Vec<Vec<Row>>,
}

impl WarmStart {
    /// The total normal impulse [N s] the last substep of the last frame applied through the rows of pair
    /// `pair` in world `world` (divide by the substep length for the mean contact force [N]); 0 for a
    /// pair without rows.
    pub fn pair_normal_impulse(&self, world: usize, pair: usize) -> f32 {
        self.rows.get(world).map_or(0.0, |rows| rows.iter().filter(|r| r.pair == pair).map(|r| r.lambda_n).sum())
    }

    /// The total contact impulse vector [N s] (normal and friction) the last substep of the last frame
    /// applied to pair `pair`'s query body `a` in world `world` (world frame; the SDF body got the opposite).
    pub fn pair_impulse(&self, world: usize, pair: usize) -> Vec3 {
        self.rows.get(world).map_or(Vec3::ZERO, |rows| {
            rows.iter()
                .filter(|r| r.pair == pair)
                .filter_map(|r| {
                    r.normal.map(|n| {
                        let t1 = n.any_orthonormal_vector();
                        r.lambda_n * n + r.lambda_t[0] * t1 + r.lambda_t[1] * n.cross(t1)
                    })
                })
                .sum()
        })
    }

    /// The rows' state as bytes (what the next frame's match and warm start read; the per-substep caches
    /// are rebuilt), for checkpoints that must continue exactly.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut b = Vec::new();
        let mut put = |x: u32| b.extend_from_slice(&x.to_le_bytes());
        put(self.rows.len() as u32);
        for rows in &self.rows {
            put(rows.len() as u32);
            for r in rows {
                for i in [r.a, r.b, r.pair, r.patch] {
                    put(i as u32);
                }
                let n = r.normal.unwrap_or(Vec3::ZERO);
                let floats = [
                    r.anchor_a.x,
                    r.anchor_a.y,
                    r.anchor_a.z,
                    r.mu,
                    r.lambda_n,
                    r.lambda_t[0],
                    r.lambda_t[1],
                    n.x,
                    n.y,
                    n.z,
                    r.sep,
                    r.point_b.x,
                    r.point_b.y,
                    r.point_b.z,
                ];
                put(r.normal.is_some() as u32);
                for f in floats {
                    put(f.to_bits());
                }
            }
        }
        b
    }

    /// Reads what [`to_bytes`](Self::to_bytes) wrote; None if the bytes are not such a state.
    pub fn from_bytes(bytes: &[u8]) -> Option<Self> {
        let mut at = 0usize;
        let mut word = || -> Option<u32> {
            let w = u32::from_le_bytes(bytes.get(at..at + 4)?.try_into().ok()?);
            at += 4;
            Some(w)
        };
        let worlds = word()? as usize;
        let mut out = Vec::with_capacity(worlds.min(1 << 20));
        for _ in 0..worlds {
            let n = word()? as usize;
            let mut rows = Vec::with_capacity(n.min(1 << 20));
            for _ in 0..n {
                let (a, b, pair, patch) = (word()? as usize, word()? as usize, word()? as usize, word()? as usize);
                let has_normal = word()? != 0;
                let mut f = [0.0f32; 14];
                for x in &mut f {
                    *x = f32::from_bits(word()?);
                }
                rows.push(Row {
                    a,
                    b,
                    pair,
                    patch,
                    anchor_a: Vec3::new(f[0], f[1], f[2]),
                    mu: f[3],
                    lambda_n: f[4],
                    lambda_t: [f[5], f[6]],
                    normal: has_normal.then(|| Vec3::new(f[7], f[8], f[9])),
                    sep: f[10],
                    point_b: Vec3::new(f[11], f[12], f[13]),
                    cache: None,
                });
            }
            out.push(rows);
        }
        (at == bytes.len()).then_some(WarmStart { rows: out })
    }

    /// Forgets world `world`'s rows, so its next frame starts cold (after the world was reset: last
    /// frame's impulses belong to contacts that no longer exist).
    pub fn clear_world(&mut self, world: usize) {
        if let Some(rows) = self.rows.get_mut(world) {
            rows.clear();
        }
    }

    /// Renumbers the pairs of last frame's rows (`map`: old pair index -> new, None: the pair is gone and
    /// its rows are dropped), for callers whose pair list changes from frame to frame (crate::many_body).
    pub fn remap_pairs(&mut self, map: impl Fn(usize) -> Option<usize>) {
        for rows in &mut self.rows {
            rows.retain_mut(|r| match map(r.pair) {
                Some(p) => {
                    r.pair = p;
                    true
                }
                None => false,
            });
            // Stable: a patch's rows keep their slot order, which the match's tie-break follows.
            rows.sort_by_key(|r| (r.pair, r.patch));
        }
    }

    /// Last frame's rows of patch `patch` of pair `pair` in world `world`.
    pub(super) fn patch_rows(&self, world: usize, pair: usize, patch: usize) -> &[Row] {
        let prev = &self.rows[world];
        &prev[prev.partition_point(|o| (o.pair, o.patch) < (pair, patch))
            ..prev.partition_point(|o| (o.pair, o.patch) <= (pair, patch))]
    }
}

/// The closest of `old` (last frame's rows of the same patch) that was the same contact as `row` hands
/// over its impulses and normal: `normal` is the patch's normal this frame, `tol` the match distance [m]
/// ([`WARM_DISTANCE`] times the pair's contact offset).
pub(super) fn take_over(row: &mut Row, old: &[Row], normal: Vec3, tol: f32) {
    let mut best: Option<(f32, &Row)> = None;
    for o in old {
        let Some(n) = o.normal else { continue };
        let d = o.anchor_a.distance(row.anchor_a);
        if n.dot(normal) >= WARM_COS
            && d <= tol
            && o.point_b.distance(row.point_b) <= tol
            && best.is_none_or(|(bd, _)| d < bd)
        {
            best = Some((d, o));
        }
    }
    if let Some((_, o)) = best {
        (row.lambda_n, row.lambda_t, row.normal) = (o.lambda_n, o.lambda_t, o.normal);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(i: usize, normal: Option<Vec3>) -> Row {
        let f = i as f32;
        Row {
            a: i,
            b: i + 1,
            pair: 2 * i,
            patch: 3 * i,
            anchor_a: Vec3::new(f, -f, 0.5 * f),
            mu: 0.3,
            lambda_n: 1e-3 * f,
            lambda_t: [-2e-4 * f, 7e-5],
            normal,
            sep: -1e-4 * f,
            point_b: Vec3::new(0.1, f, -f),
            cache: None,
        }
    }

    #[test]
    fn warm_start_bytes_round_trip() {
        let warm =
            WarmStart { rows: vec![vec![row(1, Some(Vec3::Z)), row(2, None)], vec![], vec![row(3, Some(-Vec3::X))]] };
        let bytes = warm.to_bytes();
        let back = WarmStart::from_bytes(&bytes).expect("round trip");
        assert_eq!(back.to_bytes(), bytes);
        assert_eq!(back.rows.len(), 3);
        assert_eq!(back.rows[0][1].normal, None);
        assert_eq!(back.rows[2][0].normal, Some(-Vec3::X));
        assert_eq!(back.pair_impulse(0, 2), warm.pair_impulse(0, 2));
        assert!(WarmStart::from_bytes(&bytes[..bytes.len() - 1]).is_none());
        assert!(WarmStart::from_bytes(&[bytes.as_slice(), &[0u8; 4]].concat()).is_none());
    }
}

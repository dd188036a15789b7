//! Signed distance fields (paper III-A): a dense voxel grid of signed distances baked from a triangle
//! mesh ([`bake`]), cached on disk by content ([`cache`]), sampled with trilinear interpolation and an
//! analytic trilinear gradient. The same sampling runs in WGSL (`contact/sdf_sample.wgsl`); this is its
//! CPU twin.
//!
//! Sign convention: negative inside the solid, positive outside; the gradient points outward.

pub mod bake;
pub mod cache;
pub mod revolved;
pub mod thread;

use glam::{UVec3, Vec3};

/// A dense grid of signed distances in a shape's frame.
#[derive(Clone, Debug, PartialEq)]
pub struct SdfGrid {
    /// Position of sample (0, 0, 0) in the shape frame [m].
    pub origin: Vec3,
    /// Distance between neighbouring samples along every axis [m].
    pub spacing: f32,
    /// Samples along x, y, z (each >= 2).
    pub dims: UVec3,
    /// Signed distance [m] (negative inside), shape [dims.x * dims.y * dims.z], index x + dims.x * (y + dims.y * z).
    pub values: Vec<f32>,
}

impl SdfGrid {
    /// Flat index of sample (i, j, k).
    #[inline]
    pub fn index(&self, i: u32, j: u32, k: u32) -> usize {
        (i + self.dims.x * (j + self.dims.y * k)) as usize
    }

    /// Shape-frame position of sample (i, j, k) [m].
    #[inline]
    pub fn point(&self, i: u32, j: u32, k: u32) -> Vec3 {
        self.origin + self.spacing * Vec3::new(i as f32, j as f32, k as f32)
    }

    /// Far corner of the sampled box [m].
    pub fn max_corner(&self) -> Vec3 {
        self.origin + self.spacing * (self.dims - UVec3::ONE).as_vec3()
    }

    /// Signed distance [m] and its gradient (not normalised) at `p` (shape frame). Inside the box:
    /// trilinear interpolation and its exact derivative. Outside: the value at the nearest box point plus
    /// the distance to it, with the gradient pointing away from the box, so the field stays a valid bound.
    pub fn sample(&self, p: Vec3) -> (f32, Vec3) {
        trilinear(self.origin, self.spacing, self.dims, p, |i, j, k| self.values[self.index(i, j, k)])
    }

    /// Bytes the grid occupies.
    pub fn byte_size(&self) -> u64 {
        self.values.len() as u64 * 4
    }
}

/// Trilinear value and exact gradient of a sampled field at `p`: `at(i, j, k)` reads sample (i, j, k) of a
/// grid with sample 0 at `lo`, spacing `h` and `dims` samples. Outside the box the distance to the box is
/// added and the gradient points away from it. Shared by [`SdfGrid::sample`] and the kernels' CPU twin
/// (which reads 16-bit values); the WGSL `sdf_sample` performs the same operations in the same order.
pub fn trilinear(lo: Vec3, h: f32, dims: UVec3, p: Vec3, at: impl Fn(u32, u32, u32) -> f32) -> (f32, Vec3) {
    let hi = lo + h * (dims - UVec3::ONE).as_vec3();
    let q = p.clamp(lo, hi);
    let g = (q - lo) / h;
    let cell = g.floor().as_uvec3().min(dims - UVec3::splat(2));
    let f = g - cell.as_vec3();
    let (x, y, z) = (cell.x, cell.y, cell.z);
    let (c000, c100, c010, c110) = (at(x, y, z), at(x + 1, y, z), at(x, y + 1, z), at(x + 1, y + 1, z));
    let (c001, c101, c011, c111) = (at(x, y, z + 1), at(x + 1, y, z + 1), at(x, y + 1, z + 1), at(x + 1, y + 1, z + 1));
    let x00 = c000 + (c100 - c000) * f.x;
    let x10 = c010 + (c110 - c010) * f.x;
    let x01 = c001 + (c101 - c001) * f.x;
    let x11 = c011 + (c111 - c011) * f.x;
    let y0 = x00 + (x10 - x00) * f.y;
    let y1 = x01 + (x11 - x01) * f.y;
    let d = y0 + (y1 - y0) * f.z;
    let ya = (c100 - c000) + ((c110 - c010) - (c100 - c000)) * f.y;
    let yb = (c101 - c001) + ((c111 - c011) - (c101 - c001)) * f.y;
    let dx = ya + (yb - ya) * f.z;
    let dy = (x10 - x00) + ((x11 - x01) - (x10 - x00)) * f.z;
    let dz = y1 - y0;
    let out = p - q;
    let out_len = out.length();
    if out_len > 0.0 {
        (d + out_len, out / out_len)
    } else {
        (d, Vec3::new(dx, dy, dz) / h)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A grid holding the exact SDF of a sphere: trilinear sampling is close and the gradient is radial.
    #[test]
    fn sample_sphere_grid() {
        let r = 0.3f32;
        let n = 41u32;
        let spacing = 1.0 / (n - 1) as f32;
        let origin = Vec3::splat(-0.5);
        let mut values = Vec::new();
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    values.push((origin + spacing * Vec3::new(i as f32, j as f32, k as f32)).length() - r);
                }
            }
        }
        let grid = SdfGrid { origin, spacing, dims: UVec3::splat(n), values };
        for p in [Vec3::new(0.31, 0.0, 0.0), Vec3::new(0.1, -0.2, 0.21), Vec3::new(-0.05, 0.33, 0.07)] {
            let (d, g) = grid.sample(p);
            assert!((d - (p.length() - r)).abs() < spacing * 0.1, "{p}: {d}");
            assert!(g.normalize().dot(p.normalize()) > 0.995, "{p}: {g}");
            assert!((g.length() - 1.0).abs() < 0.05);
        }
        // Outside the box the value grows with the distance to it.
        let (d, g) = grid.sample(Vec3::new(1.5, 0.0, 0.0));
        assert!((d - (0.2 + 1.0)).abs() < 1e-4 && g.x > 0.99, "{d} {g}");
    }
}

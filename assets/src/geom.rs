//! Mesh construction from angular columns.
//!
//! Every surface this crate builds is a radial graph r = f(theta, z) over a z interval: a helical thread,
//! a cylinder, a chamfered peg, a hexagonal or square prism wall. Such a surface is sampled on N columns
//! at theta_k = 2 pi k / N (the same angles for every part, so mating parts are sampled alike); each column
//! is a list of (z, r) points from the bottom plane to the top plane, and neighbouring columns are stitched
//! by merging their points in order of a key (the helical coordinate u = z - lead theta / 2 pi for threads,
//! z for plain surfaces). Points of equal key (the same profile corner) are joined by an edge, so the
//! thread's crest and root corners are exact helical edges of the mesh. The bottom and top point of every
//! column form the rings that end caps (disks, annuli) close.

use factory_engine::mesh::TriMesh;
use glam::DVec3;

use crate::iso::ThreadProfile;

/// One sampled point of a column: height, radius and merge key, metres.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ColumnPoint {
    pub z: f64,
    pub r: f64,
    pub key: f64,
}

/// Columns at theta_k = 2 pi k / N; `lead` is subtracted from the keys of column 0 when it is stitched
/// after column N-1 (one full turn later).
pub(crate) struct ColumnSurface {
    pub columns: Vec<Vec<ColumnPoint>>,
    pub lead: f64,
}

/// Angle of column `k` of `n` [rad].
pub(crate) fn column_angle(k: usize, n: usize) -> f64 {
    std::f64::consts::TAU * k as f64 / n as f64
}

/// Distance from the axis to the boundary of a regular polygon with `sides` sides and inradius `apothem`
/// along direction `theta`; one flat's normal is the +x axis, so corners lie at pi/sides + 2 pi m/sides.
pub(crate) fn polygon_radius(theta: f64, sides: usize, apothem: f64) -> f64 {
    let sector = std::f64::consts::TAU / sides as f64;
    let phi = (theta + 0.5 * sector).rem_euclid(sector) - 0.5 * sector;
    apothem / phi.cos()
}

/// A surface of revolution: the same (z, r) polyline (bottom to top) on every column.
pub(crate) fn lathe(profile: &[(f64, f64)], n: usize) -> ColumnSurface {
    let col: Vec<ColumnPoint> = profile.iter().map(|&(z, r)| ColumnPoint { z, r, key: z }).collect();
    ColumnSurface { columns: vec![col; n], lead: 0.0 }
}

/// The side wall of a regular polygonal prism from `z0` to `z1`.
pub(crate) fn polygon_wall(sides: usize, apothem: f64, z0: f64, z1: f64, n: usize) -> ColumnSurface {
    let columns = (0..n)
        .map(|k| {
            let r = polygon_radius(column_angle(k, n), sides, apothem);
            vec![ColumnPoint { z: z0, r, key: z0 }, ColumnPoint { z: z1, r, key: z1 }]
        })
        .collect();
    ColumnSurface { columns, lead: 0.0 }
}

/// A right-hand helical thread surface between the planes `zlo` and `zhi`: at column angle theta the
/// radius at height z is `profile.radius(z - phase - P theta / 2 pi)`, so a tooth centre passes through
/// (theta = 0, z = phase). `breaks` are the profile's corners in one period (sorted, [-P/2, P/2)).
pub(crate) fn helical_thread(
    profile: &ThreadProfile,
    breaks: &[f64],
    n: usize,
    phase: f64,
    zlo: f64,
    zhi: f64,
) -> ColumnSurface {
    let p = profile.pitch;
    // Corners closer than this to an end plane are dropped so no sliver triangles appear at the caps.
    let end_gap = 1e-3 * p;
    let columns = (0..n)
        .map(|k| {
            let c = phase + p * k as f64 / n as f64;
            let mut col = vec![ColumnPoint { z: zlo, r: profile.radius(zlo - c), key: zlo - c }];
            let m0 = ((zlo - c) / p).floor() as i64 - 1;
            let m1 = ((zhi - c) / p).ceil() as i64 + 1;
            for m in m0..=m1 {
                for &b in breaks {
                    let key = b + m as f64 * p;
                    let z = key + c;
                    if z > zlo + end_gap && z < zhi - end_gap {
                        col.push(ColumnPoint { z, r: profile.radius(key), key });
                    }
                }
            }
            col.push(ColumnPoint { z: zhi, r: profile.radius(zhi - c), key: zhi - c });
            col
        })
        .collect();
    ColumnSurface { columns, lead: p }
}

/// Accumulates vertices and triangles.
#[derive(Default)]
pub(crate) struct Builder {
    positions: Vec<glam::Vec3>,
    triangles: Vec<[u32; 3]>,
}

impl Builder {
    fn vertex(&mut self, p: DVec3) -> u32 {
        self.positions.push(p.as_vec3());
        self.positions.len() as u32 - 1
    }

    fn tri(&mut self, t: [u32; 3], flip: bool) {
        self.triangles.push(if flip { [t[0], t[2], t[1]] } else { t });
    }

    /// Adds the surface, facing away from the axis when `outward` (a solid's outer wall) or towards it
    /// (a bore). Returns the bottom and top rings (one vertex per column).
    pub fn side(&mut self, s: &ColumnSurface, outward: bool) -> (Vec<u32>, Vec<u32>) {
        let n = s.columns.len();
        let ids: Vec<Vec<u32>> = s
            .columns
            .iter()
            .enumerate()
            .map(|(k, col)| {
                let (sin, cos) = column_angle(k, n).sin_cos();
                col.iter().map(|p| self.vertex(DVec3::new(p.r * cos, p.r * sin, p.z))).collect()
            })
            .collect();
        // Keys equal to within this are the same profile corner seen from two columns.
        let tie = 1e-12;
        for k in 0..n {
            let k1 = (k + 1) % n;
            let shift = if k1 == 0 { s.lead } else { 0.0 };
            let (l, r) = (&s.columns[k], &s.columns[k1]);
            let (li, ri) = (&ids[k], &ids[k1]);
            let (mut i, mut j) = (0, 0);
            // (column k, column k+1, up column k) winds counter-clockwise seen from outside: e_theta x e_z = e_r.
            while i + 1 < l.len() || j + 1 < r.len() {
                let advance_left = if i + 1 == l.len() {
                    false
                } else if j + 1 == r.len() {
                    true
                } else {
                    l[i + 1].key <= r[j + 1].key - shift + tie
                };
                if advance_left {
                    self.tri([li[i], ri[j], li[i + 1]], !outward);
                    i += 1;
                } else {
                    self.tri([li[i], ri[j], ri[j + 1]], !outward);
                    j += 1;
                }
            }
        }
        (ids.iter().map(|c| c[0]).collect(), ids.iter().map(|c| *c.last().unwrap()).collect())
    }

    /// Closes a ring with a fan from its centre on the axis at height `z`, facing +z when `up`.
    pub fn disk(&mut self, ring: &[u32], z: f64, up: bool) {
        let c = self.vertex(DVec3::new(0.0, 0.0, z));
        let n = ring.len();
        for k in 0..n {
            self.tri([c, ring[k], ring[(k + 1) % n]], !up);
        }
    }

    /// Joins two rings in one plane with a quad strip, facing +z when `up`; both rings have one vertex per
    /// column, `inner` nearer the axis.
    pub fn annulus(&mut self, inner: &[u32], outer: &[u32], up: bool) {
        let n = inner.len();
        debug_assert_eq!(n, outer.len());
        for k in 0..n {
            let k1 = (k + 1) % n;
            self.tri([inner[k], outer[k], outer[k1]], !up);
            self.tri([inner[k], outer[k1], inner[k1]], !up);
        }
    }

    pub fn finish(self) -> TriMesh {
        TriMesh::new(self.positions, self.triangles)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn polygon_radius_hits_flats_and_corners() {
        let a = 12.0;
        assert!((polygon_radius(0.0, 6, a) - a).abs() < 1e-12);
        assert!((polygon_radius(std::f64::consts::PI / 6.0, 6, a) - a * 2.0 / 3f64.sqrt()).abs() < 1e-12);
        assert!((polygon_radius(std::f64::consts::FRAC_PI_2, 6, a) - a * 2.0 / 3f64.sqrt()).abs() < 1e-12);
        assert!((polygon_radius(std::f64::consts::FRAC_PI_4, 4, a) - a * 2f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn cylinder_with_disks_is_closed_and_exact() {
        let n = 96;
        let (r, h) = (0.01, 0.02);
        let mut b = Builder::default();
        let (bot, top) = b.side(&lathe(&[(0.0, r), (h, r)], n), true);
        b.disk(&bot, 0.0, false);
        b.disk(&top, h, true);
        let m = b.finish();
        assert!(m.topology().is_watertight(), "{:?}", m.topology());
        // Inscribed n-gon prism: V = n/2 r^2 sin(2 pi / n) h.
        let exact = 0.5 * n as f64 * r * r * (std::f64::consts::TAU / n as f64).sin() * h;
        assert!((m.signed_volume() - exact).abs() / exact < 1e-5);
    }
}

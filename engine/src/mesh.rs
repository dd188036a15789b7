//! Triangle meshes: the OBJ reader and writer, topology checks, and mass properties.
//!
//! Mass properties use the divergence theorem over signed tetrahedra from the origin (Mirtich 1996,
//! "Fast and accurate computation of polyhedral mass properties"; the tetrahedron inertia integrals of
//! Tonon 2004), accumulated in f64 so that 100k-triangle meshes stay accurate in f32 output.

use crate::error::{EngineError, Result};
use glam::{DMat3, DVec3, Mat3, Vec3};
use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::Path;

/// An indexed triangle mesh in its own frame [m]. Triangles are counter-clockwise seen from outside.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriMesh {
    /// Vertex positions [m], shape [vertex_count].
    pub positions: Vec<Vec3>,
    /// Vertex indices of each triangle, counter-clockwise from outside, shape [triangle_count].
    pub triangles: Vec<[u32; 3]>,
}

/// Mass, centre of mass and inertia of a solid of uniform density bounded by a closed mesh.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MassProperties {
    /// Volume [m^3].
    pub volume: f32,
    /// Mass [kg].
    pub mass: f32,
    /// Centre of mass in the mesh frame [m].
    pub com: Vec3,
    /// Inertia tensor about the centre of mass, mesh axes [kg m^2].
    pub inertia: Mat3,
}

/// What is wrong with a mesh's topology, as found by [`TriMesh::topology`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Topology {
    /// Undirected edges used by exactly one triangle (holes).
    pub boundary_edges: usize,
    /// Undirected edges used by more than two triangles.
    pub non_manifold_edges: usize,
    /// Edges whose two triangles traverse them in the same direction (inconsistent winding).
    pub misoriented_edges: usize,
    /// Triangles with a repeated vertex index or zero area.
    pub degenerate_triangles: usize,
}

impl Topology {
    /// Every edge shared by exactly two triangles with opposite directions, and no degenerate triangle.
    pub fn is_watertight(&self) -> bool {
        *self == Topology::default()
    }
}

impl TriMesh {
    /// Builds a mesh from positions and triangles.
    pub fn new(positions: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Self {
        TriMesh { positions, triangles }
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// The three corners of triangle `t` [m].
    pub fn triangle(&self, t: usize) -> [Vec3; 3] {
        let [a, b, c] = self.triangles[t];
        [self.positions[a as usize], self.positions[b as usize], self.positions[c as usize]]
    }

    /// Axis-aligned bounds (min, max) [m]; both zero for an empty mesh.
    pub fn aabb(&self) -> (Vec3, Vec3) {
        if self.positions.is_empty() {
            return (Vec3::ZERO, Vec3::ZERO);
        }
        self.positions
            .iter()
            .fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(lo, hi), p| (lo.min(*p), hi.max(*p)))
    }

    /// Returns a copy with every vertex mapped by `f` (scale, transform).
    pub fn map_positions(&self, f: impl Fn(Vec3) -> Vec3) -> TriMesh {
        TriMesh { positions: self.positions.iter().map(|p| f(*p)).collect(), triangles: self.triangles.clone() }
    }

    /// The same surface with every triangle whose longest edge exceeds `max_edge` [m] bisected at that
    /// edge's midpoint, recursively. Meant for a mesh whose triangles are *queried* for contacts (one
    /// candidate per triangle, paper III-A): a long, thin triangle (a 9 mm bore wall facet) yields one
    /// point where it needs several (the rim and a tilted peg's corner lower down). Neighbours are split
    /// independently, so the result may have T-junctions: do not use it for mass properties or baking.
    pub fn split_long_triangles(&self, max_edge: f32) -> TriMesh {
        assert!(max_edge > 0.0 && max_edge.is_finite(), "max_edge must be > 0, got {max_edge}");
        let mut positions = self.positions.clone();
        let mut out = Vec::with_capacity(self.triangles.len());
        let mut stack: Vec<[u32; 3]> = self.triangles.iter().rev().copied().collect();
        while let Some(t) = stack.pop() {
            let p = t.map(|i| positions[i as usize]);
            let len2 = [(p[1] - p[0]).length_squared(), (p[2] - p[1]).length_squared(), (p[0] - p[2]).length_squared()];
            let e = (0..3).max_by(|&a, &b| len2[a].total_cmp(&len2[b])).unwrap();
            if len2[e] <= max_edge * max_edge {
                out.push(t);
                continue;
            }
            // Edge e runs from corner e to corner e + 1; the opposite corner is e + 2.
            let (a, b, c) = (t[e], t[(e + 1) % 3], t[(e + 2) % 3]);
            let m = positions.len() as u32;
            positions.push(0.5 * (positions[a as usize] + positions[b as usize]));
            stack.push([m, b, c]);
            stack.push([a, m, c]);
        }
        TriMesh::new(positions, out)
    }

    /// Appends another mesh (its indices shifted).
    pub fn append(&mut self, other: &TriMesh) {
        let base = self.positions.len() as u32;
        self.positions.extend_from_slice(&other.positions);
        self.triangles.extend(other.triangles.iter().map(|t| [t[0] + base, t[1] + base, t[2] + base]));
    }

    /// Merges vertices closer than `tolerance` [m] (quantised hashing) and drops triangles that collapse.
    /// Generators that emit one ring per section use this to stitch sections into a closed surface.
    pub fn weld(&self, tolerance: f32) -> TriMesh {
        let inv = 1.0 / tolerance;
        let key = |p: Vec3| ((p.x * inv).round() as i64, (p.y * inv).round() as i64, (p.z * inv).round() as i64);
        let mut map: HashMap<(i64, i64, i64), u32> = HashMap::new();
        let mut positions = Vec::new();
        let remap: Vec<u32> = self
            .positions
            .iter()
            .map(|p| {
                *map.entry(key(*p)).or_insert_with(|| {
                    positions.push(*p);
                    positions.len() as u32 - 1
                })
            })
            .collect();
        let triangles = self
            .triangles
            .iter()
            .map(|t| [remap[t[0] as usize], remap[t[1] as usize], remap[t[2] as usize]])
            .filter(|t| t[0] != t[1] && t[1] != t[2] && t[0] != t[2])
            .collect();
        TriMesh { positions, triangles }
    }

    /// Edge-sharing statistics: a closed, consistently oriented 2-manifold has all counts zero.
    pub fn topology(&self) -> Topology {
        let mut directed: HashMap<(u32, u32), u32> = HashMap::with_capacity(self.triangles.len() * 3);
        let mut topo = Topology::default();
        for (t, tri) in self.triangles.iter().enumerate() {
            let [a, b, c] = self.triangle(t);
            if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] || (b - a).cross(c - a).length_squared() == 0.0
            {
                topo.degenerate_triangles += 1;
            }
            for k in 0..3 {
                *directed.entry((tri[k], tri[(k + 1) % 3])).or_default() += 1;
            }
        }
        let mut undirected: HashMap<(u32, u32), (u32, u32)> = HashMap::new();
        for (&(a, b), &n) in &directed {
            let e = undirected.entry((a.min(b), a.max(b))).or_default();
            if a < b {
                e.0 += n
            } else {
                e.1 += n
            }
        }
        for &(fwd, back) in undirected.values() {
            match fwd + back {
                1 => topo.boundary_edges += 1,
                2 if fwd == 1 => {}
                2 => topo.misoriented_edges += 1,
                _ => topo.non_manifold_edges += 1,
            }
        }
        topo
    }

    /// Signed volume [m^3]: positive when the triangles wind counter-clockwise seen from outside.
    pub fn signed_volume(&self) -> f64 {
        (0..self.triangles.len())
            .map(|t| {
                let [a, b, c] = self.triangle(t).map(|p| p.as_dvec3());
                a.dot(b.cross(c)) / 6.0
            })
            .sum()
    }

    /// Mass properties of the solid bounded by this closed mesh at `density` [kg/m^3].
    pub fn mass_properties(&self, density: f32) -> MassProperties {
        let rho = density as f64;
        let (mut vol, mut first) = (0.0f64, DVec3::ZERO);
        // Second moments about the origin: integrals of x^2, y^2, z^2, xy, yz, zx over the solid.
        let (mut sq, mut mixed) = (DVec3::ZERO, DVec3::ZERO);
        for t in 0..self.triangles.len() {
            let [a, b, c] = self.triangle(t).map(|p| p.as_dvec3());
            let v = a.dot(b.cross(c)) / 6.0;
            vol += v;
            first += v * (a + b + c) / 4.0;
            // For a tetrahedron (0, a, b, c): int x_i x_j dV = V/20 * (sum_k p_k,i p_k,j + (sum p)_i (sum p)_j).
            let s = a + b + c;
            sq += v / 20.0 * (a * a + b * b + c * c + s * s);
            let m = |p: DVec3| DVec3::new(p.x * p.y, p.y * p.z, p.z * p.x);
            mixed += v / 20.0 * (m(a) + m(b) + m(c) + m(s));
        }
        let com = if vol.abs() > 0.0 { first / vol } else { DVec3::ZERO };
        let (sq, mixed) = (sq * rho, mixed * rho);
        let mass = vol * rho;
        let i_origin = DMat3::from_cols(
            DVec3::new(sq.y + sq.z, -mixed.x, -mixed.z),
            DVec3::new(-mixed.x, sq.x + sq.z, -mixed.y),
            DVec3::new(-mixed.z, -mixed.y, sq.x + sq.y),
        );
        // Parallel axis theorem back to the centre of mass.
        let shift = DMat3::from_diagonal(DVec3::splat(com.length_squared())) - outer(com, com);
        let inertia = i_origin - shift * mass;
        MassProperties { volume: vol as f32, mass: mass as f32, com: com.as_vec3(), inertia: inertia.as_mat3() }
    }

    /// Reads a Wavefront OBJ file: `v` and `f` records (polygons are fan-triangulated; `v/vt/vn` and
    /// negative indices accepted); every other record is ignored. Errors name the file and line.
    pub fn load_obj(path: &Path) -> Result<TriMesh> {
        let text = std::fs::read_to_string(path).map_err(|e| EngineError::io(path, e))?;
        Self::parse_obj(&text, path)
    }

    /// Parses OBJ text; `path` is only used in error messages.
    pub fn parse_obj(text: &str, path: &Path) -> Result<TriMesh> {
        let err = |line: usize, message: String| EngineError::Parse { path: path.to_path_buf(), line, message };
        let mut mesh = TriMesh::default();
        let mut face_lines = Vec::new();
        for (i, raw) in text.lines().enumerate() {
            let line_no = i + 1;
            let line = raw.split('#').next().unwrap_or("").trim();
            let mut it = line.split_whitespace();
            match it.next() {
                Some("v") => {
                    let mut c = [0.0f32; 3];
                    for (k, slot) in c.iter_mut().enumerate() {
                        let tok =
                            it.next().ok_or_else(|| err(line_no, format!("vertex needs 3 coordinates, found {k}")))?;
                        *slot = tok
                            .parse()
                            .map_err(|_| err(line_no, format!("vertex coordinate {tok:?} is not a number")))?;
                        if !slot.is_finite() {
                            return Err(err(line_no, format!("vertex coordinate {tok:?} is not finite")));
                        }
                    }
                    mesh.positions.push(Vec3::from_array(c));
                }
                Some("f") => face_lines.push((line_no, it.map(str::to_owned).collect::<Vec<_>>())),
                _ => {}
            }
        }
        let n = mesh.positions.len() as i64;
        for (line_no, toks) in face_lines {
            if toks.len() < 3 {
                return Err(err(line_no, format!("face needs at least 3 vertices, found {}", toks.len())));
            }
            let idx = toks
                .iter()
                .map(|tok| {
                    let first = tok.split('/').next().unwrap_or("");
                    let v: i64 =
                        first.parse().map_err(|_| err(line_no, format!("face index {tok:?} is not an integer")))?;
                    let resolved = if v < 0 { n + v } else { v - 1 };
                    if v == 0 || resolved < 0 || resolved >= n {
                        return Err(err(
                            line_no,
                            format!(
                                "face index {v} out of range: the file has {n} vertices (valid 1..={n} or -{n}..=-1)"
                            ),
                        ));
                    }
                    Ok(resolved as u32)
                })
                .collect::<Result<Vec<u32>>>()?;
            for k in 1..idx.len() - 1 {
                mesh.triangles.push([idx[0], idx[k], idx[k + 1]]);
            }
        }
        if mesh.triangles.is_empty() {
            return Err(EngineError::Asset {
                path: path.to_path_buf(),
                message: "no faces: an OBJ mesh needs at least one `f` record".into(),
            });
        }
        Ok(mesh)
    }

    /// OBJ text of this mesh (positions in metres with 9 significant digits).
    pub fn to_obj(&self, name: &str) -> String {
        let mut s = String::with_capacity(self.positions.len() * 40 + self.triangles.len() * 24);
        let _ = writeln!(s, "# factory-rs\no {name}");
        for p in &self.positions {
            let _ = writeln!(s, "v {:.9e} {:.9e} {:.9e}", p.x, p.y, p.z);
        }
        for t in &self.triangles {
            let _ = writeln!(s, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1);
        }
        s
    }

    /// Writes the mesh as OBJ, atomically.
    pub fn write_obj(&self, path: &Path) -> Result<()> {
        let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        crate::fsutil::write_atomic(path, self.to_obj(&name).as_bytes())
    }
}

fn outer(a: DVec3, b: DVec3) -> DMat3 {
    DMat3::from_cols(a * b.x, a * b.y, a * b.z)
}

/// Axis-aligned box of half extents `h` centred at the origin, 12 outward-wound triangles.
pub fn box_mesh(h: Vec3) -> TriMesh {
    let positions = (0..8)
        .map(|i| {
            Vec3::new(
                if i & 1 == 0 { -h.x } else { h.x },
                if i & 2 == 0 { -h.y } else { h.y },
                if i & 4 == 0 { -h.z } else { h.z },
            )
        })
        .collect();
    let triangles = vec![
        [0, 2, 3],
        [0, 3, 1], // -z
        [4, 5, 7],
        [4, 7, 6], // +z
        [0, 1, 5],
        [0, 5, 4], // -y
        [2, 6, 7],
        [2, 7, 3], // +y
        [0, 4, 6],
        [0, 6, 2], // -x
        [1, 3, 7],
        [1, 7, 5], // +x
    ];
    TriMesh { positions, triangles }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splitting_long_triangles_keeps_the_surface_and_bounds_every_edge() {
        let m = box_mesh(Vec3::new(0.01, 0.002, 0.0005));
        let s = m.split_long_triangles(0.001);
        let area = |m: &TriMesh| -> f32 {
            (0..m.triangle_count())
                .map(|t| {
                    let [a, b, c] = m.triangle(t);
                    0.5 * (b - a).cross(c - a).length()
                })
                .sum()
        };
        assert!((area(&s) - area(&m)).abs() < 1e-4 * area(&m), "area {} vs {}", area(&s), area(&m));
        assert!(s.triangle_count() > 10 * m.triangle_count());
        for t in 0..s.triangle_count() {
            let [a, b, c] = s.triangle(t);
            let longest = (b - a).length().max((c - b).length()).max((a - c).length());
            assert!(longest <= 0.001 + 1e-9, "triangle {t}: edge {longest}");
            // Orientation kept: every normal still points away from the box centre.
            assert!((b - a).cross(c - a).dot((a + b + c) / 3.0) > 0.0, "triangle {t} flipped");
        }
    }

    #[test]
    fn box_is_watertight_with_exact_mass_properties() {
        let h = Vec3::new(0.1, 0.2, 0.3);
        let m = box_mesh(h);
        assert!(m.topology().is_watertight(), "{:?}", m.topology());
        let mp = m.mass_properties(1000.0);
        let (x, y, z) = (2.0 * h.x, 2.0 * h.y, 2.0 * h.z);
        assert!((mp.volume - x * y * z).abs() < 1e-7);
        let mass = 1000.0 * x * y * z;
        assert!((mp.mass - mass).abs() < 1e-4);
        assert!(mp.com.length() < 1e-7);
        let expect = Vec3::new(y * y + z * z, x * x + z * z, x * x + y * y) * mass / 12.0;
        let d = Vec3::new(mp.inertia.x_axis.x, mp.inertia.y_axis.y, mp.inertia.z_axis.z);
        assert!((d - expect).abs().max_element() < 1e-6, "{d} vs {expect}");
        assert!(mp.inertia.x_axis.y.abs() < 1e-7);
    }

    #[test]
    fn shifted_box_moves_com_not_inertia() {
        let m = box_mesh(Vec3::splat(0.5)).map_positions(|p| p + Vec3::new(1.0, -2.0, 3.0));
        let mp = m.mass_properties(1.0);
        assert!((mp.com - Vec3::new(1.0, -2.0, 3.0)).length() < 1e-5);
        assert!((mp.inertia.x_axis.x - 1.0 / 6.0).abs() < 1e-4);
    }

    #[test]
    fn open_and_flipped_meshes_are_detected() {
        let mut m = box_mesh(Vec3::ONE);
        m.triangles.pop();
        assert_eq!(m.topology().boundary_edges, 3);
        let mut f = box_mesh(Vec3::ONE);
        f.triangles[0].swap(1, 2);
        assert_eq!(f.topology().misoriented_edges, 3);
        assert!(box_mesh(Vec3::ONE).signed_volume() > 0.0);
    }

    #[test]
    fn obj_round_trip_and_errors_name_the_line() {
        let m = box_mesh(Vec3::new(1.0, 2.0, 3.0));
        let back = TriMesh::parse_obj(&m.to_obj("b"), Path::new("b.obj")).unwrap();
        assert_eq!(back.triangles, m.triangles);
        let e = TriMesh::parse_obj("v 0 0 0\nv 1 0 0\nf 1 2 9\n", Path::new("bad.obj")).unwrap_err();
        let s = e.to_string();
        assert!(s.starts_with("bad.obj:3:") && s.contains("out of range"), "{s}");
        let e = TriMesh::parse_obj("v 0 zero 0\n", Path::new("x.obj")).unwrap_err().to_string();
        assert!(e.starts_with("x.obj:1:"), "{e}");
        let quad =
            TriMesh::parse_obj("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1/1/1 2/2/2 3/3/3 -1\n", Path::new("q")).unwrap();
        assert_eq!(quad.triangles, vec![[0, 1, 2], [0, 2, 3]]);
    }
}

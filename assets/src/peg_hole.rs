//! Round pegs and holes (Factory's insertion set, paper Table VII, ISO 286), in the assembled zero pose.
//!
//! Frame (Factory's 4 mm meshes): z is the insertion axis. The hole is a square block of
//! `block_width` x `block_width` from z = 0 to 8.9916 mm with a through bore (Factory's 4 mm hole mesh has
//! the bore open at both faces and a 25 mm block); the peg, 50 mm long with 45 degree chamfers at both
//! ends (0.5 mm in Factory's 4 mm pegs), stands from z = 0 to 50 mm, its bottom flush with the block's
//! bottom. Diameters from factory_asset_info_insertion.yaml; the diametral clearance is hole - peg
//! (4 mm: 0.104 tight / 0.112 loose).

use crate::error::{AssetError, Result};
use crate::geom::{lathe, polygon_wall, Builder};
use crate::iso::Fit;
use crate::part::Part;
use std::fmt;
use std::str::FromStr;

/// Density of pegs and holes [kg/m^3] (factory_asset_info_insertion.yaml).
pub const INSERTION_DENSITY: f32 = 8000.0;
/// Peg length [m].
pub const PEG_LENGTH: f64 = 0.050;
/// Hole block height [m].
pub const HOLE_HEIGHT: f64 = 0.0089916;
/// Factory's SDF resolution for pegs and holes.
pub const PEG_HOLE_SDF_RESOLUTION: u32 = 256;

/// Nominal size of a round peg-and-hole pair.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PegSize {
    /// 4 mm.
    D4,
    /// 8 mm.
    D8,
    /// 12 mm.
    D12,
    /// 16 mm.
    D16,
}

impl PegSize {
    /// All sizes, small to large.
    pub const ALL: [PegSize; 4] = [PegSize::D4, PegSize::D8, PegSize::D12, PegSize::D16];

    /// Nominal diameter [mm].
    pub fn nominal_mm(self) -> u32 {
        match self {
            PegSize::D4 => 4,
            PegSize::D8 => 8,
            PegSize::D12 => 12,
            PegSize::D16 => 16,
        }
    }

    /// Peg diameter at `fit` [m] (factory_asset_info_insertion.yaml).
    pub fn peg_diameter(self, fit: Fit) -> f64 {
        let (tight, loose) = match self {
            PegSize::D4 => (3.996, 3.988),
            PegSize::D8 => (7.995, 7.986),
            PegSize::D12 => (11.994, 11.983),
            PegSize::D16 => (15.994, 15.983),
        };
        1e-3 * match fit {
            Fit::Tight => tight,
            Fit::Loose => loose,
        }
    }

    /// Hole diameter [m] (the same hole serves both fits).
    pub fn hole_diameter(self) -> f64 {
        1e-3 * match self {
            PegSize::D4 => 4.1,
            PegSize::D8 => 8.1,
            PegSize::D12 => 12.2,
            PegSize::D16 => 16.5,
        }
    }
}

impl fmt::Display for PegSize {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.nominal_mm())
    }
}

impl FromStr for PegSize {
    type Err = AssetError;
    /// Accepts "8" or "8mm".
    fn from_str(s: &str) -> Result<Self> {
        let t = s.trim();
        let t = t.strip_suffix("mm").unwrap_or(t);
        PegSize::ALL.into_iter().find(|p| p.nominal_mm().to_string() == t).ok_or_else(|| AssetError::UnknownSize {
            given: s.to_string(),
            valid: PegSize::ALL.iter().map(|p| p.to_string()).collect::<Vec<_>>().join(", "),
        })
    }
}

/// Mesh options for pegs and holes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PegHoleOptions {
    /// Angular segments around the axis (a multiple of 8, at least 16, so the block's corners are
    /// columns). Default 128.
    pub segments: usize,
    /// Axial (= radial) length of the 45 degree chamfer at each peg end [m]; 0 for none. Default 0.5 mm.
    pub peg_chamfer: f64,
    /// Side of the hole's square block [m]. Default 25 mm (Factory's 4 mm hole).
    pub block_width: f64,
}

impl Default for PegHoleOptions {
    fn default() -> Self {
        PegHoleOptions { segments: 128, peg_chamfer: 0.5e-3, block_width: 0.025 }
    }
}

/// An assembled round peg and hole.
#[derive(Clone, Debug)]
pub struct PegHole {
    /// The peg (`round_peg_<d>mm_<fit>`), z from 0 to 50 mm [m].
    pub peg: Part,
    /// The block with the through hole (`round_hole_<d>mm`), z from 0 to 8.9916 mm [m].
    pub hole: Part,
    /// Peg diameter [m].
    pub peg_diameter: f32,
    /// Hole diameter [m].
    pub hole_diameter: f32,
    /// Diametral clearance, hole - peg [m].
    pub clearance: f32,
    /// The peg's 45-degree end chamfer [m].
    pub peg_chamfer: f32,
}

impl PegHole {
    /// The peg's exact (analytic) signed distance field, for the engine's `ShapeGeometry::Revolved` /
    /// `SdfShape::Revolved`: the same radius, length and chamfers as the peg mesh, exactly round (the mesh
    /// is a polygon of `segments` sides, whose facets a baked grid would carry into the contact normals).
    pub fn peg_sdf(&self) -> factory_engine::sdf::revolved::RevolvedSdf {
        factory_engine::sdf::revolved::RevolvedSdf::chamfered_cylinder(
            0.5 * self.peg_diameter,
            PEG_LENGTH as f32,
            self.peg_chamfer,
        )
        .expect("peg_hole checked the chamfer against the radius")
    }
}

/// Builds the peg and hole of `size` at `fit`.
pub fn peg_hole(size: PegSize, fit: Fit, opts: &PegHoleOptions) -> Result<PegHole> {
    let n = opts.segments;
    if n < 16 || !n.is_multiple_of(8) || n > 4096 {
        return Err(AssetError::InvalidOption {
            name: "segments",
            value: n.to_string(),
            expected: "a multiple of 8 from 16 to 4096".into(),
        });
    }
    let (dp, dh) = (size.peg_diameter(fit), size.hole_diameter());
    let rp = 0.5 * dp;
    if !(0.0..0.5 * rp).contains(&opts.peg_chamfer) {
        return Err(AssetError::InvalidOption {
            name: "peg chamfer",
            value: format!("{} m", opts.peg_chamfer),
            expected: format!("0 <= chamfer < {} m (half the peg radius)", 0.5 * rp),
        });
    }
    if opts.block_width.is_nan() || opts.block_width <= dh + 1e-3 {
        return Err(AssetError::InvalidOption {
            name: "block width",
            value: format!("{} m", opts.block_width),
            expected: format!("more than the hole diameter + 1 mm ({} m)", dh + 1e-3),
        });
    }

    let c = opts.peg_chamfer;
    let profile: Vec<(f64, f64)> = if c > 0.0 {
        vec![(0.0, rp - c), (c, rp), (PEG_LENGTH - c, rp), (PEG_LENGTH, rp - c)]
    } else {
        vec![(0.0, rp), (PEG_LENGTH, rp)]
    };
    let mut b = Builder::default();
    let (bottom, top) = b.side(&lathe(&profile, n), true);
    b.disk(&bottom, 0.0, false);
    b.disk(&top, PEG_LENGTH, true);
    let peg_mesh = b.finish();

    let mut b = Builder::default();
    let (out_bottom, out_top) = b.side(&polygon_wall(4, 0.5 * opts.block_width, 0.0, HOLE_HEIGHT, n), true);
    let (bore_bottom, bore_top) = b.side(&lathe(&[(0.0, 0.5 * dh), (HOLE_HEIGHT, 0.5 * dh)], n), false);
    b.annulus(&bore_bottom, &out_bottom, false);
    b.annulus(&bore_top, &out_top, true);
    let hole_mesh = b.finish();

    let d = size.nominal_mm();
    Ok(PegHole {
        peg: Part::new(format!("round_peg_{d}mm_{}", fit.name()), peg_mesh, INSERTION_DENSITY, PEG_HOLE_SDF_RESOLUTION),
        hole: Part::new(format!("round_hole_{d}mm"), hole_mesh, INSERTION_DENSITY, PEG_HOLE_SDF_RESOLUTION),
        peg_diameter: dp as f32,
        hole_diameter: dh as f32,
        clearance: (dh - dp) as f32,
        peg_chamfer: c as f32,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clearances_match_paper_table_vii() {
        // Table VII round pegs: 0.104-0.112, 0.105-0.114, 0.206-0.217, 0.506-0.517 mm (diametral).
        let want = [(0.104, 0.112), (0.105, 0.114), (0.206, 0.217), (0.506, 0.517)];
        for (size, (t, l)) in PegSize::ALL.into_iter().zip(want) {
            let ct = (size.hole_diameter() - size.peg_diameter(Fit::Tight)) * 1e3;
            let cl = (size.hole_diameter() - size.peg_diameter(Fit::Loose)) * 1e3;
            assert!((ct - t).abs() < 1e-9 && (cl - l).abs() < 1e-9, "{size}: {ct} {cl}");
        }
    }

    #[test]
    fn sizes_parse_and_bad_options_are_rejected() {
        assert_eq!("8mm".parse::<PegSize>().unwrap(), PegSize::D8);
        assert_eq!("5".parse::<PegSize>().unwrap_err().to_string(), "unknown size 5; valid: 4, 8, 12, 16");
        let o = PegHoleOptions { segments: 100, ..Default::default() };
        assert!(peg_hole(PegSize::D4, Fit::Tight, &o).is_err());
        let o = PegHoleOptions { block_width: 0.004, ..Default::default() };
        assert!(peg_hole(PegSize::D4, Fit::Tight, &o).unwrap_err().to_string().contains("block width"));
        let o = PegHoleOptions { peg_chamfer: 0.0015, ..Default::default() };
        assert!(peg_hole(PegSize::D4, Fit::Tight, &o).unwrap_err().to_string().contains("chamfer"));
    }

    #[test]
    fn the_exact_peg_field_passes_through_every_vertex_of_the_peg_mesh() {
        // Every mesh vertex lies on the round surface; facet centres lie inside it by the chord's sagitta
        // r (1 - cos(pi / n)), 0.6 um for the 4 mm peg at 128 segments.
        for size in PegSize::ALL {
            let ph = peg_hole(size, Fit::Tight, &PegHoleOptions::default()).unwrap();
            let f = ph.peg_sdf();
            let worst = ph.peg.mesh.positions.iter().map(|&p| f.sample(p).0.abs()).fold(0.0f32, f32::max);
            assert!(worst < 1e-6, "{size}: vertex off the field's surface by {worst} m");
            let r = 0.5 * ph.peg_diameter;
            let sagitta = r * (1.0 - (std::f32::consts::PI / 128.0).cos());
            for t in 0..ph.peg.mesh.triangle_count() {
                let [a, b, c] = ph.peg.mesh.triangle(t);
                let d = f.sample((a + b + c) / 3.0).0;
                assert!(d <= 1e-6 && d >= -sagitta - 1e-6, "{size}: facet centre at {d} m");
            }
        }
    }
}

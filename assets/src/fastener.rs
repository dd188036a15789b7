//! Hex nuts and hex bolts with ISO metric threads, in their assembled zero pose.
//!
//! Frame (Factory's M16 convention): z is the bolt axis; the bolt head is a hexagonal prism from z = 0 to
//! the head height, the fully threaded shank runs from there to head + shank length, and the nut sits on
//! the head (z from head height to head height + nut height) screwed onto the same helix, so every flank
//! faces its mate across the ISO clearance. Hexagons have a flat normal to +x (corners on +-y), as in
//! Factory's nut mesh. The bolt head uses the nut's width across flats (Factory's own bolt heads are
//! round, diameter = width across flats; a hexagon is what a real ISO 4017 bolt has).
//!
//! Threads are right-hand, single start: the thread surface is the helical sweep of the ISO 68-1 profile
//! ([`crate::iso::ThreadProfile`]) sampled on `segments_per_turn` columns, clipped by the end planes and
//! closed by planar annuli (nut) or disks (bolt tip).
//!
//! Bolt tip chamfer (`ThreadOptions::bolt_tip_chamfer`): ISO 4753's chamfered end, a 45-degree cone from
//! the crest down to the thread's minor diameter at the end face (the standard's d_p <= d3; Factory's M16
//! bolt mesh has one, 7.98 -> 6.72 mm in radius over its top 1.3 mm). A nut set on a flat-cut tip rests
//! its bore's edge on the sharp crest and slides off under any side load; on the cone it is centred.

use crate::error::{AssetError, Result};
use crate::geom::{helical_thread, polygon_wall, Builder};
use crate::iso::{FastenerDims, Fit, IsoSize, ThreadSpec, STEEL_DENSITY};
use crate::part::Part;

/// Factory's SDF resolution for nuts (factory_nut_*.urdf).
pub const NUT_SDF_RESOLUTION: u32 = 256;
/// Factory's SDF resolution for bolts (factory_bolt_*.urdf).
pub const BOLT_SDF_RESOLUTION: u32 = 512;

/// Mesh resolution of threaded parts, and the bolt's end.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ThreadOptions {
    /// Angular columns per turn (a multiple of 12, at least 24, so the hexagon's corners are columns).
    /// Default 192: M16 nut ~11.6k triangles, bolt ~20.7k.
    pub segments_per_turn: usize,
    /// Segments along each flank of the profile (1..=16); flanks are straight, so 1 is exact.
    pub flank_subdivisions: usize,
    /// Chamfer the bolt's free end (ISO 4753, 45 degrees down to the minor diameter; the module doc) in
    /// the mesh and the analytic SDF. Default off: the flat-cut tip the nut-bolt benchmarks were measured on.
    pub bolt_tip_chamfer: bool,
}

impl Default for ThreadOptions {
    fn default() -> Self {
        ThreadOptions { segments_per_turn: 192, flank_subdivisions: 1, bolt_tip_chamfer: false }
    }
}

impl ThreadOptions {
    /// Checks the ranges documented on the fields.
    pub fn validate(&self) -> Result<()> {
        let n = self.segments_per_turn;
        if n < 24 || !n.is_multiple_of(12) || n > 4096 {
            return Err(AssetError::InvalidOption {
                name: "segments per turn",
                value: n.to_string(),
                expected: "a multiple of 12 from 24 to 4096 (e.g. 96, 192, 384)".into(),
            });
        }
        if !(1..=16).contains(&self.flank_subdivisions) {
            return Err(AssetError::InvalidOption {
                name: "flank subdivisions",
                value: self.flank_subdivisions.to_string(),
                expected: "1..=16".into(),
            });
        }
        Ok(())
    }
}

/// An assembled nut and bolt.
#[derive(Clone, Debug)]
pub struct NutBolt {
    /// The hex nut (`nut_<size>_<fit>`), z from head height to head height + nut height [m].
    pub nut: Part,
    /// The hex bolt (`bolt_<size>_<fit>`), z from 0 to head height + shank length [m].
    pub bolt: Part,
    /// Thread geometry, both parts' diameters and the clearances between them.
    pub spec: ThreadSpec,
    /// Nut height, width across flats, head height, shank length [m].
    pub dims: FastenerDims,
    /// Thread pitch [m] (= `spec.pitch`).
    pub pitch: f32,
    /// Height of a bolt tooth centre at angle 0 [m]: tooth centres lie on z = phase + P (theta/2pi + m).
    pub thread_phase: f32,
    /// Radius of the bolt's end face when its tip is chamfered (`ThreadOptions::bolt_tip_chamfer`) [m].
    pub bolt_tip_radius: Option<f64>,
}

/// Builds the nut and bolt of `size` at end `fit` of class 6H/6g with Factory's dimensions, in the
/// assembled zero pose.
pub fn nut_bolt(size: IsoSize, fit: Fit, opts: &ThreadOptions) -> Result<NutBolt> {
    nut_bolt_from_spec(ThreadSpec::new(size, fit), size.factory_dims(), opts)
}

/// Builds a nut and bolt from explicit thread diameters and dimensions (any point of the tolerance band,
/// or a hand-made spec: start from [`ThreadSpec::new`] and edit its public diameters). Part names still
/// come from `spec.size` and `spec.fit`. A spec whose nut pitch diameter is not larger than the bolt's
/// gives touching or interpenetrating threads; that is allowed (the paper's contact tests use a 1 um
/// negative clearance) and the caller's responsibility.
pub fn nut_bolt_from_spec(spec: ThreadSpec, dims: FastenerDims, opts: &ThreadOptions) -> Result<NutBolt> {
    opts.validate()?;
    let positive = [dims.nut_height, dims.width_across_flats, dims.head_height, dims.shank_length];
    if positive.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
        return Err(AssetError::InvalidOption {
            name: "fastener dimensions",
            value: format!("{dims:?}"),
            expected: "finite positive lengths [m]".into(),
        });
    }
    if dims.nut_height > dims.shank_length {
        return Err(AssetError::InvalidOption {
            name: "nut height",
            value: format!("{} m", dims.nut_height),
            expected: format!("at most the shank length {} m (the nut sits on the shank)", dims.shank_length),
        });
    }
    let widest = spec.nut_root_diameter.max(spec.bolt_major_diameter);
    if dims.width_across_flats <= widest {
        return Err(AssetError::InvalidOption {
            name: "width across flats",
            value: format!("{} m", dims.width_across_flats),
            expected: format!("more than the thread's largest diameter {widest} m"),
        });
    }
    let n = opts.segments_per_turn;
    let apothem = 0.5 * dims.width_across_flats;
    let (head, top) = (dims.head_height, dims.head_height + dims.shank_length);
    let (nut_lo, nut_hi) = (dims.head_height, dims.head_height + dims.nut_height);
    // A tooth centre at (theta = 0, z = head height); shared by nut and bolt, which puts them in phase.
    let phase = head;

    let bolt_profile = spec.bolt_profile();
    let nut_profile = spec.nut_profile();
    let bolt_breaks = bolt_profile.breakpoints(opts.flank_subdivisions)?;
    let nut_breaks = nut_profile.breakpoints(opts.flank_subdivisions)?;

    let mut b = Builder::default();
    let (head_bottom, head_top) = b.side(&polygon_wall(6, apothem, 0.0, head, n), true);
    b.disk(&head_bottom, 0.0, false);
    let mut shank = helical_thread(&bolt_profile, &bolt_breaks, n, phase, head, top);
    let bolt_tip_radius = opts.bolt_tip_chamfer.then(|| bolt_tip_radius(&spec));
    if let Some(tip) = bolt_tip_radius {
        chamfer_top(&mut shank, tip, top);
    }
    let (shank_bottom, shank_top) = b.side(&shank, true);
    b.annulus(&shank_bottom, &head_top, true);
    b.disk(&shank_top, top, true);
    let bolt_mesh = b.finish();

    let mut b = Builder::default();
    let (hex_bottom, hex_top) = b.side(&polygon_wall(6, apothem, nut_lo, nut_hi, n), true);
    let (bore_bottom, bore_top) = b.side(&helical_thread(&nut_profile, &nut_breaks, n, phase, nut_lo, nut_hi), false);
    b.annulus(&bore_bottom, &hex_bottom, false);
    b.annulus(&bore_top, &hex_top, true);
    let nut_mesh = b.finish();

    let tag = format!("{}_{}", spec.size.name().to_lowercase(), spec.fit.name());
    Ok(NutBolt {
        nut: Part::new(format!("nut_{tag}"), nut_mesh, STEEL_DENSITY, NUT_SDF_RESOLUTION),
        bolt: Part::new(format!("bolt_{tag}"), bolt_mesh, STEEL_DENSITY, BOLT_SDF_RESOLUTION),
        spec,
        dims,
        pitch: spec.pitch as f32,
        thread_phase: phase as f32,
        bolt_tip_radius,
    })
}

/// Cuts a surface's columns with the 45-degree cone r <= tip + (top - z): each column's (z, r) polyline
/// becomes min(polyline, cone line), exactly (both are piecewise linear in z: a point is added where a
/// segment crosses the line, then every radius is clamped to it).
fn chamfer_top(surface: &mut crate::geom::ColumnSurface, tip: f64, top: f64) {
    let cone = |z: f64| tip + (top - z);
    for col in &mut surface.columns {
        let mut out = Vec::with_capacity(col.len() + 4);
        for (i, p) in col.iter().enumerate() {
            if let Some(q) = i.checked_sub(1).map(|j| col[j]) {
                // Excess over the cone at both ends; a sign change is a crossing inside the segment.
                let (e0, e1) = (q.r - cone(q.z), p.r - cone(p.z));
                if (e0 < 0.0 && e1 > 0.0) || (e0 > 0.0 && e1 < 0.0) {
                    let t = e0 / (e0 - e1);
                    let z = q.z + t * (p.z - q.z);
                    out.push(crate::geom::ColumnPoint { z, r: cone(z), key: q.key + (z - q.z) });
                }
            }
            out.push(crate::geom::ColumnPoint { r: p.r.min(cone(p.z)), ..*p });
        }
        *col = out;
    }
}

/// Radius of a chamfered bolt's end face [m]: ISO 4753 asks d_p <= d3, the minor diameter of ISO 724's
/// rounded root, d3 = d - 1.226869 P (M16: 6.773 mm; Factory's bolt mesh: 6.72 mm). The generated profile's
/// flat root is shallower (d1 plus the fit's shift), so the cone cuts a little into the core at the face.
pub fn bolt_tip_radius(spec: &ThreadSpec) -> f64 {
    0.5 * (spec.nominal_diameter - 1.226869 * spec.pitch)
}

/// Axial (= radial) length of a chamfered bolt's 45-degree cone, crest radius minus end-face radius [m].
pub fn bolt_tip_chamfer_height(spec: &ThreadSpec) -> f64 {
    spec.bolt_profile().max_radius - bolt_tip_radius(spec)
}

/// Volume the bolt tip chamfer removes [m^3]: pi times the integral over the chamfer's height of the mean
/// over one pitch of max(0, r(u)^2 - cone(z)^2) (at a given height the angle sweeps the helical coordinate
/// over one period), by the midpoint rule on a 400 x 400 grid (converged to ~1e-6 of the result).
pub fn bolt_tip_chamfer_volume(spec: &ThreadSpec) -> f64 {
    let prof = spec.bolt_profile();
    let (tip, height) = (bolt_tip_radius(spec), bolt_tip_chamfer_height(spec));
    let n = 400;
    let mut sum = 0.0;
    for i in 0..n {
        // Depth below the end face, and the cone's radius there.
        let depth = (i as f64 + 0.5) / n as f64 * height;
        let c = tip + depth;
        let mean = (0..n)
            .map(|j| {
                let r = prof.radius((j as f64 + 0.5) / n as f64 * prof.pitch);
                (r * r - c * c).max(0.0)
            })
            .sum::<f64>()
            / n as f64;
        sum += mean;
    }
    std::f64::consts::PI * sum * height / n as f64
}

/// Closed-form nut volume [m^3]: hexagon area x h - h x pi x mean over one pitch of r(u)^2, with r the
/// nut's bore profile (a helical bore has the same cross-section area at every height).
pub fn nut_closed_form_volume(spec: &ThreadSpec, dims: &FastenerDims) -> f64 {
    let h = dims.nut_height;
    h * (dims.hexagon_area() - std::f64::consts::PI * spec.nut_profile().mean_square_radius())
}

/// Closed-form bolt volume [m^3]: hexagonal head plus the threaded core, pi x mean r(u)^2 x shank length.
pub fn bolt_closed_form_volume(spec: &ThreadSpec, dims: &FastenerDims) -> f64 {
    dims.hexagon_area() * dims.head_height
        + std::f64::consts::PI * spec.bolt_profile().mean_square_radius() * dims.shank_length
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn options_are_validated() {
        let base = ThreadOptions::default();
        assert!(base.validate().is_ok());
        for bad in [ThreadOptions { segments_per_turn: 100, ..base }, ThreadOptions { segments_per_turn: 12, ..base }] {
            let e = nut_bolt(IsoSize::M8, Fit::Tight, &bad).unwrap_err().to_string();
            assert!(e.contains("multiple of 12"), "{e}");
        }
        let e = ThreadOptions { flank_subdivisions: 0, ..base }.validate().unwrap_err().to_string();
        assert!(e.contains("1..=16"), "{e}");
        let spec = ThreadSpec::new(IsoSize::M8, Fit::Tight);
        let dims = IsoSize::M8.factory_dims();
        let narrow = FastenerDims { width_across_flats: 0.007, ..dims };
        assert!(nut_bolt_from_spec(spec, narrow, &base).unwrap_err().to_string().contains("width across flats"));
        let tall = FastenerDims { nut_height: 0.05, ..dims };
        assert!(nut_bolt_from_spec(spec, tall, &base).unwrap_err().to_string().contains("nut height"));
        let zero = FastenerDims { head_height: 0.0, ..dims };
        assert!(nut_bolt_from_spec(spec, zero, &base).is_err());
    }

    #[test]
    fn from_spec_with_a_mid_band_bolt_is_closed_and_in_between() {
        let tight = ThreadSpec::new(IsoSize::M12, Fit::Tight);
        let loose = ThreadSpec::new(IsoSize::M12, Fit::Loose);
        let mut mid = tight;
        mid.bolt_pitch_diameter = 0.5 * (tight.bolt_pitch_diameter + loose.bolt_pitch_diameter);
        mid.bolt_root_diameter = 0.5 * (tight.bolt_root_diameter + loose.bolt_root_diameter);
        let opts = ThreadOptions { segments_per_turn: 48, ..Default::default() };
        let nb = nut_bolt_from_spec(mid, IsoSize::M12.factory_dims(), &opts).unwrap();
        assert!(nb.bolt.mesh.topology().is_watertight());
        let m = |s: ThreadSpec| {
            nut_bolt_from_spec(s, IsoSize::M12.factory_dims(), &opts).unwrap().bolt.mass_properties.mass
        };
        let (mt, mm, ml) = (m(tight), nb.bolt.mass_properties.mass, m(loose));
        assert!(mt > mm && mm > ml, "{mt} {mm} {ml}");
    }

    #[test]
    fn coarse_m8_is_closed_with_flank_subdivisions() {
        let opts = ThreadOptions { segments_per_turn: 48, flank_subdivisions: 3, bolt_tip_chamfer: true };
        let nb = nut_bolt(IsoSize::M8, Fit::Loose, &opts).unwrap();
        for part in [&nb.nut, &nb.bolt] {
            assert!(part.mesh.topology().is_watertight(), "{} {:?}", part.name, part.mesh.topology());
            assert!(part.mesh.signed_volume() > 0.0);
        }
    }
}

impl NutBolt {
    /// The bolt's exact (analytic) signed distance field, for the engine's `SdfShape::Thread`: the same
    /// profile, phase, thread span and hexagonal head as the bolt mesh, without the mesh's chordal error
    /// (the mesh samples the helix on `segments_per_turn` columns) or a grid's interpolation error.
    pub fn bolt_sdf(&self) -> factory_engine::sdf::thread::ThreadSdf {
        let prof = self.spec.bolt_profile();
        let d = &self.dims;
        factory_engine::sdf::thread::ThreadSdf {
            pitch: prof.pitch as f32,
            phase: self.thread_phase,
            pitch_radius: prof.pitch_radius as f32,
            min_radius: prof.min_radius as f32,
            max_radius: prof.max_radius as f32,
            z_lo: d.head_height as f32,
            z_hi: (d.head_height + d.shank_length) as f32,
            head: Some(factory_engine::sdf::thread::HexPrism {
                apothem: (0.5 * d.width_across_flats) as f32,
                z0: 0.0,
                z1: d.head_height as f32,
            }),
            tip_radius: self.bolt_tip_radius.unwrap_or(0.0) as f32,
        }
    }
}

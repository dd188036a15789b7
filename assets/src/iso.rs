//! ISO metric screw threads: the ISO 68-1 basic profile, the ISO 965-1 tolerance class 6H/6g, and
//! Factory's fastener dimensions (nut height, width across flats, bolt head height, shank length).
//!
//! Conventions: every length in this module's public structs is in metres unless the field name says
//! `_mm` or `_um`; angles in radians.
//!
//! ISO 68-1 basic profile (identical for nut and bolt): fundamental triangle of height
//! H = sqrt(3)/2 P with flanks at 30 degrees from the radial plane (60 degree included angle);
//! the major diameter d = D is H/8 below the triangle's apex (flat of width P/8), the minor diameter
//! d1 = D1 = d - 5/4 H = d - 1.082532 P is H/4 above its base (flat of width P/4), and the pitch diameter
//! d2 = D2 = d - 3/4 H = d - 0.649519 P is where tooth and groove are both P/2 wide.
//!
//! ISO 965-1 (2013), tolerance class 6H (nut) / 6g (bolt), values in micrometres:
//! - fundamental deviation of g, es = -(15 + 11 P) rounded (ISO 965-1 Table 3); EI of H is 0;
//! - Td(6), bolt major diameter tolerance, grade 6 (Table 5, ~ 180 P^(2/3) - 3.15 / sqrt(P));
//! - TD1(6), nut minor diameter tolerance, grade 6 (Table 4, ~ 230 P^0.7 for P >= 1 mm,
//!   433 P - 190 P^1.22 for P < 1 mm);
//! - Td2(6), bolt pitch diameter tolerance, grade 6 (Table 7, ~ 90 P^0.4 d^0.1, d the geometric mean of the
//!   diameter range: 2.8-5.6, 5.6-11.2, 11.2-22.4 mm);
//! - TD2(6), nut pitch diameter tolerance, grade 6 (Table 6, ~ 1.32 Td2(6)).
//!
//! | size | P    | es(g) | Td(6) | Td2(6) | TD1(6) | TD2(6) |
//! |------|------|-------|-------|--------|--------|--------|
//! | M4   | 0.70 | -22   | 140   | 90     | 180    | 118    |
//! | M8   | 1.25 | -28   | 212   | 118    | 265    | 160    |
//! | M12  | 1.75 | -34   | 265   | 150    | 335    | 200    |
//! | M16  | 2.00 | -38   | 280   | 160    | 375    | 212    |
//! | M20  | 2.50 | -42   | 335   | 170    | 450    | 224    |
//!
//! (M16 6g: d 15.962/15.682, d2 14.663/14.503; 6H: D2 14.701/14.913, D1 13.835/14.210.)
//!
//! Fits, as the ends of the tolerance band (paper Table VII): [`Fit::Tight`] puts both parts at their
//! maximum-material limits (bolt d = d + es, d2 = d2 + es; nut D2 = D2, D1 = D1: smallest clearance),
//! [`Fit::Loose`] at their least-material limits (bolt d = d + es - Td, d2 = d2 + es - Td2; nut
//! D2 = D2 + TD2, D1 = D1 + TD1: largest clearance). ISO 965-1 bounds the bolt root (d3) and the nut major
//! diameter (D) on one side only; this crate keeps the basic flat roots and moves them with the pitch
//! diameter (bolt root = d1 + (d2' - d2), nut root = D + (D2' - D2)), so the flanks keep their basic
//! shape and the root flats stay P/4 (bolt) and P/8 (nut) wide.

use crate::error::{AssetError, Result};
use std::fmt;
use std::str::FromStr;

/// sqrt(3): the flank slope dr/dz of a 60 degree thread.
pub const SQRT3: f64 = 1.732_050_807_568_877_2;

/// Density of steel used for nuts and bolts [kg/m^3] (Factory's FactoryEnvNutBolt.yaml).
pub const STEEL_DENSITY: f32 = 7850.0;

/// An ISO metric coarse thread size of Factory's nut-and-bolt set.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum IsoSize {
    /// M4 x 0.7.
    M4,
    /// M8 x 1.25.
    M8,
    /// M12 x 1.75.
    M12,
    /// M16 x 2 (Factory's default).
    M16,
    /// M20 x 2.5.
    M20,
}

/// Which end of the ISO 965-1 tolerance band both mating parts sit at.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Fit {
    /// Maximum material: the smallest clearance the tolerance class allows.
    Tight,
    /// Least material: the largest clearance the tolerance class allows.
    Loose,
}

/// One row of ISO 965-1 class 6H/6g for a size, in micrometres (see the module table).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Iso965Row {
    /// Thread pitch P [mm].
    pub pitch_mm: f64,
    /// Fundamental deviation es of tolerance position g (negative) [um].
    pub es_um: f64,
    /// Td(6): bolt major diameter tolerance [um].
    pub bolt_major_tol_um: f64,
    /// Td2(6): bolt pitch diameter tolerance [um].
    pub bolt_pitch_tol_um: f64,
    /// TD1(6): nut minor diameter tolerance [um].
    pub nut_minor_tol_um: f64,
    /// TD2(6): nut pitch diameter tolerance [um].
    pub nut_pitch_tol_um: f64,
}

/// Factory's nut and bolt dimensions (factory_asset_info_nut_bolt.yaml), metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FastenerDims {
    /// Nut height [m].
    pub nut_height: f64,
    /// Nut (and bolt head) width across flats [m].
    pub width_across_flats: f64,
    /// Bolt head height [m].
    pub head_height: f64,
    /// Threaded shank length above the head [m].
    pub shank_length: f64,
}

impl FastenerDims {
    /// Width across corners of the hexagon, 2/sqrt(3) x flats [m].
    pub fn width_across_corners(&self) -> f64 {
        2.0 * self.width_across_flats / SQRT3
    }

    /// Area of the hexagon, sqrt(3)/2 x flats^2 [m^2].
    pub fn hexagon_area(&self) -> f64 {
        SQRT3 / 2.0 * self.width_across_flats * self.width_across_flats
    }
}

impl IsoSize {
    /// All sizes, small to large.
    pub const ALL: [IsoSize; 5] = [IsoSize::M4, IsoSize::M8, IsoSize::M12, IsoSize::M16, IsoSize::M20];

    /// The size's name as written on drawings ("M16").
    pub fn name(self) -> &'static str {
        match self {
            IsoSize::M4 => "M4",
            IsoSize::M8 => "M8",
            IsoSize::M12 => "M12",
            IsoSize::M16 => "M16",
            IsoSize::M20 => "M20",
        }
    }

    /// Nominal (basic major) diameter d [mm].
    pub fn nominal_diameter_mm(self) -> f64 {
        match self {
            IsoSize::M4 => 4.0,
            IsoSize::M8 => 8.0,
            IsoSize::M12 => 12.0,
            IsoSize::M16 => 16.0,
            IsoSize::M20 => 20.0,
        }
    }

    /// The ISO 965-1 6H/6g row for this size (coarse pitch).
    pub fn iso965(self) -> Iso965Row {
        // (P mm, es um, Td um, Td2 um, TD1 um, TD2 um): ISO 965-1 Tables 3-7, see the module docs.
        let (p, es, td, td2, tdd1, tdd2) = match self {
            IsoSize::M4 => (0.7, -22.0, 140.0, 90.0, 180.0, 118.0),
            IsoSize::M8 => (1.25, -28.0, 212.0, 118.0, 265.0, 160.0),
            IsoSize::M12 => (1.75, -34.0, 265.0, 150.0, 335.0, 200.0),
            IsoSize::M16 => (2.0, -38.0, 280.0, 160.0, 375.0, 212.0),
            IsoSize::M20 => (2.5, -42.0, 335.0, 170.0, 450.0, 224.0),
        };
        Iso965Row {
            pitch_mm: p,
            es_um: es,
            bolt_major_tol_um: td,
            bolt_pitch_tol_um: td2,
            nut_minor_tol_um: tdd1,
            nut_pitch_tol_um: tdd2,
        }
    }

    /// Factory's nut height, width across flats, head height and shank length for this size.
    pub fn factory_dims(self) -> FastenerDims {
        // (nut height, flats, head height, shank) [mm], factory_asset_info_nut_bolt.yaml.
        let (h, f, head, shank) = match self {
            IsoSize::M4 => (3.2, 7.0, 4.0, 16.0),
            IsoSize::M8 => (6.5, 13.0, 8.0, 18.0),
            IsoSize::M12 => (10.0, 19.0, 12.0, 20.0),
            IsoSize::M16 => (13.0, 24.0, 16.0, 25.0),
            IsoSize::M20 => (16.0, 30.0, 20.0, 45.0),
        };
        FastenerDims {
            nut_height: h * 1e-3,
            width_across_flats: f * 1e-3,
            head_height: head * 1e-3,
            shank_length: shank * 1e-3,
        }
    }
}

fn valid_list<T: fmt::Display>(all: &[T]) -> String {
    all.iter().map(|v| v.to_string()).collect::<Vec<_>>().join(", ")
}

impl fmt::Display for IsoSize {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for IsoSize {
    type Err = AssetError;
    /// Accepts "M16" or "m16".
    fn from_str(s: &str) -> Result<Self> {
        IsoSize::ALL
            .into_iter()
            .find(|size| size.name().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| AssetError::UnknownSize { given: s.to_string(), valid: valid_list(&IsoSize::ALL) })
    }
}

impl Fit {
    /// Both fits.
    pub const ALL: [Fit; 2] = [Fit::Tight, Fit::Loose];

    /// "tight" or "loose", as in Factory's asset names.
    pub fn name(self) -> &'static str {
        match self {
            Fit::Tight => "tight",
            Fit::Loose => "loose",
        }
    }
}

impl fmt::Display for Fit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Fit {
    type Err = AssetError;
    /// Accepts "tight" or "loose" (any case).
    fn from_str(s: &str) -> Result<Self> {
        Fit::ALL
            .into_iter()
            .find(|fit| fit.name().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| AssetError::UnknownFit { given: s.to_string(), valid: valid_list(&Fit::ALL) })
    }
}

/// The thread geometry of one nut-and-bolt pair: basic ISO 68-1 numbers and the actual diameters of each
/// part at the chosen end of the ISO 965-1 band. Lengths in metres, angles in radians.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ThreadSpec {
    /// Thread size.
    pub size: IsoSize,
    /// End of the tolerance band.
    pub fit: Fit,
    /// Pitch P (= lead, single start) [m].
    pub pitch: f64,
    /// Height of the fundamental triangle H = sqrt(3)/2 P [m].
    pub fundamental_height: f64,
    /// Basic major diameter d = D [m].
    pub nominal_diameter: f64,
    /// Basic pitch diameter d2 = D2 = d - 0.649519 P [m].
    pub basic_pitch_diameter: f64,
    /// Basic minor diameter d1 = D1 = d - 1.082532 P [m].
    pub basic_minor_diameter: f64,
    /// Lead angle on the basic pitch diameter, atan(P / (pi d2)) [rad].
    pub lead_angle: f64,
    /// Bolt major (crest) diameter at this fit [m].
    pub bolt_major_diameter: f64,
    /// Bolt pitch diameter at this fit [m].
    pub bolt_pitch_diameter: f64,
    /// Bolt root (flat) diameter at this fit [m].
    pub bolt_root_diameter: f64,
    /// Nut minor (crest) diameter at this fit [m].
    pub nut_minor_diameter: f64,
    /// Nut pitch diameter at this fit [m].
    pub nut_pitch_diameter: f64,
    /// Nut root (flat) diameter at this fit [m].
    pub nut_root_diameter: f64,
}

impl ThreadSpec {
    /// The thread of `size` at end `fit` of class 6H/6g.
    pub fn new(size: IsoSize, fit: Fit) -> ThreadSpec {
        let row = size.iso965();
        let um = 1e-6;
        let p = row.pitch_mm * 1e-3;
        let d = size.nominal_diameter_mm() * 1e-3;
        let h = SQRT3 / 2.0 * p;
        let d2 = d - 0.75 * h;
        let d1 = d - 1.25 * h;
        let es = row.es_um * um;
        let (bolt_major, bolt_pitch, nut_pitch, nut_minor) = match fit {
            Fit::Tight => (d + es, d2 + es, d2, d1),
            Fit::Loose => (
                d + es - row.bolt_major_tol_um * um,
                d2 + es - row.bolt_pitch_tol_um * um,
                d2 + row.nut_pitch_tol_um * um,
                d1 + row.nut_minor_tol_um * um,
            ),
        };
        ThreadSpec {
            size,
            fit,
            pitch: p,
            fundamental_height: h,
            nominal_diameter: d,
            basic_pitch_diameter: d2,
            basic_minor_diameter: d1,
            lead_angle: (p / (std::f64::consts::PI * d2)).atan(),
            bolt_major_diameter: bolt_major,
            bolt_pitch_diameter: bolt_pitch,
            bolt_root_diameter: d1 + (bolt_pitch - d2),
            nut_minor_diameter: nut_minor,
            nut_pitch_diameter: nut_pitch,
            nut_root_diameter: d + (nut_pitch - d2),
        }
    }

    /// Radial gap between the nut's and the bolt's flanks when the helices are in phase,
    /// (D2' - d2') / 2 [m]. This is also the smallest radial gap anywhere along the profile.
    pub fn radial_flank_clearance(&self) -> f64 {
        0.5 * (self.nut_pitch_diameter - self.bolt_pitch_diameter)
    }

    /// Axial gap between each bolt flank and the facing nut flank in the zero pose, radial / sqrt(3) [m]
    /// (the total axial play is twice this).
    pub fn axial_flank_clearance(&self) -> f64 {
        self.radial_flank_clearance() / SQRT3
    }

    /// Gap between facing flanks measured along the flank normal, radial / 2 [m].
    pub fn normal_flank_clearance(&self) -> f64 {
        0.5 * self.radial_flank_clearance()
    }

    /// Radial gap at the bolt's crest (nut root radius - bolt major radius) [m].
    pub fn crest_clearance(&self) -> f64 {
        0.5 * (self.nut_root_diameter - self.bolt_major_diameter)
    }

    /// Radial gap at the bolt's root (nut minor radius - bolt root radius) [m].
    pub fn root_clearance(&self) -> f64 {
        0.5 * (self.nut_minor_diameter - self.bolt_root_diameter)
    }

    /// tan of the lead angle, P / (pi d2) (M16: 0.0433).
    pub fn tan_lead_angle(&self) -> f64 {
        self.lead_angle.tan()
    }

    /// The bolt's radial profile: material inside the returned radius.
    pub fn bolt_profile(&self) -> ThreadProfile {
        ThreadProfile {
            pitch: self.pitch,
            pitch_radius: 0.5 * self.bolt_pitch_diameter,
            min_radius: 0.5 * self.bolt_root_diameter,
            max_radius: 0.5 * self.bolt_major_diameter,
        }
    }

    /// The nut's radial profile: the bore (void) is inside the returned radius, in phase with
    /// [`ThreadSpec::bolt_profile`] (a bolt tooth sits in every nut groove).
    pub fn nut_profile(&self) -> ThreadProfile {
        ThreadProfile {
            pitch: self.pitch,
            pitch_radius: 0.5 * self.nut_pitch_diameter,
            min_radius: 0.5 * self.nut_minor_diameter,
            max_radius: 0.5 * self.nut_root_diameter,
        }
    }
}

/// A 60 degree trapezoidal thread profile as radius against the helical coordinate u (axial offset from
/// a tooth centre, period `pitch`): r(u) = clamp(r_pitch + sqrt(3) (P/4 - |u|), r_min, r_max) for
/// |u| <= P/2. For a bolt the region inside r is material; for a nut it is the bore. Metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ThreadProfile {
    /// Pitch [m].
    pub pitch: f64,
    /// Radius where the tooth is P/2 wide [m].
    pub pitch_radius: f64,
    /// Root (smallest) radius [m].
    pub min_radius: f64,
    /// Crest (largest) radius [m].
    pub max_radius: f64,
}

impl ThreadProfile {
    /// Radius [m] at helical coordinate `u` [m].
    pub fn radius(&self, u: f64) -> f64 {
        let p = self.pitch;
        let w = u - p * (u / p).round();
        (self.pitch_radius + SQRT3 * (0.25 * p - w.abs())).clamp(self.min_radius, self.max_radius)
    }

    /// Half width of the crest flat, P/4 - (r_max - r_pitch)/sqrt(3) [m].
    pub fn crest_half_width(&self) -> f64 {
        0.25 * self.pitch - (self.max_radius - self.pitch_radius) / SQRT3
    }

    /// Offset from the tooth centre where the root flat starts, P/4 + (r_pitch - r_min)/sqrt(3) [m].
    pub fn root_start(&self) -> f64 {
        0.25 * self.pitch + (self.pitch_radius - self.min_radius) / SQRT3
    }

    /// The profile's corners within one period, sorted, in [-P/2, P/2): root end, crest start, crest end,
    /// root start, plus `flank_subdivisions - 1` points inside each flank. Errors when a flat would have
    /// negative width.
    pub fn breakpoints(&self, flank_subdivisions: usize) -> Result<Vec<f64>> {
        let p = self.pitch;
        let (a, b) = (self.crest_half_width(), self.root_start());
        let tol = 1e-9 * p;
        if self.min_radius.is_nan()
            || self.min_radius >= self.max_radius
            || a.is_nan()
            || a < -tol
            || b > 0.5 * p + tol
            || a >= b
        {
            return Err(AssetError::Profile(format!(
                "pitch {p} m, pitch radius {}, root {}, crest {}: crest half width {a}, root start {b} \
                 (need 0 <= crest half width < root start <= P/2)",
                self.pitch_radius, self.min_radius, self.max_radius
            )));
        }
        let a = a.max(0.0);
        let b = b.min(0.5 * p);
        let n = flank_subdivisions.max(1);
        let mut pts = Vec::with_capacity(4 + 2 * n);
        // Rising flank from -b to -a (inclusive of both ends).
        for i in 0..=n {
            pts.push(-b + (b - a) * i as f64 / n as f64);
        }
        if a > tol {
            // Falling flank from a to b; b coincides with -b modulo P when the root flat has zero width.
            let last = if b >= 0.5 * p - tol { n - 1 } else { n };
            for i in 0..=last {
                pts.push(a + (b - a) * i as f64 / n as f64);
            }
        } else {
            let last = if b >= 0.5 * p - tol { n - 1 } else { n };
            for i in 1..=last {
                pts.push(a + (b - a) * i as f64 / n as f64);
            }
        }
        Ok(pts)
    }

    /// Mean of r(u)^2 over one period [m^2] (pi times this is the bore or core cross-section area, the
    /// same at every height for a helical surface). Exact: r is piecewise linear in u.
    pub fn mean_square_radius(&self) -> f64 {
        let p = self.pitch;
        let (a, b) = (self.crest_half_width().max(0.0), self.root_start().min(0.5 * p));
        let (r0, r1) = (self.min_radius, self.max_radius);
        // Over the half period [0, P/2]: crest flat [0, a] at r1, flank [a, b] linear r1 -> r0, root [b, P/2].
        let flank = (b - a) * (r1 * r1 + r1 * r0 + r0 * r0) / 3.0;
        (a * r1 * r1 + flank + (0.5 * p - b) * r0 * r0) / (0.5 * p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// ISO 965-1 rounds its tolerance formulas to preferred numbers; the printed tables are within this
    /// relative distance of the formulas for the five coarse pitches used here.
    const ISO_ROUNDING_REL: f64 = 0.05;

    #[test]
    fn table_matches_iso965_formulas() {
        for size in IsoSize::ALL {
            let row = size.iso965();
            let p = row.pitch_mm;
            let d = size.nominal_diameter_mm();
            let range_mean = if d <= 5.6 {
                (2.8f64 * 5.6).sqrt()
            } else if d <= 11.2 {
                (5.6f64 * 11.2).sqrt()
            } else {
                (11.2f64 * 22.4).sqrt()
            };
            let es = -(15.0 + 11.0 * p);
            let td = 180.0 * p.powf(2.0 / 3.0) - 3.15 / p.sqrt();
            let td1 = if p < 1.0 { 433.0 * p - 190.0 * p.powf(1.22) } else { 230.0 * p.powf(0.7) };
            let td2 = 90.0 * p.powf(0.4) * range_mean.powf(0.1);
            let tdd2 = 1.32 * td2;
            for (name, table, formula) in [
                ("es", row.es_um, es),
                ("Td", row.bolt_major_tol_um, td),
                ("TD1", row.nut_minor_tol_um, td1),
                ("Td2", row.bolt_pitch_tol_um, td2),
                ("TD2", row.nut_pitch_tol_um, tdd2),
            ] {
                let rel = (table - formula).abs() / formula.abs();
                assert!(rel < ISO_ROUNDING_REL, "{size} {name}: table {table} vs formula {formula:.1}");
            }
        }
    }

    /// Published M16 6g/6H limits are given to the micrometre.
    const LIMIT_TOL: f64 = 0.5e-6;

    #[test]
    fn m16_limits_match_published_values() {
        let t = ThreadSpec::new(IsoSize::M16, Fit::Tight);
        let l = ThreadSpec::new(IsoSize::M16, Fit::Loose);
        for (got, want) in [
            (t.bolt_major_diameter, 15.962e-3),
            (l.bolt_major_diameter, 15.682e-3),
            (t.bolt_pitch_diameter, 14.663e-3),
            (l.bolt_pitch_diameter, 14.503e-3),
            (t.nut_pitch_diameter, 14.701e-3),
            (l.nut_pitch_diameter, 14.913e-3),
            (t.nut_minor_diameter, 13.835e-3),
            (l.nut_minor_diameter, 14.210e-3),
        ] {
            assert!((got - want).abs() < LIMIT_TOL, "{got} vs {want}");
        }
    }

    #[test]
    fn basic_profile_flats_follow_iso68() {
        let spec = ThreadSpec::new(IsoSize::M16, Fit::Tight);
        let p = spec.pitch;
        // Tight bolt: shifted basic profile, so the crest flat is P/8 and the root flat P/4.
        let b = spec.bolt_profile();
        assert!((2.0 * b.crest_half_width() - p / 8.0).abs() < 1e-12);
        assert!((p - 2.0 * b.root_start() - p / 4.0).abs() < 1e-12);
        // The nut's groove bottom (its root) is P/8 wide and its crest P/4 wide.
        let n = spec.nut_profile();
        assert!((2.0 * n.crest_half_width() - p / 8.0).abs() < 1e-12);
        assert!((p - 2.0 * n.root_start() - p / 4.0).abs() < 1e-12);
        assert!((b.radius(0.0) - b.max_radius).abs() < 1e-15);
        assert!((b.radius(0.5 * p) - b.min_radius).abs() < 1e-15);
        assert!((b.radius(0.25 * p) - b.pitch_radius).abs() < 1e-15);
        assert!((b.radius(0.25 * p + 3.0 * p) - b.pitch_radius).abs() < 1e-12);
    }

    #[test]
    fn mean_square_radius_matches_sampling() {
        for fit in Fit::ALL {
            let prof = ThreadSpec::new(IsoSize::M12, fit).nut_profile();
            let n = 200_000;
            let sampled: f64 =
                (0..n).map(|i| prof.radius(prof.pitch * (i as f64 + 0.5) / n as f64).powi(2)).sum::<f64>() / n as f64;
            assert!((sampled - prof.mean_square_radius()).abs() / sampled < 1e-8);
        }
    }

    #[test]
    fn breakpoints_are_sorted_within_one_period() {
        for size in IsoSize::ALL {
            for fit in Fit::ALL {
                let spec = ThreadSpec::new(size, fit);
                for prof in [spec.bolt_profile(), spec.nut_profile()] {
                    let bp = prof.breakpoints(2).unwrap();
                    assert_eq!(bp.len(), 6, "{size} {fit}");
                    assert!(bp.windows(2).all(|w| w[0] < w[1]));
                    assert!(bp[0] >= -0.5 * prof.pitch && *bp.last().unwrap() < 0.5 * prof.pitch);
                }
            }
        }
        let bad = ThreadProfile { pitch: 1.0, pitch_radius: 1.0, min_radius: 1.2, max_radius: 1.1 };
        assert!(bad.breakpoints(1).is_err());
    }

    #[test]
    fn names_parse_and_errors_list_valid_values() {
        assert_eq!("m16".parse::<IsoSize>().unwrap(), IsoSize::M16);
        assert_eq!("Loose".parse::<Fit>().unwrap(), Fit::Loose);
        let e = "M5".parse::<IsoSize>().unwrap_err().to_string();
        assert_eq!(e, "unknown size M5; valid: M4, M8, M12, M16, M20");
        let e = "snug".parse::<Fit>().unwrap_err().to_string();
        assert_eq!(e, "unknown fit snug; valid: tight, loose");
    }
}

//! factory-assets: procedural parts for Factory's assembly tasks (Narang et al., RSS 2022, section IV-A),
//! generated from the standards' parameters and exported as OBJ + URDF.
//!
//! - [`nut_bolt`]: ISO metric hex nuts and bolts M4-M20 (ISO 68-1 profile, ISO 965-1 class 6H/6g at the
//!   tight or loose end of the band, Factory's nut/head/shank dimensions), helical threads, assembled.
//! - [`peg_hole`]: round pegs and holes 4-16 mm with Factory's (paper Table VII) diameters, assembled.
//! - [`bowl`] and [`torus`]: the paper's pile-scene parts (section III-D, Table VI), solids of revolution with
//!   an exact SDF ([`RevolvedPart::sdf`]) and a mesh that revolves the same profile.
//! - [`Part`]: a closed, outward-wound [`TriMesh`](factory_engine::mesh::TriMesh) with mass properties and
//!   its SDF resolution; [`Part::write`] writes `<name>.obj` and `<name>.urdf`.
//!
//! Units: metres, kilograms, seconds, radians throughout (fields say otherwise where they are in mm/um).
//! Every assembly's zero pose is the assembled configuration.
//!
//! ```
//! use factory_assets::{nut_bolt, Fit, IsoSize, ThreadOptions};
//! let nb = nut_bolt(IsoSize::M16, Fit::Tight, &ThreadOptions { segments_per_turn: 48, ..Default::default() })?;
//! assert!(nb.nut.mesh.topology().is_watertight());
//! assert_eq!(nb.pitch, 0.002);
//! // Radial gap between the flanks: -es/2 = 19 um at the tight end of 6H/6g.
//! assert!((nb.spec.radial_flank_clearance() - 19e-6).abs() < 1e-9);
//! # Ok::<(), factory_assets::AssetError>(())
//! ```

pub mod cli;
pub mod error;
pub mod fastener;
mod geom;
pub mod iso;
pub mod part;
pub mod peg_hole;
pub mod pile;

pub use error::{AssetError, Result};
pub use fastener::{
    bolt_closed_form_volume, bolt_tip_chamfer_height, bolt_tip_chamfer_volume, bolt_tip_radius, nut_bolt,
    nut_bolt_from_spec, nut_closed_form_volume, NutBolt, ThreadOptions, BOLT_SDF_RESOLUTION, NUT_SDF_RESOLUTION,
};
pub use iso::{FastenerDims, Fit, Iso965Row, IsoSize, ThreadProfile, ThreadSpec, STEEL_DENSITY};
pub use part::{Part, WrittenPart};
pub use peg_hole::{peg_hole, PegHole, PegHoleOptions, PegSize, INSERTION_DENSITY};
pub use pile::{
    bowl, torus, BowlOptions, RevolvedPart, TorusOptions, ABS_DENSITY, BOWL_SDF_RESOLUTION, TORUS_SDF_RESOLUTION,
};

//! Peg and hole meshes: closed and outward for every size and fit, dimensions, clearance in the zero
//! pose, and bounds against Factory's 4 mm meshes.

use factory_assets::{peg_hole, Fit, PegHoleOptions, PegSize, INSERTION_DENSITY};

#[test]
fn every_size_and_fit_is_watertight_and_outward() {
    for size in PegSize::ALL {
        for fit in Fit::ALL {
            let ph = peg_hole(size, fit, &PegHoleOptions::default()).unwrap();
            for part in [&ph.peg, &ph.hole] {
                let topo = part.mesh.topology();
                assert!(topo.is_watertight(), "{}: {topo:?}", part.name);
                assert!(part.mesh.signed_volume() > 0.0, "{} is inside out", part.name);
                assert_eq!(part.sdf_resolution, 256);
                assert_eq!(part.density, INSERTION_DENSITY);
            }
        }
    }
}

/// f32 storage of metre coordinates.
const POS_TOL: f32 = 1e-6;

#[test]
fn four_mm_bounds_match_factory_meshes() {
    // Factory: peg x,y +-0.001998 (tight) / +-0.001994 (loose), z 0..0.05, bottom ring r 0.001498 (0.5 mm
    // chamfer); hole block x,y +-0.0125, z 0..0.008992, bore r 0.00205 open at both faces.
    for (fit, r) in [(Fit::Tight, 0.001998f32), (Fit::Loose, 0.001994)] {
        let ph = peg_hole(PegSize::D4, fit, &PegHoleOptions::default()).unwrap();
        let (lo, hi) = ph.peg.mesh.aabb();
        assert!((hi.x - r).abs() < POS_TOL && (lo.y + r).abs() < POS_TOL, "{fit}: peg {lo} {hi}");
        assert!(lo.z.abs() < POS_TOL && (hi.z - 0.05).abs() < POS_TOL);
        let bottom_r =
            ph.peg.mesh.positions.iter().filter(|p| p.z == 0.0).map(|p| p.truncate().length()).fold(0.0, f32::max);
        assert!((bottom_r - (r - 0.0005)).abs() < POS_TOL, "{fit}: chamfer ring {bottom_r}");
        let (lo, hi) = ph.hole.mesh.aabb();
        assert!((hi.x - 0.0125).abs() < POS_TOL && (lo.y + 0.0125).abs() < POS_TOL, "hole {lo} {hi}");
        assert!(lo.z.abs() < POS_TOL && (hi.z - 0.008992).abs() < 1e-6, "hole {lo} {hi}");
        // Through hole: both faces have a ring at the bore radius and nothing inside it.
        for z in [0.0f32, hi.z] {
            let inner = ph
                .hole
                .mesh
                .positions
                .iter()
                .filter(|p| p.z == z)
                .map(|p| p.truncate().length())
                .fold(f32::MAX, f32::min);
            assert!((inner - 0.00205).abs() < POS_TOL, "bore ring at z {z}: {inner}");
        }
    }
}

/// Volume error of the inscribed N-gon at N = 128: (2 pi/N)^2/6 = 4e-4 of the circle's area, plus the
/// exact chamfer cones.
const VOLUME_REL_TOL: f64 = 1e-3;

#[test]
fn volumes_and_clearance() {
    for size in PegSize::ALL {
        for fit in Fit::ALL {
            let ph = peg_hole(size, fit, &PegHoleOptions::default()).unwrap();
            let (rp, rh) = (0.5 * ph.peg_diameter as f64, 0.5 * ph.hole_diameter as f64);
            let c = 0.0005;
            let pi = std::f64::consts::PI;
            // Cylinder minus two chamfer rings (frustum deficit pi c (r^2 - ... )): exact solid of revolution.
            let frustum = pi * c / 3.0 * (rp * rp + rp * (rp - c) + (rp - c) * (rp - c));
            let peg = pi * rp * rp * (0.05 - 2.0 * c) + 2.0 * frustum;
            let hole = (0.025 * 0.025 - pi * rh * rh) * 0.0089916;
            for (part, want) in [(&ph.peg, peg), (&ph.hole, hole)] {
                let v = part.mass_properties.volume as f64;
                assert!((v - want).abs() / want < VOLUME_REL_TOL, "{}: {v} vs {want}", part.name);
            }
            assert!((ph.clearance - (ph.hole_diameter - ph.peg_diameter)).abs() < 1e-9);
            // Radial gap in the zero pose between peg vertices and the bore: the peg's largest radius
            // inside the block is its radius, the bore's smallest is the hole's (inscribed chords aside).
            let peg_max =
                ph.peg.mesh.positions.iter().filter(|p| p.z < 0.009).map(|p| p.truncate().length()).fold(0.0, f32::max);
            let bore_min = ph.hole.mesh.positions.iter().map(|p| p.truncate().length()).fold(f32::MAX, f32::min);
            let gap = (bore_min - peg_max) as f64;
            assert!((gap - 0.5 * ph.clearance as f64).abs() < 1e-6, "{}: gap {gap}", ph.peg.name);
        }
    }
}

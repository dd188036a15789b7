//! Written parts load back through the engine's URDF loader with their mass properties, SDF resolution
//! and an identical collision mesh.

use factory_assets::{nut_bolt, peg_hole, Fit, IsoSize, Part, PegHoleOptions, PegSize, ThreadOptions};
use factory_engine::urdf::{load_collision_mesh, load_urdf};

/// Relative tolerance for values printed with 10 significant digits and stored as f32.
const REL: f32 = 1e-6;

fn check(part: &Part, dir: &std::path::Path) {
    let files = part.write(dir).unwrap();
    let model = load_urdf(&files.urdf).unwrap();
    let link = model.link(&part.name).expect("link named after the part");
    let inertial = link.inertial.expect("inertial");
    let mp = &part.mass_properties;
    assert!((inertial.mass - mp.mass).abs() <= REL * mp.mass, "{}: mass {} vs {}", part.name, inertial.mass, mp.mass);
    assert!((inertial.origin.translation - mp.com).length() <= REL * mp.com.length().max(1e-3));
    let scale = mp.inertia.z_axis.z;
    for c in 0..3 {
        let d = (inertial.inertia.col(c) - mp.inertia.col(c)).abs().max_element();
        assert!(d <= REL * scale, "{}: inertia column {c} differs by {d}", part.name);
    }
    assert_eq!(link.collisions.len(), 1);
    assert_eq!(link.collisions[0].sdf_resolution, Some(part.sdf_resolution));
    let mesh = load_collision_mesh(&link.collisions[0]).unwrap();
    assert_eq!(mesh.triangles, part.mesh.triangles);
    // OBJ stores 10 significant digits: positions agree to well under a nanometre.
    let err = mesh.positions.iter().zip(&part.mesh.positions).map(|(a, b)| (*a - *b).length()).fold(0.0, f32::max);
    assert!(err < 1e-9, "{}: position error {err}", part.name);
}

#[test]
fn parts_round_trip_through_the_engine_loader() {
    let dir = std::env::temp_dir().join(format!("factory-assets-urdf-{}", std::process::id()));
    let nb =
        nut_bolt(IsoSize::M12, Fit::Tight, &ThreadOptions { segments_per_turn: 96, ..Default::default() }).unwrap();
    let ph = peg_hole(PegSize::D8, Fit::Loose, &PegHoleOptions::default()).unwrap();
    for part in [&nb.nut, &nb.bolt, &ph.peg, &ph.hole] {
        check(part, &dir);
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

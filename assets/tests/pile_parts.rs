//! Bowls and toruses (pile scenes): watertight outward meshes whose vertices lie on the exact field, sizes
//! and counts, mass properties against closed forms, and refused options.

use factory_assets::{bowl, torus, BowlOptions, RevolvedPart, TorusOptions, ABS_DENSITY};
use glam::{DVec2, Vec3};
use std::f64::consts::{PI, TAU};

/// Every vertex on the field's zero set; facet centres off it by at most the sagitta of the widest column
/// chord; the mesh outward (the field grows along every facet's normal); watertight.
fn check_mesh_on_field(p: &RevolvedPart, segments: usize) {
    let (mesh, f) = (&p.part.mesh, &p.sdf);
    let topo = mesh.topology();
    assert!(topo.is_watertight(), "{}: {topo:?}", p.part.name);
    assert!(mesh.signed_volume() > 0.0, "{} is inside out", p.part.name);
    let worst = mesh.positions.iter().map(|&v| f.sample(v).0.abs()).fold(0.0f32, f32::max);
    assert!(worst < 1e-6, "{}: a vertex is {worst} m off the field's surface", p.part.name);
    let rho_max = f.profile.iter().map(|v| v.x).fold(0.0f32, f32::max);
    let sagitta = rho_max * (1.0 - (std::f32::consts::PI / segments as f32).cos());
    let delta = 3e-4;
    for t in 0..mesh.triangle_count() {
        let [a, b, c] = mesh.triangle(t);
        let centre = (a + b + c) / 3.0;
        let d = f.sample(centre).0;
        // Inside on convex columns, outside on concave ones (a torus's hole, a bowl's inner wall).
        assert!(d.abs() <= sagitta + 1e-6, "{}: facet {t} centre at {d} m (sagitta {sagitta})", p.part.name);
        let n = (b - a).cross(c - a).normalize();
        let (out, inn) = (f.sample(centre + n * delta).0, f.sample(centre - n * delta).0);
        assert!(out > inn, "{}: facet {t} faces inwards ({inn} -> {out})", p.part.name);
    }
}

/// Integral of rho^a z^b over the profile polygon (closed; an on-axis profile's closing edge on the axis
/// adds nothing for a >= 0), by Green's theorem: the integral of rho^(a+1) z^b / (a+1) dz around the
/// boundary, exact with 3-point Gauss-Legendre for a + b <= 4.
fn moment(profile: &[DVec2], a: i32, b: i32) -> f64 {
    let (w, x) = ([5.0 / 9.0, 8.0 / 9.0, 5.0 / 9.0], [-(0.6f64).sqrt(), 0.0, (0.6f64).sqrt()]);
    let n = profile.len();
    (0..n)
        .map(|i| {
            let (p, q) = (profile[i], profile[(i + 1) % n]);
            let e = q - p;
            (0..3)
                .map(|k| {
                    let s = p + e * (0.5 + 0.5 * x[k]);
                    0.5 * w[k] * s.x.powi(a + 1) / (a + 1) as f64 * s.y.powi(b) * e.y
                })
                .sum::<f64>()
        })
        .sum()
}

/// Mass, centre height, and inertia about the axis and about a horizontal axis through the centre of mass
/// of the profile revolved with `n` planar-quad columns at `density`: the solid is s (cos, sin) blends of
/// neighbouring columns, whose volume element is s sin(2 pi / n) ds dz dt, and the blend's squared
/// length integrates to (2 + cos(2 pi / n)) / 3 over a column.
fn faceted_mass_properties(profile: &[DVec2], n: usize, density: f64) -> (f64, f64, f64, f64) {
    let beta = TAU / n as f64;
    let k = n as f64 * beta.sin();
    let blend = (2.0 + beta.cos()) / 3.0;
    let mass = density * k * moment(profile, 1, 0);
    let zc = moment(profile, 1, 1) / moment(profile, 1, 0);
    let izz = density * k * blend * moment(profile, 3, 0);
    let ixx_origin = density * k * (0.5 * blend * moment(profile, 3, 0) + moment(profile, 1, 2));
    (mass, zc, izz, ixx_origin - mass * zc * zc)
}

fn check_mass_properties(p: &RevolvedPart, segments: usize) {
    let profile: Vec<DVec2> = p.sdf.profile.iter().map(|v| v.as_dvec2()).collect();
    let (mass, zc, izz, ixx) = faceted_mass_properties(&profile, segments, p.part.density as f64);
    let mp = &p.part.mass_properties;
    let rel = |a: f32, b: f64| (a as f64 - b).abs() / b.abs();
    assert!(rel(mp.mass, mass) < 1e-5, "{}: mass {} vs {mass}", p.part.name, mp.mass);
    assert!((mp.com - Vec3::new(0.0, 0.0, zc as f32)).length() < 1e-7, "{}: com {} vs {zc}", p.part.name, mp.com);
    let i = mp.inertia;
    assert!(rel(i.z_axis.z, izz) < 1e-4, "{}: Izz {} vs {izz}", p.part.name, i.z_axis.z);
    assert!(rel(i.x_axis.x, ixx) < 1e-4 && rel(i.y_axis.y, ixx) < 1e-4, "{}: Ixx {i} vs {ixx}", p.part.name);
    let off = [i.x_axis.y, i.x_axis.z, i.y_axis.z].map(f32::abs).into_iter().fold(0.0, f32::max);
    assert!(off < 1e-6 * izz as f32, "{}: products of inertia {i}", p.part.name);
}

#[test]
fn default_torus_sizes_counts_and_field() {
    let t = torus(&TorusOptions::default()).unwrap();
    assert_eq!(t.part.name, "torus_48mm");
    // Table VI: 1024 vertices.
    assert_eq!((t.part.mesh.positions.len(), t.part.mesh.triangle_count()), (1024, 2048));
    assert!(t.sdf.is_ring() && t.sdf.profile.len() == 16);
    let (lo, hi) = t.part.mesh.aabb();
    assert!((hi - Vec3::new(0.024, 0.024, 0.008)).abs().max_element() < 1e-7, "{hi}");
    assert!((lo + Vec3::new(0.024, 0.024, 0.008)).abs().max_element() < 1e-7, "{lo}");
    assert_eq!(t.part.density, ABS_DENSITY);
    check_mesh_on_field(&t, 64);
    // The hole is outside, the tube's centre circle inside by the section's apothem.
    let apothem = 0.008 * (PI / 16.0).cos() as f32;
    assert!((t.sdf.sample(Vec3::ZERO).0 - 0.008).abs() < 1e-7);
    let (d, g) = t.sdf.sample(Vec3::new(-0.016, 0.0, 0.0));
    assert!((d + apothem).abs() < 1e-7, "{d}");
    assert!((g.length() - 1.0).abs() < 1e-5);
    eprintln!("default torus: {:?}", t.part.mass_properties);
}

#[test]
fn torus_mass_properties_match_closed_forms() {
    for opts in [
        TorusOptions::default(),
        TorusOptions { tube_sides: 8, segments: 100, ring_radius: 0.03, tube_radius: 0.005, density: 2400.0 },
    ] {
        let t = torus(&opts).unwrap();
        check_mass_properties(&t, opts.segments);
        // The regular n-gon section (area A = n/2 r^2 sin(2 pi/n), centroid at R, polar moment
        // A r^2 (2 + cos(2 pi/n)) / 6) revolved with N planar-quad columns: V = N sin(2 pi/N) R A
        // (Pappus' 2 pi R A as N grows, the smooth torus's 2 pi^2 R r^2 as n grows too).
        let (big_r, r, n) = (opts.ring_radius, opts.tube_radius, opts.tube_sides as f64);
        let (alpha, beta) = (TAU / n, TAU / opts.segments as f64);
        let area = 0.5 * n * r * r * alpha.sin();
        let k = opts.segments as f64 * beta.sin();
        let rho = opts.density as f64;
        let mass = rho * k * big_r * area;
        let u2 = area * r * r * (2.0 + alpha.cos()) / 12.0; // integral of (rho - R)^2 (= of z^2) over the section
        let izz = rho * k * (2.0 + beta.cos()) / 3.0 * (big_r.powi(3) * area + 3.0 * big_r * u2);
        let ixx = rho * k * ((2.0 + beta.cos()) / 6.0 * (big_r.powi(3) * area + 3.0 * big_r * u2) + big_r * u2);
        let mp = &t.part.mass_properties;
        assert!((mp.mass as f64 - mass).abs() / mass < 1e-5, "{} vs {mass}", mp.mass);
        assert!((mp.inertia.z_axis.z as f64 - izz).abs() / izz < 1e-4);
        assert!((mp.inertia.x_axis.x as f64 - ixx).abs() / ixx < 1e-4);
        // Against the smooth torus: m = 2 pi^2 R r^2 rho, Izz = m (R^2 + 3 r^2 / 4), Ixx = m (R^2 / 2 + 5 r^2 / 8),
        // short by the two faceting factors.
        let (fn_, fbeta) = (n * alpha.sin() / TAU, k / TAU);
        let smooth = 2.0 * PI * PI * big_r * r * r * rho;
        assert!((mp.mass as f64 / (smooth * fn_ * fbeta) - 1.0).abs() < 1e-5);
        let smooth_izz = smooth * (big_r * big_r + 0.75 * r * r);
        let smooth_ixx = smooth * (0.5 * big_r * big_r + 0.625 * r * r);
        for (got, want) in [(mp.inertia.z_axis.z as f64, smooth_izz), (mp.inertia.x_axis.x as f64, smooth_ixx)] {
            let short = 1.0 - got / want;
            assert!(short > 0.0 && short < 1.5 * (1.0 - fn_ * fbeta), "{got} vs smooth {want}");
        }
    }
}

#[test]
fn default_bowl_sizes_counts_and_field() {
    let b = bowl(&BowlOptions::default()).unwrap();
    assert_eq!(b.part.name, "bowl_100mm");
    // 14 rings of 40 and two poles; Table VI: 582 / 1160.
    assert_eq!((b.part.mesh.positions.len(), b.part.mesh.triangle_count()), (562, 1120));
    assert!(!b.sdf.is_ring() && b.sdf.profile.len() == 16);
    let (lo, hi) = b.part.mesh.aabb();
    assert!((hi - Vec3::new(0.05, 0.05, 0.028)).abs().max_element() < 1e-7, "{hi}");
    assert!((lo - Vec3::new(-0.05, -0.05, 0.0)).abs().max_element() < 1e-7, "{lo}");
    check_mesh_on_field(&b, 40);
    // The cavity is outside: on the axis above the inner bottom (z = 3 mm) and above the rim.
    assert!((b.sdf.sample(Vec3::new(0.0, 0.0, 0.015)).0 - 0.012).abs() < 1e-7);
    assert!((b.sdf.sample(Vec3::new(0.0, 0.0, 0.0015)).0 + 0.0015).abs() < 1e-7, "inside the floor");
    // Through the wall along the arc's radius (centre (20 mm, 30.07 mm)): 3 mm thick, less the chords' cos.
    let rw = (0.03f64 * 0.03 + 0.028 * 0.028) / (2.0 * 0.028);
    let centre = DVec2::new(0.02, rw);
    let sweep = (0.028f64 - rw).atan2(0.03) + PI / 2.0;
    let mut thinnest = f64::INFINITY;
    // Rays from the arc's centre up to the inner rim corner (beyond it they leave through the flat rim).
    let rim_in = b.sdf.profile[8].as_dvec2() - centre;
    let last = rim_in.y.atan2(rim_in.x);
    assert!(last < -PI / 2.0 + sweep);
    for k in 1..200 {
        let a = -PI / 2.0 + (last + PI / 2.0) * k as f64 / 200.0;
        let dir = DVec2::new(a.cos(), a.sin());
        let inside = (0..=3000)
            .filter(|&j| {
                let q = centre + dir * (rw - 0.0035 + 4e-6 * j as f64);
                b.sdf.sample(Vec3::new(q.x as f32, 0.0, q.y as f32)).0 < 0.0
            })
            .count() as f64
            * 4e-6;
        thinnest = thinnest.min(inside);
        assert!(inside < 0.003 + 8e-6, "wall at {a} rad: {inside} m thick");
    }
    // Six chords over the sweep: thickness x cos(sweep / 12) between parallel chords.
    let chord = 0.003 * (sweep / 12.0).cos();
    assert!((thinnest - chord).abs() < 8e-6, "thinnest wall {thinnest} m vs {chord}");
    eprintln!("default bowl: {:?}", b.part.mass_properties);
}

#[test]
fn bowl_mass_properties_match_the_profile_integrals() {
    for opts in [
        BowlOptions::default(),
        BowlOptions { wall_facets: 2, segments: 97, thickness: 0.001, density: 2400.0, ..Default::default() },
        BowlOptions { rim_radius: 0.08, height: 0.05, base_radius: 0.03, thickness: 0.005, ..Default::default() },
    ] {
        let b = bowl(&opts).unwrap();
        assert_eq!(b.sdf.profile.len(), 2 * opts.wall_facets + 4);
        check_mesh_on_field(&b, opts.segments);
        check_mass_properties(&b, opts.segments);
    }
    // Against the smooth shell in closed form: the foot's disk pi b^2 t plus Pappus on the annular sector
    // between radii rw - t and rw about the arc's centre (b, rw), from the bottom (-pi/2) to the rim's
    // angle: 2 pi (b A + (rw^3 - (rw - t)^3) / 3 (1 + sin end)), A = sweep (rw^2 - (rw - t)^2) / 2.
    // The part is short of it by the angular facets (N sin(2 pi / N) / 2 pi, taken out), the wall's chords
    // (a polygonal annulus is sin(step) / step of the sector: step^2 / 6 = 1.0% of the wall at 6 chords) and
    // the flat rim's corner (measured 1.4% in all).
    let b = bowl(&BowlOptions::default()).unwrap();
    let (t, base) = (0.003f64, 0.02f64);
    let rw = (0.03f64 * 0.03 + 0.028 * 0.028) / (2.0 * 0.028);
    let end = (0.028f64 - rw).atan2(0.03);
    let sweep = end + PI / 2.0;
    let area = 0.5 * sweep * (rw * rw - (rw - t) * (rw - t));
    let smooth = PI * base * base * t + TAU * (base * area + (rw.powi(3) - (rw - t).powi(3)) / 3.0 * (1.0 + end.sin()));
    let facets = 40.0 * (TAU / 40.0).sin() / TAU;
    let v = b.part.mass_properties.volume as f64;
    let short = 1.0 - v / (smooth * facets);
    assert!(short > 0.0 && short < 0.02, "{v} vs smooth {smooth} x facets {facets}");
}

#[test]
fn bad_options_name_the_field_and_its_range() {
    let cases: Vec<(String, &str)> = vec![
        (torus(&TorusOptions { tube_radius: 0.02, ..Default::default() }).unwrap_err().to_string(), "tube radius"),
        (torus(&TorusOptions { ring_radius: f64::NAN, ..Default::default() }).unwrap_err().to_string(), "ring radius"),
        (torus(&TorusOptions { tube_sides: 18, ..Default::default() }).unwrap_err().to_string(), "tube sides"),
        (torus(&TorusOptions { tube_sides: 6, ..Default::default() }).unwrap_err().to_string(), "multiple of 4"),
        (torus(&TorusOptions { segments: 4, ..Default::default() }).unwrap_err().to_string(), "segments"),
        (torus(&TorusOptions { density: 0.0, ..Default::default() }).unwrap_err().to_string(), "density"),
        (bowl(&BowlOptions { height: 0.06, ..Default::default() }).unwrap_err().to_string(), "height"),
        (bowl(&BowlOptions { base_radius: 0.025, ..Default::default() }).unwrap_err().to_string(), "curl"),
        (bowl(&BowlOptions { thickness: 0.01, ..Default::default() }).unwrap_err().to_string(), "thickness"),
        (bowl(&BowlOptions { thickness: -0.001, ..Default::default() }).unwrap_err().to_string(), "more than 0"),
        (bowl(&BowlOptions { wall_facets: 7, ..Default::default() }).unwrap_err().to_string(), "1 to 6"),
        (bowl(&BowlOptions { segments: 5000, ..Default::default() }).unwrap_err().to_string(), "8 to 4096"),
        (bowl(&BowlOptions { rim_radius: 0.0, ..Default::default() }).unwrap_err().to_string(), "rim radius"),
    ];
    for (msg, want) in cases {
        assert!(msg.starts_with("invalid ") && msg.contains(want), "{msg:?} should name {want:?}");
    }
    let e = bowl(&BowlOptions { base_radius: 0.025, ..Default::default() }).unwrap_err().to_string();
    assert_eq!(
        e,
        "invalid base radius = 0.025 m: more than 0 and at most rim radius - height (0.022 m), so the \
         wall does not curl inwards"
    );
}

#[test]
fn parts_write_obj_and_urdf() {
    let dir = std::env::temp_dir().join(format!("factory-assets-pile-{}", std::process::id()));
    for p in [torus(&TorusOptions::default()).unwrap(), bowl(&BowlOptions::default()).unwrap()] {
        let files = p.part.write(&dir).unwrap();
        let urdf = std::fs::read_to_string(&files.urdf).unwrap();
        assert!(urdf.contains(&format!("<sdf resolution=\"{}\"/>", p.part.sdf_resolution)));
        let mesh = factory_engine::mesh::TriMesh::load_obj(&files.obj).unwrap();
        assert_eq!(mesh.triangle_count(), p.part.mesh.triangle_count());
        assert!(mesh.topology().is_watertight());
    }
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn cli_writes_a_bowl_and_a_torus() {
    let dir = std::env::temp_dir().join(format!("factory-assets-pile-cli-{}", std::process::id()));
    for (cmd, name) in [("bowl", "bowl_100mm"), ("torus", "torus_48mm")] {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_factory-assets"))
            .args([cmd, "--segments", "32", "--out"])
            .arg(&dir)
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        assert!(dir.join(format!("{name}.obj")).is_file() && dir.join(format!("{name}.urdf")).is_file());
    }
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_factory-assets"))
        .args(["torus", "--segments", "3", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("invalid segments = 3: 8 to 4096"));
    std::fs::remove_dir_all(dir).ok();
}

//! Contact generation and reduction on our generated ISO M16 nut and bolt (GPU on lavapipe in CI, with
//! the CPU twin as the unreduced reference).

use factory_assets::{nut_bolt, Fit, IsoSize, NutBolt, ThreadOptions};
use factory_bench::contact_scene::{lower_until_touch, ContactScene, PartPair};
use factory_engine::contact::generate::{triangle_candidate_cpu, Xf};
use factory_engine::contact::{ContactConfig, ContactPipeline};
use factory_engine::gpu::GpuContext;
use factory_engine::sdf::cache::SdfCache;
use glam::{Vec3, Vec4Swizzles};

/// The paper's target (III-C): M4/M16 nut-bolt from ~16k candidates to ~300 contacts.
const MAX_REDUCED_CONTACTS: usize = 300;
/// The issue asks for the M16 pair to start from over 10k candidates.
const MIN_CANDIDATES: u32 = 10_000;
/// Reduction may move the penetration-weighted mean normal by at most this [deg].
const MEAN_NORMAL_TOL_DEG: f32 = 2.0;
/// Touching contacts must lie within this of the ISO 68-1 load-bearing flank normal [deg].
const FLANK_NORMAL_TOL_DEG: f32 = 5.0;
/// Contact offset for these tests [m]: half a pitch, so both flanks of every tooth are candidates.
const OFFSET: f32 = 1.0e-3;

fn parts() -> NutBolt {
    nut_bolt(IsoSize::M16, Fit::Tight, &ThreadOptions::default()).unwrap()
}

fn scene(nb: &NutBolt, sdf_res: u32) -> ContactScene {
    let pair = PartPair {
        name: "M16".into(),
        a: nb.nut.mesh.clone(),
        b: nb.bolt.mesh.clone(),
        pitch: nb.pitch,
        side_shift: 0.0,
    };
    ContactScene::new(pair, sdf_res, OFFSET, &SdfCache::new(SdfCache::default_dir())).unwrap()
}

#[test]
fn m16_reduction_from_over_10k_candidates_to_at_most_300_contacts() {
    let nb = parts();
    let sc = scene(&nb, 256);
    assert_eq!(sc.sdf_part, 1, "the bolt has more triangles, so it provides the SDF (Factory's rule)");
    let gpu = GpuContext::global().unwrap();
    let phases = [0.0, 1.0, 2.5, 4.0];
    let pipe = ContactPipeline::new(gpu, &sc.model, phases.len() as u32, &ContactConfig::default()).unwrap();
    pipe.write_body_q(gpu, &sc.poses(5.0 * nb.pitch, &phases));
    pipe.run(gpu);
    let out = pipe.read(gpu);
    for w in 0..phases.len() {
        let contacts = out.contact_count(w);
        assert!(out.candidates[w] > MIN_CANDIDATES, "world {w}: {} candidates", out.candidates[w]);
        assert!(contacts <= MAX_REDUCED_CONTACTS && contacts > 0, "world {w}: {contacts} contacts");
    }
}

/// Unreduced candidates of the nut (body 0) against the bolt SDF, from the CPU twin, in the bolt frame
/// (= world: the bolt sits at the origin).
fn unreduced(sc: &ContactScene, pipe: &ContactPipeline, nut: Xf) -> Vec<(Vec3, f32)> {
    let pair = &pipe.flat.pairs[0];
    let tris = &sc.pair.a;
    (0..tris.triangle_count())
        .map(|t| {
            let [a, b, c] = tris.triangle(t).map(|v| nut.point(v));
            triangle_candidate_cpu(pair, &pipe.flat.sdf_values, a, b, c, pipe.cfg.iterations)
        })
        .filter(|c| c.pd.w < 1e38)
        .map(|c| (c.n.xyz(), c.pd.w))
        .collect()
}

#[test]
fn m16_reduction_keeps_the_penetration_weighted_mean_normal() {
    let nb = parts();
    let sc = scene(&nb, 256);
    let gpu = GpuContext::global().unwrap();
    let pipe = ContactPipeline::new(gpu, &sc.model, 1, &ContactConfig::default()).unwrap();
    // Pushed 30 um below the centre of its axial play: the load-bearing flanks carry the penetration.
    let poses = sc.poses(5.0 * nb.pitch - 30e-6, &[0.0]);
    pipe.write_body_q(gpu, &poses);
    pipe.run(gpu);
    let reduced = pipe.read(gpu);
    let full = unreduced(&sc, &pipe, poses[0].xf());
    let weighted =
        |it: &mut dyn Iterator<Item = (Vec3, f32)>| it.fold(Vec3::ZERO, |acc, (n, d)| acc + n * (-d).max(0.0));
    let m_full = weighted(&mut full.iter().copied());
    let m_red =
        weighted(&mut reduced.patches[0].iter().flat_map(|p| p.contacts.iter().map(move |c| (p.normal, c.depth))));
    assert!(m_full.length() > 0.0 && m_red.length() > 0.0, "penetrating contacts exist");
    let angle = m_full.normalize().dot(m_red.normalize()).clamp(-1.0, 1.0).acos().to_degrees();
    assert!(angle <= MEAN_NORMAL_TOL_DEG, "mean normal moved {angle} deg ({m_full} vs {m_red})");
    // And it points up the axis: the nut rests on the thread.
    assert!(m_full.normalize().z > 0.95, "{m_full}");
}

/// ISO 68-1 load-bearing flank normal of the bolt at `p`: 30 degrees from the axis, tilted against the
/// helix by the local lead angle (right-hand thread): n ~ z + tan(30) r - P / (2 pi r) t.
fn flank_normal(p: Vec3, pitch: f32) -> Vec3 {
    let r = Vec3::new(p.x, p.y, 0.0);
    let rl = r.length();
    let radial = r / rl;
    let tangential = Vec3::Z.cross(radial);
    (Vec3::Z + 30f32.to_radians().tan() * radial - pitch / (std::f32::consts::TAU * rl) * tangential).normalize()
}

#[test]
#[ignore = "known failure: at SDF resolutions 256 and 512 trilinear interpolation across the bolt's root \
            corners under-estimates the distance by 13-31 um, more than the 19 um tight clearance, so the \
            first touch is at the nut's crest (normals ~60 deg from the axis), not on the flanks; needs an \
            exact (analytic or finer narrow-band) thread SDF"]
fn m16_nut_lowered_until_touch_contacts_the_load_bearing_flanks() {
    let nb = parts();
    let sc = scene(&nb, 512);
    let gpu = GpuContext::global().unwrap();
    let p = nb.pitch;
    let lift = lower_until_touch(gpu, &sc, 5.0 * p, 5.0 * p - 0.1e-3, 0.5e-6).unwrap();
    let pipe = ContactPipeline::new(gpu, &sc.model, 1, &ContactConfig::default()).unwrap();
    pipe.write_body_q(gpu, &sc.poses(lift, &[0.0]));
    pipe.run(gpu);
    let out = pipe.read(gpu);
    // Contacts within 2 um of touching are the ones that would carry the load.
    let touching: Vec<_> = out.patches[0]
        .iter()
        .flat_map(|pa| pa.contacts.iter().map(move |c| (pa.normal, c.point, c.depth)))
        .filter(|c| c.2 < 2e-6)
        .collect();
    assert!(touching.len() >= 10, "{} touching contacts", touching.len());
    for (n, point, _) in touching {
        let angle = n.dot(flank_normal(point, p)).clamp(-1.0, 1.0).acos().to_degrees();
        assert!(angle <= FLANK_NORMAL_TOL_DEG, "normal {n} at {point} is {angle} deg off the flank normal");
    }
}

//! `factory-bench contacts`: contact generation + reduction for N parallel copies of a shape pair (paper
//! Table I), timed over whole frames on the device and optionally on the CPU twin.

use super::summary::yes_no;
use super::Summary;
use crate::contact_scene::{min_depth, ContactScene, PartPair};
use anyhow::{anyhow, bail, Context, Result};
use clap::ValueEnum;
use factory_assets::{nut_bolt, peg_hole, Fit, IsoSize, PegHoleOptions, PegSize, ThreadOptions};
use factory_engine::contact::{ContactConfig, ContactPipeline};
use factory_engine::gpu::GpuContext;
use factory_engine::mesh::TriMesh;
use factory_engine::sdf::cache::SdfCache;
use factory_engine::sdf::thread::ThreadSdf;
use serde_json::Value;
use std::path::PathBuf;
use std::time::Instant;

/// `--pair`.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum PairKind {
    /// Our generated ISO hex nut on its bolt.
    NutBolt,
    /// Our generated round peg in its hole.
    PegHole,
}

/// `--sdf`.
#[derive(Clone, Copy, Debug, PartialEq, ValueEnum)]
pub enum SdfKind {
    Grid,
    Analytic,
}

#[derive(clap::Args)]
pub struct ContactsArgs {
    /// Which generated pair (ignored with --mesh-a/--mesh-b).
    #[arg(long, value_enum, default_value = "nut-bolt")]
    pair: PairKind,
    /// Nut-bolt size (M4, M8, M12, M16, M20) or peg diameter in mm (4, 8, 12, 16).
    #[arg(long, default_value = "M16")]
    size: String,
    /// Tolerance end: tight or loose.
    #[arg(long, default_value = "tight")]
    fit: String,
    /// Parallel worlds, one pair each.
    #[arg(long, default_value_t = 1)]
    worlds: u32,
    /// Moving part (e.g. Factory's nut) as OBJ, in the assembled pose; needs --mesh-b.
    #[arg(long, requires = "mesh_b")]
    mesh_a: Option<PathBuf>,
    /// Fixed part (e.g. Factory's bolt) as OBJ, in the assembled pose; needs --mesh-a.
    #[arg(long, requires = "mesh_a")]
    mesh_b: Option<PathBuf>,
    /// Thread pitch of the mesh pair [mm] (0 for unthreaded pairs).
    #[arg(long, default_value_t = 2.0)]
    pitch_mm: f32,
    /// SDF resolution: samples along the SDF part's longest axis (grid SDFs).
    #[arg(long, default_value_t = 256)]
    sdf_res: u32,
    /// SDF of the bolt: `grid` (baked from the mesh, as Factory) or `analytic` (exact thread field;
    /// generated nut-bolt pairs only).
    #[arg(long, value_enum, default_value = "grid")]
    sdf: SdfKind,
    /// Patch budget per pair (16..=256).
    #[arg(long, default_value_t = 64)]
    patches: u32,
    /// Candidates whose normals are within this angle of a patch's normal join it [deg].
    #[arg(long, default_value_t = 10.0)]
    normal_deg: f32,
    /// Invocations per contact workgroup (32, 64, 128, 256).
    #[arg(long, default_value_t = 64)]
    workgroup: u32,
    /// Candidates per invocation (1, 2 or 4; at most 256 per workgroup; ContactConfig::candidates_per_invocation).
    #[arg(long, default_value_t = 1)]
    per: u32,
    /// Run an invocation's four query triangles one after another instead of side by side
    /// (ContactConfig::interleaved_descent; the same results, for comparing speed).
    #[arg(long)]
    sequential_descent: bool,
    /// Projected-gradient iterations per query triangle.
    #[arg(long, default_value_t = 12)]
    descent_iters: u32,
    /// Thread columns per turn of the generated nut and bolt meshes (multiple of 12, >= 24).
    #[arg(long, default_value_t = 192)]
    segments_per_turn: usize,
    /// Contact offset [mm]: candidates farther than this are dropped.
    #[arg(long, default_value_t = 1.0)]
    offset_mm: f32,
    /// Frames to time (after one warm-up frame).
    #[arg(long, default_value_t = 30)]
    frames: u32,
    /// Also time the plain-Rust twin (all cores) on the same input.
    #[arg(long)]
    cpu: bool,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// The pair the arguments name: two OBJ files, or a generated nut-bolt (with its exact thread field) or
/// peg-hole.
fn part_pair(a: &ContactsArgs) -> Result<(PartPair, Option<ThreadSdf>)> {
    let fit: Fit = a.fit.parse().map_err(|e| anyhow!("--fit: {e}"))?;
    if let (Some(ma), Some(mb)) = (&a.mesh_a, &a.mesh_b) {
        let pair = PartPair {
            name: format!("{} / {}", ma.display(), mb.display()),
            a: TriMesh::load_obj(ma)?,
            b: TriMesh::load_obj(mb)?,
            pitch: a.pitch_mm * 1e-3,
            side_shift: 0.0,
        };
        return Ok((pair, None));
    }
    Ok(match a.pair {
        PairKind::NutBolt => {
            let s: IsoSize = a.size.parse().map_err(|e| anyhow!("--size: {e}"))?;
            let opts = ThreadOptions { segments_per_turn: a.segments_per_turn, ..Default::default() };
            let nb = nut_bolt(s, fit, &opts)?;
            (PartPair::nut_bolt(&nb), Some(nb.bolt_sdf()))
        }
        PairKind::PegHole => {
            let s: PegSize = a.size.parse().map_err(|e| anyhow!("--size: {e}"))?;
            let ph = peg_hole(s, fit, &PegHoleOptions::default())?;
            let pair = PartPair {
                name: format!("peg-hole {}mm {}", s.nominal_mm(), fit.name()),
                a: ph.peg.mesh,
                b: ph.hole.mesh,
                pitch: 0.0,
                side_shift: 0.5 * ph.clearance,
            };
            (pair, None)
        }
    })
}

/// Builds the pair, times its contact handling and prints the report.
pub fn run(a: &ContactsArgs) -> Result<()> {
    let (parts, thread_sdf) = part_pair(a)?;
    let cache = SdfCache::new(SdfCache::default_dir());
    let t_bake = Instant::now();
    let scene = match (a.sdf, thread_sdf) {
        (SdfKind::Grid, _) => {
            ContactScene::new(parts, a.sdf_res, a.offset_mm * 1e-3, &cache).context("building the contact scene")?
        }
        (SdfKind::Analytic, Some(t)) => ContactScene::with_thread_sdf(parts, t, a.offset_mm * 1e-3),
        (SdfKind::Analytic, None) => {
            bail!("--sdf analytic needs a generated nut-bolt pair (--pair nut-bolt without --mesh-a/--mesh-b)")
        }
    };
    let bake_s = t_bake.elapsed().as_secs_f64();
    let report = measure(a, &scene, bake_s)?;
    if a.json {
        println!("{report}");
    } else {
        print!("{}", summary(&report));
    }
    Ok(())
}

/// One warm-up frame, then `a.frames` frames timed in one submission (and the CPU twin with `--cpu`): the
/// report's JSON object.
fn measure(a: &ContactsArgs, scene: &ContactScene, bake_s: f64) -> Result<Value> {
    let gpu = GpuContext::global()?;
    let (worlds, frames) = (a.worlds, a.frames);
    // Threaded pairs: the nut raised by 5 whole pitches (threads in phase, centred in their axial
    // play, as the peers' scene); other pairs: the assembled pose, the peg against one side.
    let lift = 5.0 * scene.pair.pitch;
    // Each world gets its own turn of the nut (threads kept in phase), so worlds differ.
    let phases: Vec<f32> = (0..worlds).map(|w| (w as f32 * 2.399963) % std::f32::consts::TAU).collect();
    let poses = scene.poses(lift, &phases);
    let cfg = ContactConfig {
        max_patches: a.patches,
        normal_cos: a.normal_deg.to_radians().cos(),
        workgroup_size: a.workgroup,
        candidates_per_invocation: a.per,
        interleaved_descent: !a.sequential_descent,
        iterations: a.descent_iters,
        ..Default::default()
    };
    let pipe = ContactPipeline::new(gpu, &scene.model, worlds, &cfg)?;
    pipe.write_body_q(gpu, &poses);
    pipe.run(gpu);
    let out = pipe.read(gpu);
    let t = Instant::now();
    let cpu0 = process_cpu_ns();
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    for _ in 0..frames {
        pipe.encode(&mut enc);
    }
    gpu.queue.submit([enc.finish()]);
    gpu.wait();
    let handling_ms = t.elapsed().as_secs_f64() * 1e3 / frames as f64;
    let handling_cpu_ms = cpu0.zip(process_cpu_ns()).map(|(a, b)| (b - a) as f64 * 1e-6 / frames as f64);
    let cpu_ms = if a.cpu {
        let t = Instant::now();
        let reps = 3;
        for _ in 0..reps {
            std::hint::black_box(pipe.contacts_cpu(&poses));
        }
        Some(t.elapsed().as_secs_f64() * 1e3 / reps as f64)
    } else {
        None
    };
    let n = worlds as f64;
    let cand = out.candidates.iter().map(|&c| c as f64).sum::<f64>() / n;
    let contacts = (0..worlds as usize).map(|i| out.contact_count(i) as f64).sum::<f64>() / n;
    let npatch = out.patches.iter().map(|p| p.len() as f64).sum::<f64>() / n;
    let max_contacts = (0..worlds as usize).map(|i| out.contact_count(i)).max().unwrap_or(0);
    if !(cand > 0.0) {
        bail!("no contact candidates: the parts do not touch at lift {lift} m");
    }
    Ok(serde_json::json!({
        "pair": scene.pair.name,
        "worlds": worlds,
        "adapter": gpu.info.name,
        "software_adapter": gpu.is_software(),
        "query_triangles": scene.query_triangles,
        "sdf_triangles": scene.sdf_triangles,
        "sdf": if scene.grid.is_some() { "grid" } else { "analytic" },
        "sdf_resolution": scene.grid.as_ref().map(|_| a.sdf_res),
        "sdf_dims": scene.grid.as_ref().map(|g| [g.dims.x, g.dims.y, g.dims.z]),
        "sdf_bake_or_load_s": bake_s,
        "max_patches": a.patches,
        "normal_bin_deg": a.normal_deg,
        "workgroup_size": a.workgroup,
        "candidates_per_invocation": a.per,
        "interleaved_descent": !a.sequential_descent,
        "descent_iters": a.descent_iters,
        "contact_offset_mm": a.offset_mm,
        "lift_mm": lift * 1e3,
        "deepest_contact_um": min_depth(&out).map(|d| d * 1e6),
        "candidates_per_pair": cand,
        "contacts_per_pair": contacts,
        "max_contacts_per_pair": max_contacts,
        "patches_per_pair": npatch,
        "handling_ms_per_frame": handling_ms,
        "handling_cpu_ms_per_frame": handling_cpu_ms,
        "cpu_twin_ms_per_frame": cpu_ms,
        "frames": frames,
    }))
}

/// The report's figures for a person.
pub fn summary(r: &Value) -> Summary {
    let f = |k: &str| r[k].as_f64().unwrap_or(f64::NAN);
    let sdf = match r["sdf_dims"].as_array() {
        Some(d) => format!(
            "grid, {} samples along the longest axis ({}), baked or loaded in {:.2} s",
            r["sdf_resolution"],
            d.iter().map(|x| x.to_string()).collect::<Vec<_>>().join(" x "),
            f("sdf_bake_or_load_s")
        ),
        None => "analytic".into(),
    };
    let mut s = Summary::new(format!(
        "contacts: {}, {} worlds, {} frames timed",
        r["pair"].as_str().unwrap_or_default(),
        r["worlds"],
        r["frames"]
    ));
    s.row(
        "adapter",
        format!("{} (software: {})", r["adapter"].as_str().unwrap_or_default(), yes_no(r["software_adapter"] == true)),
    )
    .row("SDF", sdf)
    .row("triangles", format!("{} queried against {}", r["query_triangles"], r["sdf_triangles"]))
    .row(
        "per pair",
        format!(
            "{:.1} candidates -> {:.1} contacts (at most {}) in {:.1} patches",
            f("candidates_per_pair"),
            f("contacts_per_pair"),
            r["max_contacts_per_pair"],
            f("patches_per_pair")
        ),
    )
    .row(
        "deepest contact",
        r["deepest_contact_um"]
            .as_f64()
            .map_or("none".into(), |d| format!("{d:.2} um signed distance (negative: overlapping)")),
    )
    .row("handling", format!("{:.3} ms per frame", f("handling_ms_per_frame")));
    if let Some(cpu) = r["handling_cpu_ms_per_frame"].as_f64() {
        s.row("handling CPU time", format!("{cpu:.3} ms per frame (all threads)"));
    }
    if let Some(twin) = r["cpu_twin_ms_per_frame"].as_f64() {
        s.row("CPU twin", format!("{twin:.3} ms per frame"));
    }
    s
}

/// CPU time of all this process's threads so far [ns] (Linux; None elsewhere). On a shared machine the wall
/// time of a software adapter (lavapipe) swings with the other processes' load, its CPU time much less:
/// compare CPU times when others share the cores.
fn process_cpu_ns() -> Option<u64> {
    let mut total = 0;
    for task in std::fs::read_dir("/proc/self/task").ok()? {
        let stat = std::fs::read_to_string(task.ok()?.path().join("schedstat")).ok()?;
        total += stat.split_whitespace().next()?.parse::<u64>().ok()?;
    }
    Some(total)
}

//! Contact handling of the Screw env: the device pipeline (lavapipe without a GPU) against its CPU twin
//! (`ContactPipeline::contacts_cpu`, rayon over jobs) at the same poses, frame by frame under zero actions,
//! and the nut's triangles by their distance from its axis (those the thread pair could drop). Each
//! KEY=VALUE is a line of the `[env]` table, e.g. `start_engaged=true start_turns_down=5`.
//!
//!   cargo run --release -p factory-envs --example contacts_host -- [worlds] [frames] [KEY=VALUE ...]
use factory_engine::gpu::GpuContext;
use factory_envs::{Env, FrankaNutBolt, FrankaNutBoltConfig, StepBuffers};
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let worlds: usize = args.get(1).map(|s| s.parse().unwrap()).unwrap_or(128);
    let frames: usize = args.get(2).map(|s| s.parse().unwrap()).unwrap_or(20);
    let mut toml = String::new();
    for kv in args.iter().skip(3) {
        toml.push_str(kv);
        toml.push('\n');
    }
    let cfg: FrankaNutBoltConfig = toml::from_str(&toml).unwrap();
    let gpu = GpuContext::global().unwrap();
    let mut e = FrankaNutBolt::new(&cfg, worlds, 0).unwrap();
    let mut b = StepBuffers::new(e.spec());
    e.reset(&mut b);
    {
        let m = &e.scene().nb.nut.mesh;
        let mut hist = std::collections::BTreeMap::new();
        for t in &m.triangles {
            let r = t
                .iter()
                .map(|&i| glam::Vec2::new(m.positions[i as usize].x, m.positions[i as usize].y).length())
                .fold(f32::MAX, f32::min);
            *hist.entry((r * 1e3).floor() as i32).or_insert(0) += 1;
        }
        println!("nut triangles {} by their nearest vertex's distance from the axis [mm]: {hist:?}", m.triangles.len());
    }
    let a = vec![0.0f32; 12 * worlds];
    let (mut t_dev, mut t_cpu, mut same) = (0.0, 0.0, 0usize);
    for _ in 0..frames {
        e.step(&a, &mut b);
        let sim = &e.scene().sim;
        let t = Instant::now();
        sim.pipe.write_body_q(gpu, &sim.state.body_q);
        sim.pipe.run(gpu);
        let dev = sim.pipe.read_for_solver(gpu);
        t_dev += t.elapsed().as_secs_f64();
        let t = Instant::now();
        let cpu = sim.pipe.contacts_cpu(&sim.state.body_q);
        t_cpu += t.elapsed().as_secs_f64();
        same += (dev.candidates == cpu.candidates
            && dev.patches.iter().zip(&cpu.patches).all(|(x, y)| x.len() == y.len())) as usize;
    }
    println!("device {:.2} ms/frame, cpu twin {:.2} ms/frame, ratio {:.2}; frames with matching patch counts {same}/{frames}", 1e3 * t_dev / frames as f64, 1e3 * t_cpu / frames as f64, t_cpu / t_dev);
}

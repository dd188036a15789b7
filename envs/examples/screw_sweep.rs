//! Constant-action sweep on the Screw env: each world holds one constant action (a yaw rate and a push along
//! z) for a whole episode; prints how each episode ended (`success`, `slipped`, ...) and how far the nut went. Shows whether (and how fast)
//! a simple open-loop policy screws the nut down under the env's physics.
//!
//!   cargo run --release -p factory-envs --example screw_sweep -- [steps] [substeps] [pos_iters]
//!
//! Environment: LINK_PATCH_ITERS, GRASP_HEIGHT [m], START_ENGAGED and BOLT_TIP_CHAMFER (true/false), ZS and YAWS
//! (the z and yaw actions, comma-separated; default 0,-1 and eight yaws), REPEAT (worlds per action, default 1),
//! SIGMA (Gaussian noise of this standard deviation added to all 12 actions every step, as a PPO policy
//! explores; default 0).

use factory_envs::{Env, FrankaNutBolt, FrankaNutBoltConfig, StepBuffers};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let steps: usize = args.get(1).map(|s| s.parse().unwrap()).unwrap_or(2400);
    let mut cfg = FrankaNutBoltConfig::default();
    if let Some(s) = args.get(2) {
        cfg.substeps = s.parse().unwrap();
    }
    if let Some(s) = args.get(3) {
        cfg.pos_iters = s.parse().unwrap();
    }
    if let Ok(v) = std::env::var("LINK_PATCH_ITERS") {
        cfg.link_patch_iters = v.parse().unwrap();
    }
    if let Ok(v) = std::env::var("GRASP_HEIGHT") {
        cfg.grasp_height = v.parse().unwrap();
    }
    if let Ok(v) = std::env::var("START_ENGAGED") {
        cfg.start_engaged = v.parse().unwrap();
    }
    if let Ok(v) = std::env::var("BOLT_TIP_CHAMFER") {
        cfg.bolt_tip_chamfer = v.parse().unwrap();
    }
    // Yaw actions (unidirectional: -1 no turn, +1 the full 0.1 rad clockwise increment) x z actions.
    let list = |name: &str, default: Vec<f32>| -> Vec<f32> {
        std::env::var(name)
            .map(|v| v.split(',').map(|x| x.parse().expect("comma-separated numbers")).collect())
            .unwrap_or(default)
    };
    let yaws = list("YAWS", vec![-0.98f32, -0.95, -0.9, -0.8, -0.6, -0.2, 0.4, 1.0]);
    let zs = list("ZS", vec![0.0, -1.0]);
    let repeat: usize = std::env::var("REPEAT").map(|v| v.parse().unwrap()).unwrap_or(1);
    let sigma: f32 = std::env::var("SIGMA").map(|v| v.parse().unwrap()).unwrap_or(0.0);
    let mut rng = factory_engine::rng::SplitMix64(7);
    let combos = yaws.len() * zs.len();
    let worlds = combos * repeat;
    let mut e = FrankaNutBolt::new(&cfg, worlds, 0).unwrap();
    let mut b = StepBuffers::new(e.spec());
    e.reset(&mut b);
    let mut act = vec![0.0f32; worlds * 12];
    for r in 0..repeat {
        for (i, &z) in zs.iter().enumerate() {
            for (j, &y) in yaws.iter().enumerate() {
                let w = r * combos + i * yaws.len() + j;
                act[w * 12 + 2] = z;
                act[w * 12 + 5] = y;
            }
        }
    }
    let mean = act.clone();
    let z0: Vec<f32> = (0..worlds).map(|w| e.scene().nut_pose(w).0.z).collect();
    let mut ended: Vec<Option<(usize, &str, f32)>> = vec![None; worlds];
    let t0 = std::time::Instant::now();
    for t in 0..steps {
        let zs_before: Vec<f32> = (0..worlds).map(|w| e.scene().nut_pose(w).0.z).collect();
        // The fingertip relative to the nut's frame before the step (where a failed world is reset).
        let arm = e.scene().arm();
        let tip_rel: Vec<glam::Vec3> = (0..worlds).map(|w| arm.ee_pos[w] - e.scene().nut_pose(w).0).collect();
        if sigma > 0.0 {
            for (a, m) in act.iter_mut().zip(&mean) {
                // Box-Muller.
                let (u1, u2) = (rng.unit().max(1e-7), rng.unit());
                *a = m + sigma * (-2.0 * u1.ln()).sqrt() * (std::f32::consts::TAU * u2).cos();
            }
        }
        e.step(&act, &mut b);
        for w in 0..worlds {
            if ended[w].is_none() && b.done(w) {
                ended[w] = Some((t + 1, b.end_cause(w).unwrap_or("?"), z0[w] - zs_before[w]));
                if b.success[w] == 0.0 {
                    let r = tip_rel[w] * 1e3;
                    println!(
                        "world {w} ended {:?} at step {}: fingertip - nut frame {:.1} {:.1} {:.1} mm",
                        ended[w].unwrap().1,
                        t + 1,
                        r.x,
                        r.y,
                        r.z
                    );
                }
            }
        }
        if (t + 1) % 300 == 0 || ended.iter().all(|x| x.is_some()) {
            let sunk: Vec<String> = (0..worlds)
                .map(|w| match ended[w] {
                    Some((s, cause, d)) => format!("{cause}@{s}:{:.1}", 1e3 * d),
                    None => format!("{:.1}", 1e3 * (z0[w] - e.scene().nut_pose(w).0.z)),
                })
                .collect();
            println!("step {} ({:.0} s): sunk mm {}", t + 1, t0.elapsed().as_secs_f32(), sunk.join(" "));
            if ended.iter().all(|x| x.is_some()) {
                break;
            }
        }
    }
    for (i, &z) in zs.iter().enumerate() {
        for (j, &y) in yaws.iter().enumerate() {
            let runs: Vec<_> = (0..repeat).map(|r| ended[r * combos + i * yaws.len() + j]).collect();
            let mut causes = factory_envs::EndCauses::default();
            for (_, c, _) in runs.iter().flatten() {
                causes.add(c, 1);
            }
            let ok: Vec<usize> = runs.iter().flatten().filter(|x| x.1 == "success").map(|x| x.0).collect();
            let mean_len = ok.iter().sum::<usize>() as f32 / ok.len().max(1) as f32;
            println!(
                "a_z {z:5.2} a_yaw {y:5.2}: {} (running {}), mean steps to success {mean_len:.0}",
                causes.summary(),
                runs.iter().filter(|x| x.is_none()).count()
            );
        }
    }
}

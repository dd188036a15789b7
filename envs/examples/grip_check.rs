//! The Screw env's grasp under any settings, over many worlds: the checks of envs/tests/franka_screw.rs
//! (zero actions hold the nut on its thread; the pads do not creep along a still nut; a constant clockwise
//! yaw of 0.02 rad per step seats it within 2000 steps) on N worlds each, with the hand angle drawn from
//! Table III's [-90, 90] deg so that the worlds differ, so a solver or contact setting can be judged against
//! the tests' bounds on a distribution rather than on one trajectory before it becomes a default.
//!
//!   cargo run --release -p factory-envs --example grip_check -- N [KEY=VALUE ...]
//!
//! Each KEY=VALUE is a line of the `[env]` table (TOML), e.g. `substeps=2 pos_iters=16`.

use factory_envs::{Env, FrankaNutBolt, FrankaNutBoltConfig, StepBuffers};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let n: usize = args.get(1).and_then(|s| s.parse().ok()).expect("usage: grip_check N [KEY=VALUE ...]");
    let mut toml =
        String::from("start_engaged = true\nunidirectional_rot = false\nrandomize.hand_angle_deg = [-90, 90]\n");
    for kv in &args[2..] {
        toml.push_str(kv);
        toml.push('\n');
    }
    let cfg: FrankaNutBoltConfig = toml::from_str(&toml).unwrap_or_else(|e| panic!("{toml}: {e}"));
    let worlds = 2 * n;
    let mut e = FrankaNutBolt::new(&cfg, worlds, 1).unwrap();
    let mut b = StepBuffers::new(e.spec());
    e.reset(&mut b);
    let dim = e.spec().observation_dim();
    // The fingertip's height below the nut's (observation 2: fingertip z, 15: nut z).
    let gap = |b: &StepBuffers, w: usize| b.observation[w * dim + 15] - b.observation[w * dim + 2];
    let z0: Vec<f32> = (0..n).map(|w| e.scene().nut_pose(w).0.z).collect();
    let gap0: Vec<f32> = (0..n).map(|w| gap(&b, w)).collect();
    // Worlds 0..n hold still; worlds n..2n turn clockwise as the tests' a = -0.6 under the unidirectional
    // map (-(a + 1) / 2 = -0.2 of the 0.1 rad scale).
    let mut a = vec![0.0f32; 12 * worlds];
    for w in n..worlds {
        a[12 * w + 5] = -0.2;
    }
    let start = std::time::Instant::now();
    let mut ended = vec![None::<(usize, bool)>; worlds];
    for t in 0..2000 {
        e.step(&a, &mut b);
        for (w, end) in ended.iter_mut().enumerate() {
            if end.is_none() && b.done(w) {
                *end = Some((t + 1, b.success[w] > 0.5));
            }
        }
        if t + 1 == 300 {
            let worst = (0..n)
                .filter(|&w| ended[w].is_none())
                .map(|w| (e.scene().nut_pose(w).0.z - z0[w]).abs())
                .fold(0.0f32, f32::max);
            println!("hold 300: worst nut height change {:.3} mm", 1e3 * worst);
        }
        if (t + 1) % 250 == 0 && t < 1000 {
            let creep: Vec<f32> =
                (0..n).filter(|&w| ended[w].is_none()).map(|w| (1e3 * (gap0[w] - gap(&b, w))).abs()).collect();
            let worst = creep.iter().copied().fold(0.0f32, f32::max);
            let over = creep.iter().filter(|&&c| c >= 1.0).count();
            println!("creep {}: worst {worst:.3} mm, {over} of {} worlds at 1 mm or more", t + 1, creep.len());
        }
        if t >= 1000 && ended[n..].iter().all(Option::is_some) {
            break;
        }
    }
    let held = ended[..n].iter().filter(|e| e.is_none()).count();
    let seated: Vec<usize> = ended[n..].iter().filter_map(|e| e.filter(|&(_, s)| s).map(|(t, _)| t)).collect();
    let mean = seated.iter().sum::<usize>() as f32 / seated.len().max(1) as f32;
    println!(
        "still held {held}/{n}; seated {}/{n} (mean step {mean:.0}); wall {:.1} s",
        seated.len(),
        start.elapsed().as_secs_f32()
    );
}

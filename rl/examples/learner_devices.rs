//! The learner on burn-flex vs burn-wgpu (on the engine's device), alternating in one run: per PPO update of
//! the Table IX MLP (256-128-64), the device-resident rollout of the point mass and the update itself.
//! `cargo run --release -p factory-rl --features wgpu --example learner_devices [ROUNDS]`
//! (without the feature only flex is measured).

use std::time::Instant;

use burn::tensor::Device;
use factory_envs::{DeviceEnv, PointMassConfig, PointMassDevice};
use factory_rl::config::PpoConfig;
use factory_rl::ppo::{DeviceEpisodes, Ppo};

/// Seconds of (rollout, update) for one update on `device`, after `warm` unmeasured ones.
fn measure(device: &Device, warm: usize) -> (f64, f64) {
    let cfg = PpoConfig { hidden: vec![256, 128, 64], ..PpoConfig::default() };
    let n = 128;
    let mut env = PointMassDevice::new(&PointMassConfig::default(), n, 1, device).unwrap();
    let mut ppo = Ppo::new(&cfg, n, 4, 2, 1, device.clone());
    let mut obs = env.reset().observation;
    let mut episodes = DeviceEpisodes::new(n, device);
    let mut out = (0.0, 0.0);
    for _ in 0..=warm {
        let t0 = Instant::now();
        let rollout = ppo.collect_device(&mut env, &mut obs, &mut episodes);
        let t1 = Instant::now();
        // The update ends in the summary's readback, which waits for the device.
        ppo.update_with(rollout, Some(episodes.take()));
        out = ((t1 - t0).as_secs_f64(), t1.elapsed().as_secs_f64());
    }
    out
}

fn main() {
    let rounds: usize = std::env::args().nth(1).and_then(|s| s.parse().ok()).unwrap_or(3);
    let mut devices = vec![(Device::flex(), "flex".to_string())];
    match factory_rl::train::engine_wgpu_device() {
        Ok((d, name)) => devices.push((d, name)),
        Err(e) => eprintln!("{e}"),
    }
    println!("128 envs x horizon 32, MLP 256-128-64, minibatch 512 x 8 epochs (64 gradient steps per update)");
    for round in 0..rounds {
        for (device, name) in &devices {
            let (rollout, update) = measure(device, 1);
            println!("round {round} {name}: rollout {rollout:.3} s, update {update:.3} s");
        }
    }
}

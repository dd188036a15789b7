//! The Screw env resident on the device (`FrankaNutBoltDevice`) under the learner on burn's wgpu backend over
//! the engine's device: nothing is read back per step except an explicit logging summary (docs/ARCHITECTURE.md
//! section 7). Needs `--features wgpu`. The engine's sync count is process-wide: the tests here take turns.

#![cfg(feature = "wgpu")]

use std::path::PathBuf;
use std::sync::Mutex;

use factory_engine::gpu::host_syncs;
use factory_envs::franka::device_env::FrankaNutBoltDevice;
use factory_envs::{DeviceEnv, EnvConfig};
use factory_rl::model::readbacks;
use factory_rl::ppo::{DeviceEpisodes, Ppo};
use factory_rl::TrainConfig;

/// Two rollouts of 8 steps of 4 Screw worlds read nothing back and wait for nothing, neither in the learner
/// (its readback choke point) nor in the engine (readbacks and waits); each update then reads its summary
/// once, with finite losses and the episode tallies (episodes of 5 steps: an end per world per rollout at
/// least), every failure counted under its cause.
/// `host_syncs` counts every thread's readbacks and waits, so the tests of this binary take turns: the
/// checkpoint test's readbacks, counted during the rollout test's rollout, failed it when they overlapped.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

#[test]
fn a_franka_device_rollout_reads_nothing_back_per_step() {
    let _turn = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let (device, name) = factory_rl::train::engine_wgpu_device().expect("the engine's wgpu device");
    eprintln!("learner on {name}");
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../configs/screw_quick.toml");
    let sets: Vec<String> = ["train.env_count=4", "ppo.horizon=8", "ppo.minibatch_size=16", "env.max_episode_steps=5"]
        .map(String::from)
        .into();
    let cfg = TrainConfig::load(&path, &sets).unwrap();
    let EnvConfig::FrankaNutBolt(env_cfg) = &cfg.env else { panic!("screw_quick.toml builds {:?}", cfg.env) };
    let n = cfg.train.env_count;
    let mut env = FrankaNutBoltDevice::new(env_cfg, n, 1, &device).unwrap();
    let spec = env.spec().clone();
    let mut ppo = Ppo::new(&cfg.ppo, n, spec.observation_dim(), spec.action_dim(), 1, device.clone());
    let mut obs = env.reset().observation;
    assert_eq!(env.failure_causes(), ["far", "slipped", "fallen", "diverged"]);
    let mut episodes = DeviceEpisodes::with_causes(n, env.failure_causes().len(), &device);
    for round in 0..2 {
        let (learner, engine) = (readbacks(), host_syncs());
        let rollout = ppo.collect_device(&mut env, &mut obs, &mut episodes);
        assert_eq!(readbacks() - learner, 0, "round {round}: the learner read back during the rollout");
        assert_eq!(host_syncs() - engine, 0, "round {round}: the engine read back or waited during the rollout");
        let (stats, tallies) = ppo.update_with(rollout, Some(episodes.take()));
        assert_eq!(readbacks() - learner, 1, "round {round}: an update reads its summary once");
        assert!(stats.actor_loss.is_finite() && stats.critic_loss.is_finite(), "{stats:?}");
        let ended_by = DeviceEpisodes::ended_by(&tallies, env.failure_causes());
        eprintln!("round {round}: {stats:?}, tallies {tallies:?}, {ended_by:?}");
        assert_eq!(tallies.len(), 9);
        assert_eq!(ended_by.total(), tallies[0].round() as usize);
        assert!(!ended_by.0.contains_key("failure"), "every failure has its cause: {ended_by:?}");
        assert!(tallies[0] >= n as f32, "round {round}: {} episodes ended in 8 steps of 5-step episodes", tallies[0]);
    }
}

/// A checkpoint carries the device Screw env: a trainer resumed from one taken after 2 updates holds the
/// saved trainer's device state (bodies, the solve's warm-start rows and joints, the episodes' counters) and
/// observations bitwise. (That a loaded state then steps on bitwise is envs/tests/franka_screw_device.rs;
/// the learner on burn-wgpu is not bitwise repeatable across trainers in every run, so their updates are not
/// compared here.)
#[test]
fn a_franka_device_checkpoint_carries_the_env_state() {
    let _turn = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    use factory_rl::train::{EnvRun, Trainer};
    let (device, _) = factory_rl::train::engine_wgpu_device().expect("the engine's wgpu device");
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../configs/screw_quick.toml");
    let sets: Vec<String> = ["train.env_count=4", "ppo.horizon=8", "ppo.minibatch_size=16", "env.max_episode_steps=12"]
        .map(String::from)
        .into();
    let cfg = TrainConfig::load(&path, &sets).unwrap();
    let dir = std::env::temp_dir().join(format!("factory-rl-franka-device-{}", std::process::id()));
    let ck = dir.join("checkpoint.bin");
    let mut first = Trainer::new(cfg, device.clone()).unwrap();
    assert!(first.run.on_device(), "a wgpu learner takes the device env");
    first.update();
    first.update();
    first.save_checkpoint(&ck).unwrap();
    let resumed = Trainer::resume(&ck, device).unwrap();
    let state = |t: &Trainer| match &t.run {
        EnvRun::Device { env, obs, .. } => {
            (env.save_state().expect("the device env saves"), obs.clone().into_data().try_into_vec::<f32>().unwrap())
        }
        EnvRun::Host { .. } => panic!("the device env"),
    };
    let ((saved, saved_obs), (loaded, loaded_obs)) = (state(&first), state(&resumed));
    assert!(saved.len() > 100_000, "{} bytes of device state", saved.len());
    assert!(saved == loaded, "the resumed env's device state differs");
    assert!(saved_obs == loaded_obs, "the resumed observations differ");
    assert_eq!(resumed.updates_done, 2);
    std::fs::remove_dir_all(&dir).ok();
}

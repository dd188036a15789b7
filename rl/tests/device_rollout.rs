//! The device-resident rollout: a [`DeviceEnv`] and the learner on one device, the host reading nothing back
//! per step (readbacks counted at the learner's one choke point, `model::to_vec`), and the same learning as the
//! host path.

use std::path::PathBuf;

use burn::module::Module;
use burn::tensor::Device;
use factory_envs::{DeviceEnv, PointMassConfig, PointMassDevice};
use factory_rl::eval::evaluate;
use factory_rl::model::readbacks;
use factory_rl::ppo::{DeviceEpisodes, Ppo};
use factory_rl::TrainConfig;

fn config() -> TrainConfig {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../configs/point_mass.toml");
    TrainConfig::load(&path, &[]).unwrap()
}

fn point_mass_config(cfg: &TrainConfig) -> PointMassConfig {
    match &cfg.env {
        factory_envs::EnvConfig::PointMass(c) => c.clone(),
        other => panic!("configs/point_mass.toml builds {other:?}"),
    }
}

/// The point mass on `device` with a fresh learner, reset.
struct Run {
    env: PointMassDevice,
    ppo: Ppo,
    obs: burn::tensor::Tensor<2>,
    episodes: DeviceEpisodes,
}

impl Run {
    fn new(cfg: &TrainConfig, device: &Device) -> Self {
        let n = cfg.train.env_count;
        let mut env = PointMassDevice::new(&point_mass_config(cfg), n, 1, device).unwrap();
        let spec = env.spec().clone();
        let ppo = Ppo::new(&cfg.ppo, n, spec.observation_dim(), spec.action_dim(), 1, device.clone());
        let obs = env.reset().observation;
        Self { env, ppo, obs, episodes: DeviceEpisodes::new(n, device) }
    }
}

/// K rollout steps read nothing back; the update reads back once (its summary with the episode tallies).
fn rollouts_read_back_only_the_summary(device: Device) {
    let cfg = config();
    let Run { mut env, mut ppo, mut obs, mut episodes } = Run::new(&cfg, &device);
    for _ in 0..2 {
        let before = readbacks();
        let rollout = ppo.collect_device(&mut env, &mut obs, &mut episodes);
        let during = readbacks() - before;
        assert_eq!(during, 0, "{during} readbacks in {} rollout steps", cfg.ppo.horizon);
        let (stats, tallies) = ppo.update_with(rollout, Some(episodes.take()));
        let total = readbacks() - before;
        assert_eq!(total, 1, "an update reads back its summary once, not {total} times");
        assert!(stats.actor_loss.is_finite() && stats.critic_loss.is_finite(), "{stats:?}");
        assert_eq!(tallies.len(), 5);
        assert!(tallies[1] + tallies[4] <= tallies[0] && tallies[0] >= 0.0, "tallies {tallies:?}");
    }
}

/// The choke point counts the same on every backend: on burn-flex (the default build, CI).
#[test]
fn a_device_rollout_reads_nothing_back_per_step() {
    rollouts_read_back_only_the_summary(Device::flex());
}

/// On burn's wgpu backend sharing the engine's device (lavapipe on a machine without a GPU); needs
/// `--features wgpu`.
#[cfg(feature = "wgpu")]
#[test]
fn a_device_rollout_on_the_engines_wgpu_device_reads_nothing_back_per_step() {
    let (device, name) = factory_rl::train::engine_wgpu_device().expect("the engine's wgpu device");
    eprintln!("learner on {name}");
    rollouts_read_back_only_the_summary(device);
}

/// Trained through the device path (on burn-flex, which runs the same code fast on a CPU), the point mass is
/// learned as through the host path: > 95% of 1024 evaluation episodes in the host env.
#[test]
fn the_device_path_learns_the_point_mass() {
    let cfg = config();
    let device = Device::flex();
    let Run { mut env, mut ppo, mut obs, mut episodes } = Run::new(&cfg, &device);
    let mut ended = (0.0, 0.0);
    for _ in 0..cfg.train.updates {
        let rollout = ppo.collect_device(&mut env, &mut obs, &mut episodes);
        let (_, t) = ppo.update_with(rollout, Some(episodes.take()));
        ended = (ended.0 + t[0], ended.1 + t[1]);
    }
    let model = ppo.model.valid();
    let norm = ppo.cfg.normalize_observation.then_some(&ppo.obs_norm);
    let mut host = factory_envs::build(&cfg.env, 128, 999).unwrap();
    let report = evaluate(host.as_mut(), &model, norm, cfg.ppo.observation_clip, 1024, &device, Default::default());
    eprintln!("device path: {} episodes in training ({} succeeded); eval {report:?}", ended.0, ended.1);
    assert!(ended.0 > 0.0);
    assert!(report.success_rate > 0.95, "evaluation success {:.3} <= 0.95", report.success_rate);
}

/// A device env's failure causes are counted apart: one step of 5 worlds (a success, a time limit, two
/// `slipped`, one `far`) tallies each under its name, nothing under the generic `failure`.
#[test]
fn device_failure_causes_are_tallied_by_name() {
    let device = Device::flex();
    let t = |v: [f32; 5]| burn::tensor::Tensor::<1>::from_floats(v, &device);
    let mut episodes = DeviceEpisodes::with_causes(5, 2, &device);
    let step = factory_envs::DeviceStep {
        observation: burn::tensor::Tensor::zeros([5, 1], &device),
        reward: t([1.0; 5]),
        terminated: t([1.0, 0.0, 1.0, 1.0, 1.0]),
        truncated: t([0.0, 1.0, 0.0, 0.0, 0.0]),
        success: t([1.0, 0.0, 0.0, 0.0, 0.0]),
        // 1 + the cause's index in ["far", "slipped"].
        failure: Some(t([0.0, 0.0, 2.0, 2.0, 1.0])),
    };
    episodes.record(&step);
    let totals = episodes.take().into_data().try_into_vec::<f32>().unwrap();
    let ended_by = DeviceEpisodes::ended_by(&totals, &["far", "slipped"]);
    let want: std::collections::BTreeMap<String, usize> =
        [("success", 1), ("time_limit", 1), ("slipped", 2), ("far", 1)].map(|(k, v)| (k.to_string(), v)).into();
    assert_eq!(ended_by.0, want, "{totals:?}");
    // Without names the same step's failures fall under `failure`.
    assert_eq!(DeviceEpisodes::ended_by(&totals[..5], &[]).0.get("failure"), Some(&3));
}

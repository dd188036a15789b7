//! The Screw task through the whole loop (simulator on lavapipe or a GPU, controller, learner, checkpoint).

use std::path::PathBuf;

use burn::tensor::Device;
use factory_rl::train::Trainer;
use factory_rl::TrainConfig;

fn quick(sets: &[&str]) -> TrainConfig {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../configs/screw_quick.toml");
    let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
    TrainConfig::load(&path, &sets).unwrap()
}

/// A few updates with finite losses; a run checkpointed after 2 updates and resumed gives the same numbers
/// for updates 3 and 4 as the uninterrupted run (the env's state, warm start included, is in the checkpoint).
#[test]
fn screw_smoke_and_exact_resume() {
    let cfg = quick(&[]);
    let mut straight = Trainer::new(cfg.clone(), Device::flex()).unwrap();
    let mut a = Vec::new();
    for _ in 0..4 {
        let r = straight.update();
        let s = &r.stats;
        assert!(
            s.actor_loss.is_finite() && s.critic_loss.is_finite() && s.bounds_loss.is_finite(),
            "update {}: {s:?}",
            r.update
        );
        assert!(s.mean_reward.is_finite() && s.mean_reward < 0.0, "{s:?}");
        a.push(r.stats);
    }

    let dir = std::env::temp_dir().join(format!("factory-rl-screw-{}", std::process::id()));
    let ck = dir.join("checkpoint.bin");
    let mut first = Trainer::new(cfg, Device::flex()).unwrap();
    first.update();
    first.update();
    first.save_checkpoint(&ck).unwrap();
    drop(first);
    let mut resumed = Trainer::resume(&ck, Device::flex()).unwrap();
    for i in 2..4 {
        let s = resumed.update().stats;
        assert_eq!(
            (s.actor_loss, s.critic_loss, s.mean_reward),
            (a[i].actor_loss, a[i].critic_loss, a[i].mean_reward),
            "update {}",
            i + 1
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// With a flex (CPU) learner the Franka env has no device implementation (it needs burn's wgpu runtime on the
/// engine's device, rl/tests/franka_device.rs): asking for a device rollout is refused naming the field
/// and the valid choices, before any world is built; `auto` keeps the env on the host.
#[test]
fn a_device_rollout_of_the_franka_env_is_refused_by_name() {
    let e = Trainer::new(quick(&["train.rollout=\"device\""]), Device::flex()).err().unwrap().to_string();
    assert!(e.contains("train.rollout") && e.contains("franka_nut_bolt") && e.contains("\"host\""), "{e}");
    let t = Trainer::new(quick(&["train.env_count=2", "ppo.minibatch_size=16"]), Device::flex()).unwrap();
    assert!(!t.run.on_device(), "auto keeps the Franka env on the host");
}

/// Screw has no reset randomisation (IsaacGymEnvs): every world starts from the same observation, and the
/// evaluation says so (factory-eval then notes that mean actions play one episode in every world).
#[test]
fn screw_evaluation_reports_identical_starts() {
    let sets = ["train.env_count=2", "ppo.minibatch_size=16", "env.max_episode_steps=3"];
    let t = Trainer::new(quick(&sets), Device::flex()).unwrap();
    let dir = std::env::temp_dir().join(format!("factory-rl-screw-eval-{}", std::process::id()));
    let path = dir.join("policy.json");
    t.export_policy(&path).unwrap();
    let p = factory_rl::checkpoint::PolicyFile::load(&path).unwrap();
    let (model, norm) = p.build(&Device::flex(), &path).unwrap();
    let mut env = factory_envs::build(&p.env_config, 2, 1).unwrap();
    let opts = factory_rl::eval::EvalOptions::default();
    let r =
        factory_rl::eval::evaluate(env.as_mut(), &model, norm.as_ref(), p.observation_clip, 2, &Device::flex(), opts);
    assert!(r.identical_starts && !r.stochastic, "{r:?}");
    assert_eq!(r.ended_by.0.get("time_limit"), Some(&2), "{r:?}");
    std::fs::remove_dir_all(&dir).ok();
}

//! The learner on the point-mass task: it learns (evaluated, not trained, success), and a run resumed from a
//! checkpoint continues exactly as the uninterrupted run.

use std::path::PathBuf;

use burn::tensor::{Device, Tensor};
use factory_rl::checkpoint::PolicyFile;
use factory_rl::eval::{evaluate, EvalOptions, Trace};
use factory_rl::train::{EnvRun, Trainer};
use factory_rl::TrainConfig;

fn config(sets: &[&str]) -> TrainConfig {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../configs/point_mass.toml");
    let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
    TrainConfig::load(&path, &sets).unwrap()
}

/// The learning test: PPO reaches > 95% success on a small task written against the same Env trait,
/// judged by 1024 evaluation episodes with deterministic actions in fresh worlds (another seed).
#[test]
fn ppo_learns_point_mass_reaching() {
    let cfg = config(&[]);
    let updates = cfg.train.updates;
    let mut t = Trainer::new(cfg, Device::flex()).unwrap();
    // The untrained policy, evaluated the same way, so the bar measures learning and not an easy task.
    let untrained = {
        let dir = std::env::temp_dir().join(format!("factory-rl-untrained-{}", std::process::id()));
        let path = dir.join("policy.json");
        t.export_policy(&path).unwrap();
        let p = PolicyFile::load(&path).unwrap();
        let (model, norm) = p.build(&Device::flex(), &path).unwrap();
        let mut env = factory_envs::build(&p.env_config, 128, 999).unwrap();
        std::fs::remove_dir_all(&dir).ok();
        evaluate(env.as_mut(), &model, norm.as_ref(), p.observation_clip, 1024, &Device::flex(), Default::default())
    };
    assert!(untrained.success_rate < 0.3, "the untrained policy already succeeds: {untrained:?}");
    let mut last = None;
    for _ in 0..updates {
        let r = t.update();
        assert!(r.stats.actor_loss.is_finite() && r.stats.critic_loss.is_finite(), "update {}: {r:?}", r.update);
        // Every episode is counted once by how it ended: success, or the time limit (the point mass has no
        // failure).
        let ends = &r.ended_by.0;
        assert_eq!(ends.values().sum::<usize>(), r.episodes, "update {}: {ends:?}", r.update);
        assert!(ends.keys().all(|k| k == "success" || k == "time_limit"), "update {}: {ends:?}", r.update);
        if r.episodes > 0 {
            assert_eq!(ends.get("success").copied().unwrap_or(0) as f32 / r.episodes as f32, r.success_rate);
        }
        last = Some(r);
    }
    let last = last.unwrap();
    let dir = std::env::temp_dir().join(format!("factory-rl-learn-{}", std::process::id()));
    let policy_path = dir.join("policy.json");
    t.export_policy(&policy_path).unwrap();
    let policy = PolicyFile::load(&policy_path).unwrap();
    let device = Device::flex();
    let (model, norm) = policy.build(&device, &policy_path).unwrap();
    let mut env = factory_envs::build(&policy.env_config, 128, 999).unwrap();
    policy.check_spec(env.spec(), &policy_path).unwrap();
    let report =
        evaluate(env.as_mut(), &model, norm.as_ref(), policy.observation_clip, 1024, &device, Default::default());
    eprintln!("untrained: {untrained:?}");
    eprintln!(
        "after {updates} updates ({} env steps): training success {:.3}, eval {report:?}",
        t.env_steps, last.success_rate
    );
    assert_eq!(report.episodes, 1024);
    assert!(!report.identical_starts, "the point mass draws its starts");
    assert_eq!(report.ended_by.0.values().sum::<usize>(), 1024, "{:?}", report.ended_by);
    assert_eq!(report.ended_by.0.get("success").copied().unwrap_or(0) as f64 / 1024.0, report.success_rate);
    assert!(report.success_rate > 0.95, "evaluation success {:.3} <= 0.95", report.success_rate);
    // Sampled actions (`factory-eval --stochastic`): the noise acts, and the same seed repeats the run.
    let sampled = |seed| {
        let mut env = factory_envs::build(&policy.env_config, 128, 999).unwrap();
        let opts = EvalOptions { noise_seed: Some(seed), ..Default::default() };
        evaluate(env.as_mut(), &model, norm.as_ref(), policy.observation_clip, 1024, &device, opts)
    };
    let (s1, s2) = (sampled(5), sampled(5));
    eprintln!("sampled actions: {s1:?}");
    assert!(s1.stochastic && !report.stochastic);
    assert_ne!(s1.mean_return, report.mean_return, "sampling left the episodes as the mean's");
    assert_eq!((s1.success_rate, s1.mean_return), (s2.success_rate, s2.mean_return));
    // The per-step trace (`factory-eval --steps-csv`): world 0's observation, action, reward and flags; tracing
    // changes nothing, the first row starts from the reset, and world 0 ends at least its quota of episodes.
    let mut steps = Trace::default();
    let mut env = factory_envs::build(&policy.env_config, 128, 999).unwrap();
    let opts = EvalOptions { steps: Some(&mut steps), ..Default::default() };
    let traced = evaluate(env.as_mut(), &model, norm.as_ref(), policy.observation_clip, 1024, &device, opts);
    assert_eq!((traced.success_rate, traced.mean_return), (report.success_rate, report.mean_return));
    let (od, ad) = (env.spec().observation_dim(), env.spec().action_dim());
    assert_eq!(steps.names.len(), od + ad + 4);
    assert_eq!(steps.names[od], format!("action_{}", env.spec().action_names[0]));
    assert!(steps.rows.iter().all(|r| r.len() == od + ad + 4 && r[od..od + ad].iter().all(|a| a.abs() <= 1.0)));
    let ends = steps.rows.iter().filter(|r| r[od + ad + 1] != 0.0 || r[od + ad + 2] != 0.0).count();
    assert!(ends >= 1024 / 128, "world 0 ended {ends} episodes");
    let mut fresh = factory_envs::build(&policy.env_config, 128, 999).unwrap();
    let mut first = factory_envs::StepBuffers::new(fresh.spec());
    fresh.reset(&mut first);
    assert_eq!(&steps.rows[0][..od], &first.observation[..od]);
    std::fs::remove_dir_all(&dir).ok();
}

/// Checkpoint after 3 updates, resume in a new trainer, 3 more: the same losses and parameters as 6 straight,
/// with the env on the host and on the learner's device (`train.rollout`).
#[test]
fn resumed_run_matches_uninterrupted_run() {
    for rollout in ["host", "device"] {
        let r = format!("train.rollout=\"{rollout}\"");
        let sets = ["train.env_count=16", "ppo.minibatch_size=128", "ppo.epochs=2", "seed=7", &r];
        let mut straight = Trainer::new(config(&sets), Device::flex()).unwrap();
        assert_eq!(straight.run.on_device(), rollout == "device");
        let mut a = Vec::new();
        for _ in 0..6 {
            let before = factory_rl::model::readbacks();
            a.push(straight.update().stats);
            // A device run reads back once per update (the summary with the episode tallies); a host run
            // once per step (the actions) and once for the summary.
            let per_update = if rollout == "device" { 1 } else { straight.cfg.ppo.horizon as u64 + 1 };
            assert_eq!(factory_rl::model::readbacks() - before, per_update, "{rollout}");
        }

        let dir = std::env::temp_dir().join(format!("factory-rl-resume-{rollout}-{}", std::process::id()));
        let ck = dir.join("checkpoint.bin");
        let mut first = Trainer::new(config(&sets), Device::flex()).unwrap();
        let mut b = Vec::new();
        for _ in 0..3 {
            b.push(first.update().stats);
        }
        first.save_checkpoint(&ck).unwrap();
        drop(first);
        let mut resumed = Trainer::resume(&ck, Device::flex()).unwrap();
        assert_eq!(resumed.updates_done, 3);
        for _ in 0..3 {
            b.push(resumed.update().stats);
        }
        for (i, (x, y)) in a.iter().zip(&b).enumerate() {
            assert_eq!(
                (x.actor_loss, x.critic_loss, x.mean_reward, x.sigma),
                (y.actor_loss, y.critic_loss, y.mean_reward, y.sigma),
                "{rollout}: update {}",
                i + 1
            );
        }
        let pa = straight.ppo.model.export();
        let pb = resumed.ppo.model.export();
        assert_eq!(pa.len(), pb.len());
        for (x, y) in pa.iter().zip(&pb) {
            assert_eq!(x.2, y.2, "{rollout}: parameter {} differs after resuming", x.0);
        }
        std::fs::remove_dir_all(&dir).ok();
    }
}

/// A policy exported for one spec is refused by an env of another, showing both.
#[test]
fn policy_for_another_spec_is_refused() {
    let t = Trainer::new(config(&["train.env_count=4", "ppo.minibatch_size=64"]), Device::flex()).unwrap();
    let dir = std::env::temp_dir().join(format!("factory-rl-spec-{}", std::process::id()));
    let path = dir.join("policy.json");
    t.export_policy(&path).unwrap();
    let mut policy = PolicyFile::load(&path).unwrap();
    policy.observation_names.pop();
    let env = factory_envs::build(&policy.env_config, 4, 0).unwrap();
    let e = policy.check_spec(env.spec(), &path).unwrap_err().to_string();
    assert!(e.contains("goal_dx_m") && e.contains("vy_m_s") && e.contains("policy.json"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}

/// A checkpoint write that fails (its folder is a file) leaves the previous checkpoint as it was.
#[test]
fn failed_checkpoint_write_keeps_the_previous_one() {
    let mut t = Trainer::new(config(&["train.env_count=4", "ppo.minibatch_size=64"]), Device::flex()).unwrap();
    let dir = std::env::temp_dir().join(format!("factory-rl-atomic-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let ck = dir.join("checkpoint.bin");
    t.save_checkpoint(&ck).unwrap();
    let before = std::fs::read(&ck).unwrap();
    t.update();
    // A write that cannot happen (the target's folder is the existing checkpoint file; file modes would not
    // stop root): it must fail without touching the previous checkpoint or leaving a temporary file.
    let blocked = ck.join("inside-a-file");
    assert!(t.save_checkpoint(&blocked).is_err());
    assert_eq!(std::fs::read(&ck).unwrap(), before);
    let leftovers = std::fs::read_dir(&dir)
        .unwrap()
        .filter(|e| e.as_ref().unwrap().file_name().to_string_lossy().ends_with(".tmp"))
        .count();
    assert_eq!(leftovers, 0);
    std::fs::remove_dir_all(&dir).ok();
}

/// `train.stagger_first_episodes = N`: every world's first episode ends by step N, truncated (not
/// terminated) unless it reached the goal, at spread-out steps, so the next episodes run out of phase; the
/// learner's generator is untouched (the first rollout's observations are the unstaggered run's). A value
/// beyond the env's time limit is refused naming the field.
#[test]
fn staggered_first_episodes_end_out_of_phase() {
    let sets = ["train.env_count=64", "ppo.minibatch_size=64", "env.max_episode_steps=100"];
    for rollout in ["host", "device"] {
        let with = |more: &[&str]| config(&[&sets[..], &[&format!("train.rollout=\"{rollout}\"")], more].concat());
        let plain = Trainer::new(with(&[]), Device::flex()).unwrap();
        let mut t = Trainer::new(with(&["train.stagger_first_episodes=20"]), Device::flex()).unwrap();
        assert_eq!(t.run.on_device(), rollout == "device");
        assert_eq!(plain.run.observation(), t.run.observation());
        let n = 64;
        let mut first_end = vec![0u32; n];
        for step in 1..=20u32 {
            // Per world: ended this step, and whether by truncation or success.
            let (ended, ok): (Vec<bool>, Vec<bool>) = match &mut t.run {
                EnvRun::Host { env, buf, .. } => {
                    env.step(&vec![0.0f32; n * 2], buf);
                    (0..n).map(|w| (buf.done(w), buf.truncated[w] == 1.0 || buf.success[w] == 1.0)).unzip()
                }
                EnvRun::Device { env, .. } => {
                    let out = env.step(Tensor::zeros([n, 2], &Device::flex()));
                    let flags = |x: Tensor<1>| x.into_data().try_into_vec::<f32>().unwrap();
                    let (term, trunc, succ) = (flags(out.terminated), flags(out.truncated), flags(out.success));
                    (0..n).map(|w| (term[w] + trunc[w] > 0.0, trunc[w] == 1.0 || succ[w] == 1.0)).unzip()
                }
            };
            for w in 0..n {
                if first_end[w] == 0 && ended[w] {
                    first_end[w] = step;
                    assert!(ok[w], "{rollout}: world {w} ended otherwise");
                }
            }
        }
        assert!(first_end.iter().all(|&s| s > 0), "{rollout}: all first episodes end within 20 steps: {first_end:?}");
        let mut distinct = first_end.clone();
        distinct.sort_unstable();
        distinct.dedup();
        assert!(distinct.len() >= 12, "{rollout}: end steps spread over 1..=20: {first_end:?}");
    }

    let e = Trainer::new(config(&[&sets[..], &["train.stagger_first_episodes=101"]].concat()), Device::flex())
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("train.stagger_first_episodes") && e.contains("100"), "{e}");
}

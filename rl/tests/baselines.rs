//! The baselines of `factory-eval --baseline` on the point-mass task, where each has a known answer: the
//! scripted PD law reaches every goal, the zero action reaches only goals drawn within reach of the start,
//! the untrained network is the one a training run with that seed starts from, and the constant sweep runs
//! every candidate on its own worlds. Also the reports' Wilson intervals and per-episode records.

use burn::tensor::Device;
use factory_envs::{Env, EnvSpec, PointMassConfig, StepBuffers};
use factory_rl::baseline::{best_point, constant_candidates, sweep_constants, untrained_model};
use factory_rl::checkpoint::PolicyFile;
use factory_rl::eval::{evaluate, evaluate_actor, wilson_interval, Actor, EvalOptions, EvalReport};
use factory_rl::Ppo;

fn point_mass(worlds: usize, seed: u64) -> Box<dyn Env> {
    factory_envs::build(&factory_envs::EnvConfig::PointMass(PointMassConfig::default()), worlds, seed).unwrap()
}

fn run(env: &mut dyn Env, actor: Actor<'_>, episodes: usize) -> EvalReport {
    evaluate_actor(env, actor, episodes, &Device::flex(), EvalOptions::default()).unwrap()
}

/// Hand-computed 95% Wilson score intervals (z = 1.959964).
#[test]
fn wilson_interval_matches_hand_computed_values() {
    let close = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).abs() < 1e-9 && (a[1] - b[1]).abs() < 1e-9;
    assert!(close(wilson_interval(113, 128), [0.8156338407297717, 0.9276831767816524]));
    assert!(close(wilson_interval(0, 10), [0.0, 0.2775328030260577]));
    assert!(close(wilson_interval(10, 10), [0.7224671969739421, 1.0]));
    assert!(close(wilson_interval(1, 2), [0.09453120463920084, 0.9054687953607992]));
    assert_eq!(wilson_interval(0, 0), [0.0, 1.0]);
}

#[test]
fn scripted_reaches_every_goal_and_zero_almost_none() {
    let scripted = run(point_mass(64, 5).as_mut(), Actor::Scripted, 256);
    assert_eq!(scripted.success_rate, 1.0, "{:?}", scripted.ended_by);
    // Zero action: the mass never moves, so only a goal drawn within 5 cm of the start is reached (the
    // chance of that in the 2 m square is pi 0.05^2 / 4 = 0.2%).
    let zero = vec![0.0; 64 * 2];
    let zero = run(point_mass(64, 5).as_mut(), Actor::Fixed(&zero), 256);
    assert!(zero.success_rate < 0.02, "{:?}", zero.ended_by);
    assert!(zero.episode_records.iter().filter(|r| r.ended_by == "success").all(|r| r.steps == 1));

    // The records account for every episode, and the rate and interval for the records.
    for r in [&scripted, &zero] {
        assert_eq!(r.episode_records.len(), 256);
        let wins = r.episode_records.iter().filter(|e| e.ended_by == "success").count();
        assert_eq!(wins as f64 / 256.0, r.success_rate);
        assert_eq!(r.success_interval_95, wilson_interval(wins, 256));
        let mut per_world = [0usize; 64];
        r.episode_records.iter().for_each(|e| per_world[e.world] += 1);
        assert!(per_world.iter().all(|&k| k == 4), "each world ends its quota of 256 / 64");
    }
}

/// An env without a script is refused by name rather than acting with something else.
#[test]
fn scripted_baseline_is_refused_for_an_env_without_a_script() {
    struct NoScript(Box<dyn Env>);
    impl Env for NoScript {
        fn spec(&self) -> &EnvSpec {
            self.0.spec()
        }
        fn reset(&mut self, out: &mut StepBuffers) {
            self.0.reset(out)
        }
        fn step(&mut self, action: &[f32], out: &mut StepBuffers) {
            self.0.step(action, out)
        }
    }
    let mut env = NoScript(point_mass(2, 1));
    let err = evaluate_actor(&mut env, Actor::Scripted, 4, &Device::flex(), EvalOptions::default()).unwrap_err();
    let msg = err.to_string();
    assert!(msg.contains("--baseline") && msg.contains("point_mass") && msg.contains("no scripted"), "{msg}");
}

/// The untrained baseline is the learner's starting network for the seed: the same mean actions.
#[test]
fn untrained_network_is_the_learners_start() {
    let cfg = factory_rl::PpoConfig::default();
    let device = Device::flex();
    let ppo = Ppo::new(&cfg, 4, 4, 2, 11, device.clone());
    let dir = std::env::temp_dir().join(format!("factory-rl-baselines-{}", std::process::id()));
    let path = dir.join("policy.json");
    let env_cfg = factory_envs::EnvConfig::PointMass(PointMassConfig::default());
    let policy = PolicyFile::from_learner(&ppo, point_mass(1, 0).spec(), &env_cfg, 0, 0);
    policy.save(&path).unwrap();
    let policy = PolicyFile::load(&path).unwrap();
    std::fs::remove_dir_all(&dir).ok();
    let untrained = untrained_model(&policy, 11, &device);
    let obs = [0.3f32, -0.2, 0.1, 0.0, -0.5, 0.4, 0.0, 0.2];
    let (start, _) = policy.build(&device, &path).unwrap();
    let mean = |m: &factory_rl::model::ActorCritic| {
        let o = burn::tensor::Tensor::<1>::from_floats(obs.as_slice(), &device).reshape([2, 4]);
        factory_rl::model::to_vec(m.forward(o).0)
    };
    assert_eq!(mean(&untrained), mean(&start));
    let other = untrained_model(&policy, 12, &device);
    assert_ne!(mean(&other), mean(&start), "another seed draws other weights");
    // Evaluated like the policy it stands for.
    let mut env = point_mass(8, 3);
    let r = evaluate(env.as_mut(), &untrained, None, 5.0, 16, &device, EvalOptions::default());
    assert_eq!(r.episodes, 16);
}

/// Each candidate runs on its own worlds (world w takes candidate w mod k) for the same number of episodes,
/// and the best is chosen by successes first.
#[test]
fn constant_sweep_gives_each_candidate_its_worlds() {
    let candidates = constant_candidates(2);
    let mut env = point_mass(2 * candidates.len(), 9);
    let points = sweep_constants(env.as_mut(), &candidates, 3, &Device::flex(), false).unwrap();
    assert_eq!(points.len(), 9);
    for (p, c) in points.iter().zip(&candidates) {
        assert_eq!((&p.action, p.episodes), (c, 6));
    }
    let best = best_point(&points).unwrap();
    assert!(points.iter().all(|p| p.successes <= best.successes));
    let mut odd = point_mass(10, 9);
    assert!(sweep_constants(odd.as_mut(), &candidates, 1, &Device::flex(), false).is_err(), "10 worlds, 9 actions");
}

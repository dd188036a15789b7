//! A config mistake on the command line is refused before anything runs, and the message names the key (with
//! the valid ones) and the file it came from: `factory-train --config FILE --set KEY=VALUE` parsed as the
//! binary parses it (clap), then loaded as the binary loads it (`TrainConfig::load`), and `factory-eval`'s
//! `--set` (env keys only).

use std::path::{Path, PathBuf};

use clap::Parser;
use factory_rl::cli::TrainArgs;
use factory_rl::config::env_with_sets;
use factory_rl::TrainConfig;

fn shipped_config(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs").join(name)
}

/// `factory-train ARGS` up to the loaded config: the error text, or panics if it loads.
fn train_command_line_error(args: &[&str]) -> String {
    let args = TrainArgs::try_parse_from(std::iter::once("factory-train").chain(args.iter().copied()))
        .expect("the command line parses");
    let config = args.config.expect("--config given");
    match TrainConfig::load(&config, &args.sets) {
        Ok(cfg) => panic!("loaded, but should have been refused: {cfg:?}"),
        Err(e) => e.to_string(),
    }
}

fn assert_names(message: &str, words: &[&str]) {
    for w in words {
        assert!(message.contains(w), "the error does not name `{w}`:\n{message}");
    }
}

#[test]
fn unknown_key_in_a_config_file_names_the_key_and_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let shipped = std::fs::read_to_string(shipped_config("point_mass.toml")).unwrap();
    // A misspelt learner key, and a misspelt env key: each refused with the key, the file and the valid key.
    let cases = [("[ppo]", "horizn = 64", "horizon"), ("[env]", "goal_radiu = 0.1", "goal_radius")];
    for (table, line, valid) in cases {
        let path = dir.path().join("typo.toml");
        std::fs::write(&path, shipped.replacen(table, &format!("{table}\n{line}"), 1)).unwrap();
        let key = line.split(' ').next().unwrap();
        let path_text = path.display().to_string();
        let e = train_command_line_error(&["--config", &path_text]);
        assert_names(&e, &[key, valid, &path_text]);
    }
}

#[test]
fn unknown_key_in_a_set_override_names_the_key() {
    let config = shipped_config("point_mass.toml").display().to_string();
    for (set, key, valid) in [
        ("ppo.horizn=64", "horizn", "horizon"),
        ("train.env_cont=8", "env_cont", "env_count"),
        ("env.goal_radiu=0.1", "goal_radiu", "goal_radius"),
        ("sed=3", "sed", "seed"),
    ] {
        let e = train_command_line_error(&["--config", &config, "--set", set]);
        assert_names(&e, &[key, valid]);
    }
    // A known key with a value of the wrong kind names the key too.
    let e = train_command_line_error(&["--config", &config, "--set", "ppo.horizon=long"]);
    assert_names(&e, &["horizon"]);
    // An unknown env type names the valid ones.
    let e = train_command_line_error(&["--config", &config, "--set", "env.type=pointmass"]);
    assert_names(&e, &["pointmass", "point_mass", "franka_nut_bolt"]);
    // A nested key of the Franka env, in a table of its own.
    let screw = shipped_config("screw.toml").display().to_string();
    let e = train_command_line_error(&["--config", &screw, "--set", "env.randomize.hand_angle=[0, 1]"]);
    assert_names(&e, &["hand_angle", "hand_angle_deg"]);
    let e = train_command_line_error(&["--config", &screw, "--set", "env.controller.kpp=3"]);
    assert_names(&e, &["kpp"]);
}

#[test]
fn eval_set_refuses_unknown_and_non_env_keys_by_name() {
    let cfg = TrainConfig::load(&shipped_config("point_mass.toml"), &[]).unwrap();
    let e = env_with_sets(&cfg.env, &["env.max_episode_step=50".into()]).unwrap_err().to_string();
    assert_names(&e, &["max_episode_step", "max_episode_steps"]);
    let e = env_with_sets(&cfg.env, &["ppo.horizon=8".into()]).unwrap_err().to_string();
    assert_names(&e, &["ppo.horizon", "env."]);
    // A valid override is applied, so the refusals above are about the keys.
    let env = env_with_sets(&cfg.env, &["env.max_episode_steps=50".into()]).unwrap();
    let factory_envs::EnvConfig::PointMass(pm) = env else { panic!("{env:?}") };
    assert_eq!(pm.max_episode_steps, 50);
}

//! The whole user path on the point-mass task, through the library code the binaries run: a tiny run trained
//! into a run folder (`factory-train`), its exported policy loaded and evaluated (`factory-eval`), its
//! learning curve drawn (`factory-plot`). Each stage reads what the one before wrote, from disk.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use burn::tensor::Device;
use factory_rl::checkpoint::{write_atomic, PolicyFile};
use factory_rl::config::env_with_sets;
use factory_rl::eval::{evaluate, EvalOptions, EvalReport};
use factory_rl::plot::{plot_svg, read_metrics, smooth};
use factory_rl::run_dir::{checkpoint_path, policy_path, CSV_HEADER};
use factory_rl::session::{run_session, Progress};
use factory_rl::train::{resolve_device, Trainer};
use factory_rl::TrainConfig;

/// Updates of the tiny run.
const UPDATES: usize = 4;
/// Its worlds and horizon: 4 updates x 16 worlds x 16 steps = 1024 env steps.
const ENVS: usize = 16;
const HORIZON: usize = 16;

fn shipped_config(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs").join(name)
}

/// `factory-train --config configs/point_mass.toml --set ... --run-dir RUN`: the config loaded with the
/// overrides, a trainer, and the binary's session (`factory_rl::session::run_session`): the resolved config,
/// one metrics row per update, a checkpoint and the policy every `checkpoint_every` updates and at the end.
fn train(run: &Path) -> TrainConfig {
    let sets: Vec<String> = [
        format!("train.env_count={ENVS}"),
        format!("train.updates={UPDATES}"),
        "train.checkpoint_every=2".into(),
        format!("ppo.horizon={HORIZON}"),
        "ppo.minibatch_size=64".into(),
        "ppo.epochs=2".into(),
        "ppo.device=cpu".into(),
        "seed=7".into(),
        // Episodes of 20 steps end within the run's 64 steps per world, so every update past the first has
        // a success rate to plot.
        "env.max_episode_steps=20".into(),
    ]
    .into();
    let cfg = TrainConfig::load(&shipped_config("point_mass.toml"), &sets).expect("the shipped config loads");
    let (device, _) = resolve_device(cfg.ppo.device).expect("the cpu learner");
    let mut t = Trainer::new(cfg.clone(), device).expect("a trainer");
    std::fs::create_dir_all(run).unwrap();
    let summary = run_session(&mut t, run, Progress::Quiet, &AtomicBool::new(false)).expect("the session runs");
    assert!(!summary.interrupted);
    assert_eq!((summary.updates, summary.env_steps), (UPDATES, (UPDATES * ENVS * HORIZON) as u64));
    cfg
}

/// `factory-eval --policy RUN/policy.json --envs 8 --episodes N --seed S --set env.max_episode_steps=40`: the
/// env rebuilt from the policy file's own config with the override, the spec checked, the mean action.
fn eval(policy: &Path, episodes: usize, seed: u64) -> EvalReport {
    let p = PolicyFile::load(policy).expect("policy.json loads");
    let env_cfg = env_with_sets(&p.env_config, &["env.max_episode_steps=40".into()]).expect("an env.* override");
    let mut env = factory_envs::build(&env_cfg, 8, seed).expect("the policy's env builds");
    p.check_spec(env.spec(), policy).expect("the policy's spec is the env's");
    let device = Device::flex();
    let (model, norm) = p.build(&device, policy).expect("the policy's network builds");
    evaluate(env.as_mut(), &model, norm.as_ref(), p.observation_clip, episodes, &device, EvalOptions::default())
}

#[test]
fn train_export_evaluate_plot() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("runs/point_mass/tiny");
    let cfg = train(&run);

    // The run folder holds what factory-eval, factory-plot and `--resume` read.
    for file in ["config.toml", "metrics.csv", "checkpoint.bin", "policy.json", "provenance.json"] {
        assert!(run.join(file).is_file(), "{file} missing from the run folder {}", run.display());
    }
    // The provenance names the policy by its hash, and the run's seed and counts.
    let prov: factory_rl::run_dir::Provenance =
        serde_json::from_str(&std::fs::read_to_string(run.join("provenance.json")).unwrap()).unwrap();
    let policy_bytes = std::fs::read(run.join("policy.json")).unwrap();
    use sha2::Digest;
    assert_eq!(prov.policy_sha256, format!("{:x}", sha2::Sha256::digest(&policy_bytes)));
    assert_eq!((prov.seed, prov.updates, prov.env_steps), (7, UPDATES, (UPDATES * ENVS * HORIZON) as u64));
    assert_eq!(prov.builds.len(), 1, "{:?}", prov.builds);
    let saved = TrainConfig::load(&run.join("config.toml"), &[]).expect("the saved config.toml loads");
    assert_eq!(saved, cfg, "config.toml is the resolved config, overrides included");
    assert_eq!((saved.train.env_count, saved.ppo.horizon, saved.seed), (ENVS, HORIZON, 7));

    let csv = std::fs::read_to_string(run.join("metrics.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some(CSV_HEADER));
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), UPDATES, "one metrics row per update:\n{csv}");
    for (i, row) in rows.iter().enumerate() {
        assert_eq!(row.len(), CSV_HEADER.split(',').count(), "row {}: {row:?}", i + 1);
        assert_eq!(row[0], (i + 1).to_string(), "the update column");
        assert_eq!(row[1], ((i + 1) * ENVS * HORIZON).to_string(), "the env_steps column");
        // The point mass rolls out on the learner's device (`rollout = "auto"`): the rollout is one stage,
        // nothing waited for per step; it reports no progress.
        let stages: Vec<&str> = row[14].split(' ').map(|kv| kv.split('=').next().unwrap()).collect();
        assert_eq!(stages, ["learn", "rollout_other"], "the stage_seconds column");
        assert_eq!(row[15], "", "the progress_steps column");
    }

    // The checkpoint resumes at the end of the run.
    let resumed = Trainer::resume(&checkpoint_path(&run), Device::flex()).expect("the checkpoint resumes");
    assert_eq!(resumed.updates_done, UPDATES);
    assert_eq!(resumed.env_steps, (UPDATES * ENVS * HORIZON) as u64);
    assert_eq!(resumed.cfg, cfg);

    // The exported policy: the last update's, evaluated on a quota of episodes per world.
    let policy = PolicyFile::load(&policy_path(&run)).unwrap();
    assert_eq!((policy.env.as_str(), policy.updates), ("point_mass", UPDATES));
    assert_eq!(policy.hidden, cfg.ppo.hidden);
    let episodes = 24;
    let report = eval(&policy_path(&run), episodes, 12345);
    assert_eq!(report.episodes, episodes, "{report:?}");
    assert!(!report.stochastic, "the mean action by default");
    assert!(report.success_rate.is_finite() && (0.0..=1.0).contains(&report.success_rate), "{report:?}");
    assert!(report.mean_return.is_finite(), "{report:?}");
    assert_eq!(report.ended_by.0.values().sum::<usize>(), episodes, "each episode counted once: {report:?}");
    let succeeded = report.ended_by.0.get("success").copied().unwrap_or(0);
    assert_eq!(succeeded as f64 / episodes as f64, report.success_rate);
    // What factory-eval prints: for a person, in the point mass's own words (it measures no torque and seats
    // nothing); with --json, one object.
    let summary = report.summary(&policy.env, 8);
    eprint!("{summary}");
    assert!(summary.starts_with("point_mass (mean actions): 24 episodes over 8 worlds"), "{summary}");
    for word in ["NaN", "seated", "torque"] {
        assert!(!summary.contains(word), "the point mass's summary says `{word}`:\n{summary}");
    }
    let json: serde_json::Value = serde_json::from_str(&serde_json::to_string(&report).unwrap()).unwrap();
    assert_eq!(json["episodes"], episodes);
    let again = eval(&policy_path(&run), episodes, 12345);
    assert_eq!(
        (again.success_rate, again.mean_return),
        (report.success_rate, report.mean_return),
        "the same policy, seed and mean actions give the same evaluation"
    );

    // The learning curve from metrics.csv.
    let points = read_metrics(&run.join("metrics.csv")).expect("factory-plot reads metrics.csv");
    assert_eq!(points.len(), UPDATES);
    assert_eq!(points.last().unwrap().env_steps, (UPDATES * ENVS * HORIZON) as f64);
    let smoothed = smooth(&points, 2);
    assert_eq!(smoothed.len(), UPDATES / 2);
    assert!(smoothed.iter().all(|p| p.success_rate.is_finite() && p.mean_return.is_finite()), "{smoothed:?}");
    let svg = plot_svg(&smoothed, "tiny").expect("the curve draws");
    let out = run.join("curve.svg");
    write_atomic(&out, svg.as_bytes()).unwrap();
    let written = std::fs::read_to_string(&out).unwrap();
    assert!(written.starts_with("<svg") && written.trim_end().ends_with("</svg>"), "not a whole SVG");
    // Three panels, each with its curve (plot.rs draws them in one colour, #1F77B4) and its x-axis title.
    assert_eq!(written.matches("stroke=\"#1F77B4\"").count(), 3, "one curve per panel");
    let text_lines = |t: &str| written.lines().filter(|l| *l == t).count();
    assert_eq!(text_lines("env steps"), 2, "two panels against env steps");
    assert_eq!(text_lines("training wall time [h]"), 1, "one panel against wall time");
}

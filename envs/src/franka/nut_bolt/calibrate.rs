//! FrankaCalibrate (paper App. D3) for the Screw task: starts drawn from the reset ranges, each held still
//! for a while, and only the stable ones kept, so that a Screw episode never starts from a grasp that
//! loses the nut by itself. A start is stable when its world's episode does not end during the hold and
//! the nut moves less than `max_slip_mm` relative to the pads' midpoint, in the hand's frame (the paper: 1
//! mm over 1 s). The hand reaches each start by inverse kinematics at the reset, as the env's own draws do,
//! rather than by driving there.
//!
//! The kept states (joints, nut pose, the draw they came from) go to a versioned JSON file
//! ([`CalibrationFile`]); an env with `randomize.starts_file` draws its starts from it uniformly. A file
//! made for other physics (any key that changes a held start: the solver, contacts, materials, grip,
//! geometry, the ranges) is refused naming each key that differs, with both values.

use std::path::Path;

use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};

use super::config::FrankaNutBoltConfig;
use super::task::pad_midpoint;
use super::{FrankaNutBolt, StartDraw};
use crate::env::{Env, StepBuffers};
use crate::error::{EnvError, Result};
use crate::franka::scene::DOF;

/// The file format this build writes and reads.
pub const CALIBRATION_FORMAT: &str = "factory-calibration/1";

/// One stable start.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibratedStart {
    /// Arm and finger joint positions after the hold [rad, m], shape [9].
    pub joint_q: Vec<f32>,
    /// The nut frame's position after the hold [m].
    pub nut_pos: [f32; 3],
    /// The nut frame's orientation after the hold (x, y, z, w).
    pub nut_quat: [f32; 4],
    /// The draw it came from.
    pub draw: StartDraw,
    /// How far the nut moved relative to the pads over the hold [mm].
    pub slip_mm: f32,
}

/// A calibration: the stable starts and how they were found.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrationFile {
    /// [`CALIBRATION_FORMAT`].
    pub format: String,
    /// The env config the starts were drawn and held with.
    pub env_config: FrankaNutBoltConfig,
    /// Control steps each start was held with zero actions.
    pub hold_steps: u32,
    /// The largest slip kept [mm].
    pub max_slip_mm: f32,
    /// Starts drawn (kept or not).
    pub drawn: usize,
    /// The stable starts.
    pub starts: Vec<CalibratedStart>,
}

/// The config's keys that do not change how a held start behaves: an env may differ from its calibration
/// file in these.
const FREE_KEYS: &[&str] = &[
    "max_episode_steps",
    "success_bonus",
    "failure_penalty",
    "far_error",
    "observe_finger_force",
    "observe_previous_action",
    "unidirectional_rot",
    "pos_action_scale",
    "rot_action_scale",
    "force_action_scale",
    "torque_action_scale",
];

fn file_error(path: &Path, reason: String) -> EnvError {
    EnvError::InvalidValue { field: "randomize.starts_file", reason: format!("{}: {reason}", path.display()) }
}

/// The config as a TOML table without the free keys and the starts file.
fn physics_keys(cfg: &FrankaNutBoltConfig) -> toml::Table {
    let mut t = toml::Table::try_from(cfg).expect("a config serialises");
    for k in FREE_KEYS {
        t.remove(*k);
    }
    if let Some(toml::Value::Table(r)) = t.get_mut("randomize") {
        r.remove("starts_file");
    }
    t
}

impl CalibrationFile {
    /// Reads a calibration file, refusing another format.
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| file_error(path, e.to_string()))?;
        let value: serde_json::Value =
            serde_json::from_str(&text).map_err(|e| file_error(path, format!("not JSON: {e}")))?;
        let format = value.get("format").and_then(|f| f.as_str()).unwrap_or("none");
        if format != CALIBRATION_FORMAT {
            return Err(file_error(path, format!("format `{format}`, this build reads `{CALIBRATION_FORMAT}`")));
        }
        let file: Self = serde_json::from_value(value).map_err(|e| file_error(path, e.to_string()))?;
        if file.starts.is_empty() {
            return Err(file_error(path, "holds no stable start".into()));
        }
        if let Some(s) = file.starts.iter().find(|s| s.joint_q.len() != DOF) {
            return Err(file_error(path, format!("a start has {} joints, the Franka {DOF}", s.joint_q.len())));
        }
        Ok(file)
    }

    /// Writes the file atomically.
    pub fn save(&self, path: &Path) -> Result<()> {
        let text = serde_json::to_string(self).map_err(|e| file_error(path, e.to_string()))?;
        factory_engine::fsutil::write_atomic(path, text.as_bytes()).map_err(|e| file_error(path, e.to_string()))
    }

    /// Refuses an env config whose physics differs from the file's, naming each key with both values.
    pub fn check_env(&self, cfg: &FrankaNutBoltConfig, path: &Path) -> Result<()> {
        let (file, env) = (physics_keys(&self.env_config), physics_keys(cfg));
        let mut keys: Vec<&String> = file.keys().chain(env.keys()).collect();
        keys.sort();
        keys.dedup();
        let diffs: Vec<String> = keys
            .into_iter()
            .filter(|k| file.get(*k) != env.get(*k))
            .map(|k| {
                let show = |v: Option<&toml::Value>| v.map_or("unset".to_string(), |v| v.to_string());
                format!("`{k}`: {} in the file, {} in this env", show(file.get(k)), show(env.get(k)))
            })
            .collect();
        if diffs.is_empty() {
            Ok(())
        } else {
            Err(file_error(path, format!("calibrated for other physics: {}", diffs.join("; "))))
        }
    }

    /// Start `i`'s nut pose and joints.
    pub fn start(&self, i: usize) -> ((Vec3, Quat), [f32; DOF], StartDraw) {
        let s = &self.starts[i];
        let mut q = [0.0; DOF];
        q.copy_from_slice(&s.joint_q);
        ((Vec3::from_array(s.nut_pos), Quat::from_array(s.nut_quat)), q, s.draw)
    }
}

/// Draws `rounds x worlds` starts from `cfg`'s ranges (seeded by `seed`), holds each for `hold_steps` control
/// steps with zero actions (the yaw action bidirectional, so zero holds still) and keeps those whose nut
/// slipped less than `max_slip_mm` relative to the pads and whose episode did not end. `progress` is called
/// after each round with the starts drawn and kept so far.
pub fn calibrate(
    cfg: &FrankaNutBoltConfig,
    worlds: usize,
    rounds: usize,
    seed: u64,
    hold_steps: u32,
    max_slip_mm: f32,
    mut progress: impl FnMut(usize, usize),
) -> Result<CalibrationFile> {
    if cfg.randomize.starts_file.is_some() {
        return Err(EnvError::InvalidValue {
            field: "randomize.starts_file",
            reason: "calibration draws from the ranges; unset the starts file".into(),
        });
    }
    let held = FrankaNutBoltConfig {
        unidirectional_rot: false,
        max_episode_steps: cfg.max_episode_steps.max(hold_steps + 1),
        ..cfg.clone()
    };
    let mut env = FrankaNutBolt::new(&held, worlds, seed)?;
    let mut buf = StepBuffers::new(env.spec());
    let zero = vec![0.0f32; worlds * env.spec().action_dim()];
    // Every world's nut relative to the pads' midpoint in the hand's frame [m].
    let relative = |env: &FrankaNutBolt| -> Vec<Vec3> {
        let arm = env.scene().arm();
        (0..worlds)
            .map(|w| {
                let (p, q) = env.scene().nut_pose(w);
                let nut = p + q * env.nut_com_local();
                arm.ee_quat[w].inverse() * (nut - pad_midpoint(arm.ee_pos[w], arm.ee_quat[w]))
            })
            .collect()
    };
    let mut starts = Vec::new();
    for round in 0..rounds {
        env.reset(&mut buf);
        let draws = env.start_draws().to_vec();
        let before = relative(&env);
        let mut ended = vec![false; worlds];
        for _ in 0..hold_steps {
            env.step(&zero, &mut buf);
            for (w, e) in ended.iter_mut().enumerate() {
                *e |= buf.done(w);
            }
        }
        let after = relative(&env);
        for w in (0..worlds).filter(|&w| !ended[w]) {
            let slip_mm = 1e3 * after[w].distance(before[w]);
            if slip_mm < max_slip_mm {
                let (p, q) = env.scene().nut_pose(w);
                starts.push(CalibratedStart {
                    joint_q: env.scene().sim.joints.joint_q[w * DOF..(w + 1) * DOF].to_vec(),
                    nut_pos: p.to_array(),
                    nut_quat: q.to_array(),
                    draw: draws[w],
                    slip_mm,
                });
            }
        }
        progress((round + 1) * worlds, starts.len());
    }
    Ok(CalibrationFile {
        format: CALIBRATION_FORMAT.into(),
        env_config: cfg.clone(),
        hold_steps,
        max_slip_mm,
        drawn: rounds * worlds,
        starts,
    })
}

//! The explicit env registry: configs select an env by `type`.
//!
//! ```toml
//! [env]
//! type = "point_mass"
//! dt = 0.05
//! ```

use serde::{Deserialize, Serialize};

#[cfg(feature = "device")]
use crate::device::DeviceEnv;
use crate::env::Env;
use crate::error::{EnvError, Result};
use crate::franka::nut_bolt::{FrankaNutBolt, FrankaNutBoltConfig};
use crate::point_mass::{PointMass, PointMassConfig};
#[cfg(feature = "device")]
use crate::point_mass_device::PointMassDevice;

/// The registered envs' `type` names.
pub const NAMES: &[&str] = &["point_mass", "franka_nut_bolt"];

/// An env config: the `[env]` table, selected by its `type` key.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum EnvConfig {
    /// [`PointMass`].
    PointMass(PointMassConfig),
    /// [`FrankaNutBolt`] (Factory's nut-and-bolt tasks).
    FrankaNutBolt(FrankaNutBoltConfig),
}

impl EnvConfig {
    /// The config's registered name.
    pub fn name(&self) -> &'static str {
        match self {
            EnvConfig::PointMass(_) => "point_mass",
            EnvConfig::FrankaNutBolt(_) => "franka_nut_bolt",
        }
    }

    /// Reads an `[env]` table, refusing unknown types (listing the valid ones) and unknown keys.
    pub fn from_toml(value: toml::Value) -> Result<Self> {
        let ty = value.get("type").and_then(|t| t.as_str()).map(str::to_owned);
        match ty {
            None => Err(EnvError::Parse(format!("no `type`; valid types: {}", NAMES.join(", ")))),
            Some(t) if !NAMES.contains(&t.as_str()) => Err(EnvError::UnknownType(t)),
            Some(t) => value.clone().try_into().map_err(|e: toml::de::Error| {
                // The tagged enum's error does not say which key; deserialising the variant's own table does
                // (the key, and for a nested one its path). From the parsed table, not from its text: a text
                // rendered again would carry line numbers that are not the config file's.
                let mut table = value.as_table().cloned().unwrap_or_default();
                table.remove("type");
                let table = toml::Value::Table(table);
                let detail = match t.as_str() {
                    "point_mass" => table.try_into::<PointMassConfig>().err(),
                    "franka_nut_bolt" => table.try_into::<FrankaNutBoltConfig>().err(),
                    _ => None,
                };
                EnvError::Parse(detail.map_or_else(|| e.to_string(), |d| d.to_string().trim_end().to_owned()))
            }),
        }
    }
}

/// Builds the env a config describes with `env_count` worlds, seeded by `seed`.
pub fn build(cfg: &EnvConfig, env_count: usize, seed: u64) -> Result<Box<dyn Env>> {
    Ok(match cfg {
        EnvConfig::PointMass(c) => Box::new(PointMass::new(c, env_count, seed)?),
        EnvConfig::FrankaNutBolt(c) => Box::new(FrankaNutBolt::new(c, env_count, seed)?),
    })
}

/// Builds the device-resident implementation of the env a config describes on `device`, where it has one:
/// `point_mass` on any device; `franka_nut_bolt` on burn's wgpu runtime over the engine's device (built with
/// the `wgpu` feature, and unless its config asks for `solve = "host"`). None elsewhere (the host env then
/// runs: on a CPU learner it is the faster). Needs the `device` feature.
#[cfg(feature = "device")]
pub fn build_device(
    cfg: &EnvConfig,
    env_count: usize,
    seed: u64,
    device: &burn::prelude::Device,
) -> Result<Option<Box<dyn DeviceEnv>>> {
    Ok(match cfg {
        EnvConfig::PointMass(c) => Some(Box::new(PointMassDevice::new(c, env_count, seed, device)?)),
        EnvConfig::FrankaNutBolt(c) => franka_device(c, env_count, seed, device)?,
    })
}

#[cfg(feature = "wgpu")]
fn franka_device(
    c: &FrankaNutBoltConfig,
    env_count: usize,
    seed: u64,
    device: &burn::prelude::Device,
) -> Result<Option<Box<dyn DeviceEnv>>> {
    use crate::franka::device_env::{is_wgpu, FrankaNutBoltDevice};
    use factory_engine::sim::CoupledSolve;
    if c.solve == CoupledSolve::Host || !is_wgpu(device) {
        return Ok(None);
    }
    Ok(Some(Box::new(FrankaNutBoltDevice::new(c, env_count, seed, device)?)))
}

#[cfg(all(feature = "device", not(feature = "wgpu")))]
fn franka_device(
    _: &FrankaNutBoltConfig,
    _: usize,
    _: u64,
    _: &burn::prelude::Device,
) -> Result<Option<Box<dyn DeviceEnv>>> {
    Ok(None)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_type_lists_valid_ones() {
        let v: toml::Value = toml::from_str("type = \"pointmass\"").unwrap();
        let e = EnvConfig::from_toml(v).unwrap_err().to_string();
        assert!(e.contains("pointmass") && e.contains("point_mass"), "{e}");
    }

    #[test]
    fn unknown_key_is_named() {
        let v: toml::Value = toml::from_str("type = \"point_mass\"\ngoal_radiu = 0.1").unwrap();
        let e = EnvConfig::from_toml(v).unwrap_err().to_string();
        assert!(e.contains("goal_radiu") && e.contains("goal_radius"), "{e}");
    }

    /// Regression: the error quoted `line 12` of a table rendered again from the parsed config, while the
    /// key stood on line 13 of the user's file.
    #[test]
    fn unknown_key_error_quotes_no_line_of_another_text() {
        let text = "type = \"franka_nut_bolt\"\n# a comment\n\nsubstep = 3\n";
        let e = EnvConfig::from_toml(toml::from_str(text).unwrap()).unwrap_err().to_string();
        assert!(e.contains("`substep`") && e.contains("`substeps`"), "{e}");
        assert!(!e.contains("line"), "{e}");
    }

    #[test]
    fn wrong_type_in_a_nested_table_names_its_path() {
        let text = "type = \"franka_nut_bolt\"\n[randomize]\nhand_angle_deg = \"wide\"\n";
        let e = EnvConfig::from_toml(toml::from_str(text).unwrap()).unwrap_err().to_string();
        assert!(e.contains("randomize.hand_angle_deg"), "{e}");
    }

    #[test]
    fn wrong_type_names_the_key() {
        let v: toml::Value = toml::from_str("type = \"point_mass\"\ndt = \"fast\"").unwrap();
        let e = EnvConfig::from_toml(v).unwrap_err().to_string();
        assert!(e.contains("dt") && e.contains("f32"), "{e}");
    }

    #[test]
    fn builds_with_defaults() {
        let v: toml::Value = toml::from_str("type = \"point_mass\"\ndt = 0.02").unwrap();
        let cfg = EnvConfig::from_toml(v).unwrap();
        let env = build(&cfg, 16, 1).unwrap();
        assert_eq!(env.spec().env_count, 16);
        assert_eq!(env.spec().observation_dim(), 4);
    }
}

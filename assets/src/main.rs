//! `factory-assets`: writes Factory's parts as OBJ + URDF.
//!
//! ```text
//! factory-assets nut-bolt --size M16 --fit tight --out DIR [--segments 192]
//! factory-assets peg-hole --size 4 --fit tight --out DIR [--segments 128]
//! factory-assets bowl --out DIR [--segments 40]
//! factory-assets torus --out DIR [--segments 64]
//! ```
//!
//! The flags are `factory-assets --help` (docs/CLI.md); the subcommands live in `factory_assets::cli`.

use clap::Parser;
use factory_assets::cli::{run, Cli};

fn main() -> anyhow::Result<()> {
    run(Cli::parse())
}

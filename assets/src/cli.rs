//! The `factory-assets` command line (clap) and what each subcommand writes; here in the library so that
//! docs/CLI.md is generated from and checked against it (assets/tests/cli_doc.rs).

use crate::{
    bowl, nut_bolt, peg_hole, torus, BowlOptions, Fit, IsoSize, Part, PegHoleOptions, PegSize, ThreadOptions,
    TorusOptions,
};
use anyhow::Context;
use clap::{Parser, Subcommand};
use std::path::{Path, PathBuf};

// `factory-assets`' arguments (a doc comment here would become the command's about text).
#[derive(Parser)]
#[command(
    name = "factory-assets",
    version,
    about = "Procedural ISO nuts, bolts, pegs and holes, bowls and toruses as OBJ + URDF"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

// The part to write: each variant's doc comment is its `--help` summary.
#[derive(Subcommand)]
pub enum Command {
    /// Hex nut and bolt, assembled (nut seated on the bolt head).
    NutBolt {
        /// Thread size: M4, M8, M12, M16, M20.
        #[arg(long, value_parser = parse::<IsoSize>)]
        size: IsoSize,
        /// End of the ISO 965-1 6H/6g tolerance band: tight or loose.
        #[arg(long, value_parser = parse::<Fit>)]
        fit: Fit,
        /// Output directory (created if missing).
        #[arg(long)]
        out: PathBuf,
        /// Angular segments per thread turn (multiple of 12, 24..=4096).
        #[arg(long, default_value_t = ThreadOptions::default().segments_per_turn)]
        segments: usize,
    },
    /// Round peg and hole block, assembled.
    PegHole {
        /// Nominal diameter in mm: 4, 8, 12, 16.
        #[arg(long, value_parser = parse::<PegSize>)]
        size: PegSize,
        /// Peg diameter at the tight or loose end of the band.
        #[arg(long, value_parser = parse::<Fit>)]
        fit: Fit,
        /// Output directory (created if missing).
        #[arg(long)]
        out: PathBuf,
        /// Angular segments around the axis (multiple of 8, 16..=4096).
        #[arg(long, default_value_t = PegHoleOptions::default().segments)]
        segments: usize,
    },
    /// Bowl of the bowls pile (100 mm, ABS; factory_assets::BowlOptions defaults).
    Bowl {
        /// Output directory (created if missing).
        #[arg(long)]
        out: PathBuf,
        /// Angular segments around the axis (8..=4096).
        #[arg(long, default_value_t = BowlOptions::default().segments)]
        segments: usize,
    },
    /// Torus of the toruses pile (48 mm, ABS; factory_assets::TorusOptions defaults).
    Torus {
        /// Output directory (created if missing).
        #[arg(long)]
        out: PathBuf,
        /// Angular segments around the axis (8..=4096).
        #[arg(long, default_value_t = TorusOptions::default().segments)]
        segments: usize,
    },
}

/// A value by its `FromStr`, the error as text for clap.
fn parse<T: std::str::FromStr<Err = crate::AssetError>>(s: &str) -> Result<T, String> {
    s.parse::<T>().map_err(|e| e.to_string())
}

/// Writes `part` as OBJ + URDF into `out` and prints a line per file.
fn write(part: &Part, out: &Path) -> anyhow::Result<()> {
    let files = part.write(out).with_context(|| format!("writing {} to {}", part.name, out.display()))?;
    let mp = &part.mass_properties;
    for path in [&files.obj, &files.urdf] {
        println!(
            "{}: {} triangles, mass {:.6} kg, volume {:.6e} m^3",
            path.display(),
            part.mesh.triangle_count(),
            mp.mass,
            mp.volume
        );
    }
    Ok(())
}

/// Writes the parts `cli` names.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::NutBolt { size, fit, out, segments } => {
            let opts = ThreadOptions { segments_per_turn: segments, ..Default::default() };
            let nb = nut_bolt(size, fit, &opts)?;
            write(&nb.nut, &out)?;
            write(&nb.bolt, &out)?;
        }
        Command::PegHole { size, fit, out, segments } => {
            let ph = peg_hole(size, fit, &PegHoleOptions { segments, ..Default::default() })?;
            write(&ph.peg, &out)?;
            write(&ph.hole, &out)?;
        }
        Command::Bowl { out, segments } => write(&bowl(&BowlOptions { segments, ..Default::default() })?.part, &out)?,
        Command::Torus { out, segments } => {
            write(&torus(&TorusOptions { segments, ..Default::default() })?.part, &out)?
        }
    }
    Ok(())
}

//! The `factory-bench` command line: one module per subcommand, each with its clap arguments and its run
//! function. Every subcommand prints a short summary for a person by default and the report as one JSON
//! object with `--json` (what scripts/ and the raw files under docs/ read).

pub mod contacts;
pub mod controllers;
pub mod pareto;
pub mod scene;
pub mod summary;

use anyhow::Result;
use clap::{Parser, Subcommand};

pub use summary::Summary;

// `factory-bench`'s arguments (a doc comment here would become the command's about text).
#[derive(Parser)]
#[command(name = "factory-bench", about = "Benchmarks of the factory-rs contact pipeline")]
pub struct Cli {
    #[command(subcommand)]
    pub cmd: Cmd,
}

// The subcommands: each variant's doc comment is its `--help` summary.
#[derive(Subcommand)]
pub enum Cmd {
    /// Whole frames (contacts + solver on the GPU) of a paper scene (Table II) with its accuracy figures.
    Scene(scene::SceneArgs),
    /// Speed against error: sweeps the bolt SDF, patch budget, substeps and position iterations one at a
    /// time around the paper's baseline (frictionless nut, analytic descent as reference) and writes a
    /// CSV and an SVG plot with the Pareto front (docs/BENCHMARKS.md).
    Pareto(pareto::ParetoCmdArgs),
    /// Cost of a control step for the Franka at N worlds: the articulation quantities the controllers read
    /// (fingertip pose, Jacobian, mass matrix, gravity; `ArmBatch::from_articulation`) and each of the
    /// seven controllers' torques, on the host; then the same on the device (the articulation kernel's
    /// dynamics and the task-space controllers' kernel).
    Controllers(controllers::ControllersArgs),
    /// Contact generation + reduction for N parallel copies of a shape pair (paper Table I).
    Contacts(contacts::ContactsArgs),
}

/// Prints `report` as one JSON line (`--json`, for scripts) or, for a person, as `summary`.
pub fn print_report<R: serde::Serialize>(report: &R, json: bool, summary: impl FnOnce(&R) -> Summary) -> Result<()> {
    if json {
        println!("{}", serde_json::to_string(report)?);
    } else {
        print!("{}", summary(report));
    }
    Ok(())
}

//! `factory-bench`: measurements behind docs/BENCHMARKS.md (paper Tables I and II).
//!
//! `factory-bench contacts --pair nut-bolt --size M16 --fit tight --worlds 64 --json` times contact
//! handling (generation + reduction, one 1/60 s frame) for N parallel copies of a pair and reports the
//! candidates, contacts and patches per pair. Each subcommand's arguments and run live in
//! `factory_bench::cli`; this only dispatches.

use anyhow::Result;
use clap::Parser;
use factory_bench::cli::{contacts, controllers, pareto, scene, Cli, Cmd};

fn main() -> Result<()> {
    match Cli::parse().cmd {
        Cmd::Scene(args) => scene::run(&args),
        Cmd::Pareto(args) => pareto::run(&args),
        Cmd::Controllers(args) => controllers::run(&args),
        Cmd::Contacts(args) => contacts::run(&args),
    }
}

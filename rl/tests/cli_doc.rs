//! docs/CLI.md's `factory-train`, `factory-eval` and `factory-plot` sections are the binaries' `--help`
//! (see assets/tests/support/cli_doc.rs; regenerate with `FACTORY_BLESS=1`).

#[path = "../../assets/tests/support/cli_doc.rs"]
mod cli_doc;

use clap::CommandFactory;
use factory_rl::cli::{EvalArgs, PlotArgs, TrainArgs};

#[test]
fn cli_md_matches_the_help() {
    cli_doc::check(vec![
        ("factory-train", TrainArgs::command()),
        ("factory-eval", EvalArgs::command()),
        ("factory-plot", PlotArgs::command()),
    ]);
}

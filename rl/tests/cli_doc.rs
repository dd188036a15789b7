//! docs/CLI.md's `factory-train`, `factory-eval`, `factory-plot` and `factory-calibrate` sections are the binaries' `--help`
//! (see assets/tests/support/cli_doc.rs; regenerate with `FACTORY_BLESS=1`).

#[path = "../../assets/tests/support/cli_doc.rs"]
mod cli_doc;

use clap::CommandFactory;
use factory_rl::cli::{CalibrateArgs, EvalArgs, PlotArgs, TrainArgs};

#[test]
fn cli_md_matches_the_help() {
    cli_doc::check(vec![
        ("factory-train", TrainArgs::command()),
        ("factory-eval", EvalArgs::command()),
        ("factory-plot", PlotArgs::command()),
        ("factory-calibrate", CalibrateArgs::command()),
    ]);
}

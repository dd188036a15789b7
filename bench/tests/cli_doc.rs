//! docs/CLI.md's `factory-bench` section is the binary's `--help` and each subcommand's (see
//! assets/tests/support/cli_doc.rs; regenerate with `FACTORY_BLESS=1`).

#[path = "../../assets/tests/support/cli_doc.rs"]
mod cli_doc;

use clap::CommandFactory;

#[test]
fn cli_md_matches_the_help() {
    cli_doc::check(vec![("factory-bench", factory_bench::cli::Cli::command())]);
}

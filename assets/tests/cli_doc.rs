//! docs/CLI.md's `factory-assets` section is the binary's `--help` (see support/cli_doc.rs; regenerate with
//! `FACTORY_BLESS=1`).

#[path = "support/cli_doc.rs"]
mod cli_doc;

use clap::CommandFactory;

#[test]
fn cli_md_matches_the_help() {
    cli_doc::check(vec![("factory-assets", factory_assets::cli::Cli::command())]);
}

//! docs/CLI.md against the binaries' clap definitions: each binary's section is its `--help` and each
//! subcommand's `--help` (clap's long help), in fenced blocks between `<!-- begin NAME -->` and
//! `<!-- end NAME -->`. The check renders them in memory and fails naming the first command whose text
//! differs; with `FACTORY_BLESS=1` it rewrites the sections instead. Shared by the cli_doc tests of
//! factory-assets, factory-bench and factory-rl (each includes this file).

use std::path::PathBuf;

use clap::Command;

/// How to regenerate docs/CLI.md.
pub const BLESS: &str =
    "FACTORY_BLESS=1 cargo test --release -p factory-assets -p factory-bench -p factory-rl --test cli_doc";

/// Help is rendered at this width, whatever the terminal (clap's default without its `wrap_help` feature).
const WIDTH: usize = 100;

/// The file the sections live in.
pub fn doc_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../docs/CLI.md")
}

/// `cmd` and every subcommand below it (clap's own `help` subcommand left out), each as its full name
/// (`factory-bench scene`) and its Markdown: a heading and the long help in a text block.
pub fn blocks(cmd: Command) -> Vec<(String, String)> {
    let name = cmd.get_name().to_string();
    let mut cmd = fixed_width(cmd.bin_name(name));
    cmd.build();
    let mut out = Vec::new();
    walk(&mut cmd, 2, &mut out);
    out
}

fn fixed_width(cmd: Command) -> Command {
    let subs: Vec<String> = cmd.get_subcommands().map(|s| s.get_name().to_string()).collect();
    subs.into_iter().fold(cmd.term_width(WIDTH), |c, s| c.mut_subcommand(s, fixed_width))
}

fn walk(cmd: &mut Command, level: usize, out: &mut Vec<(String, String)>) {
    let name = cmd.get_bin_name().unwrap_or(cmd.get_name()).to_string();
    let help = cmd.render_long_help().to_string();
    let md = format!("{} `{name}`\n\n```text\n{}\n```\n", "#".repeat(level), help.trim_end());
    out.push((name, md));
    for sub in cmd.get_subcommands_mut().filter(|s| s.get_name() != "help") {
        walk(sub, level + 1, out);
    }
}

fn begin(binary: &str) -> String {
    format!("<!-- begin {binary} -->\n")
}

fn end(binary: &str) -> String {
    format!("<!-- end {binary} -->\n")
}

/// The text between `binary`'s markers in `doc` (None: no section).
fn section<'a>(doc: &'a str, binary: &str) -> Option<&'a str> {
    let from = doc.find(&begin(binary))? + begin(binary).len();
    let to = from + doc[from..].find(&end(binary))?;
    Some(&doc[from..to])
}

/// Checks (or with `FACTORY_BLESS=1` rewrites) the sections of `binaries`, each its name and its clap
/// command, in docs/CLI.md.
pub fn check(binaries: Vec<(&str, Command)>) {
    let path = doc_path();
    let bless = std::env::var("FACTORY_BLESS").is_ok_and(|v| v == "1");
    let mut doc = std::fs::read_to_string(&path).unwrap_or_default();
    let mut problems = Vec::new();
    for (binary, cmd) in binaries {
        let blocks = blocks(cmd);
        let want: String = blocks.iter().map(|(_, md)| format!("\n{md}\n")).collect();
        match section(&doc, binary) {
            Some(have) if have == want => {}
            _ if bless => doc = replace_section(&doc, binary, &want),
            None => problems.push(format!("docs/CLI.md has no section for `{binary}`")),
            Some(have) => {
                let first = blocks.iter().find(|(_, md)| !have.contains(md.as_str()));
                problems.push(match first {
                    Some((name, _)) => format!("docs/CLI.md differs from `{name} --help`"),
                    None => format!("docs/CLI.md's section for `{binary}` has text its commands do not print"),
                });
            }
        }
    }
    if bless {
        std::fs::write(&path, doc).unwrap_or_else(|e| panic!("writing {}: {e}", path.display()));
        return;
    }
    assert!(problems.is_empty(), "{}; regenerate it with\n  {BLESS}", problems.join("; "));
}

/// `doc` with `binary`'s section set to `text` (a new section goes at the end).
fn replace_section(doc: &str, binary: &str, text: &str) -> String {
    let whole = format!("{}{text}{}", begin(binary), end(binary));
    match (doc.find(&begin(binary)), section(doc, binary)) {
        (Some(from), Some(old)) => {
            let to = from + begin(binary).len() + old.len() + end(binary).len();
            format!("{}{whole}{}", &doc[..from], &doc[to..])
        }
        _ => format!("{}{}{whole}", doc, if doc.is_empty() || doc.ends_with("\n\n") { "" } else { "\n" }),
    }
}

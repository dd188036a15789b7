//! The rules the sources keep so that a newcomer can read them (docs/ARCHITECTURE.md): no source file
//! outside the tests over [`MAX_FILE_LINES`], no function over [`MAX_FN_LINES`], and no comment that points
//! outside the repository, names an issue or dates a measurement (dates and history live in docs/ and git).

use std::path::{Path, PathBuf};

use syn::visit::Visit;

/// Lines a non-test source file may have.
const MAX_FILE_LINES: usize = 900;
/// Lines a function may span, signature to closing brace (clippy's `too_many_lines` counts less: it skips
/// blank and comment lines).
const MAX_FN_LINES: usize = 150;
/// The crates' folders.
const CRATES: [&str; 7] = ["engine", "assets", "controllers", "envs", "rl", "bench", "tests"];

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Every file under `dir` whose name ends with one of `exts`, skipping build output.
fn files(dir: &Path, exts: &[&str], out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for e in entries.flatten() {
        let p = e.path();
        if p.is_dir() {
            if p.file_name().is_some_and(|n| n != "target") {
                files(&p, exts, out);
            }
        } else if exts.iter().any(|x| p.to_string_lossy().ends_with(x)) {
            out.push(p);
        }
    }
}

fn rust_files() -> Vec<PathBuf> {
    let mut out = Vec::new();
    for c in CRATES {
        files(&root().join(c), &[".rs"], &mut out);
    }
    assert!(out.len() > 100, "found only {} Rust files under {}", out.len(), root().display());
    out
}

fn rel(p: &Path) -> String {
    p.strip_prefix(root()).unwrap_or(p).display().to_string()
}

/// A file of tests: in a crate's `tests/` folder, or the test crate itself.
fn is_test_file(p: &Path) -> bool {
    let r = rel(p);
    r.starts_with("tests/") || r.split('/').nth(1) == Some("tests")
}

#[test]
fn no_source_file_outside_the_tests_is_over_900_lines() {
    let long: Vec<String> = rust_files()
        .iter()
        .filter(|p| !is_test_file(p))
        .filter_map(|p| {
            let n = std::fs::read_to_string(p).unwrap().lines().count();
            (n > MAX_FILE_LINES).then(|| format!("{}: {n} lines", rel(p)))
        })
        .collect();
    assert!(long.is_empty(), "over {MAX_FILE_LINES} lines (split them):\n{}", long.join("\n"));
}

/// Collects the functions longer than [`MAX_FN_LINES`].
struct LongFns<'a> {
    file: &'a str,
    found: Vec<String>,
}

impl LongFns<'_> {
    fn check(&mut self, name: &syn::Ident, span: proc_macro2::Span) {
        let lines = span.end().line - span.start().line + 1;
        if lines > MAX_FN_LINES {
            self.found.push(format!("{}:{} fn {name}: {lines} lines", self.file, span.start().line));
        }
    }
}

impl<'ast> Visit<'ast> for LongFns<'_> {
    fn visit_item_fn(&mut self, f: &'ast syn::ItemFn) {
        self.check(&f.sig.ident, syn::spanned::Spanned::span(f));
        syn::visit::visit_item_fn(self, f);
    }
    fn visit_impl_item_fn(&mut self, f: &'ast syn::ImplItemFn) {
        self.check(&f.sig.ident, syn::spanned::Spanned::span(f));
        syn::visit::visit_impl_item_fn(self, f);
    }
    fn visit_trait_item_fn(&mut self, f: &'ast syn::TraitItemFn) {
        if f.default.is_some() {
            self.check(&f.sig.ident, syn::spanned::Spanned::span(f));
        }
        syn::visit::visit_trait_item_fn(self, f);
    }
}

#[test]
fn no_function_is_over_150_lines() {
    let mut found = Vec::new();
    for p in rust_files() {
        let text = std::fs::read_to_string(&p).unwrap();
        let file = syn::parse_file(&text).unwrap_or_else(|e| panic!("{}: {e}", rel(&p)));
        let name = rel(&p);
        let mut v = LongFns { file: &name, found: Vec::new() };
        v.visit_file(&file);
        found.extend(v.found);
    }
    assert!(found.is_empty(), "functions over {MAX_FN_LINES} lines (split them):\n{}", found.join("\n"));
}

/// The rule's own check: a function one line over the limit is found, one at the limit is not.
#[test]
fn the_function_length_rule_counts_signature_to_closing_brace() {
    let body = |lines: usize| format!("fn f() {{\n{}}}\n", "    let _x = 1;\n".repeat(lines - 2));
    for (lines, found) in [(MAX_FN_LINES, 0), (MAX_FN_LINES + 1, 1)] {
        let mut v = LongFns { file: "t.rs", found: Vec::new() };
        v.visit_file(&syn::parse_file(&body(lines)).unwrap());
        assert_eq!(v.found.len(), found, "a {lines}-line function: {:?}", v.found);
    }
}

/// What no comment in the sources, shaders, configs or scripts says, and why.
fn forbidden(line: &str) -> Option<&'static str> {
    let l = line.to_lowercase();
    if l.contains("design.md") || l.contains("design section") || l.contains("../shared") {
        return Some("points outside the repository (docs/ARCHITECTURE.md is the map)");
    }
    let words: Vec<&str> = l.split(|c: char| !c.is_ascii_alphanumeric()).collect();
    if words.windows(2).any(|w| w[0] == "issue" && !w[1].is_empty() && w[1].chars().all(|c| c.is_ascii_digit())) {
        return Some("names an issue (say what holds instead)");
    }
    let b = line.as_bytes();
    let dated = (0..b.len().saturating_sub(9)).any(|i| {
        let d = |k: usize| b[i + k].is_ascii_digit();
        b[i] == b'2' && b[i + 1] == b'0' && d(2) && d(3) && b[i + 4] == b'-' && d(5) && d(6) && b[i + 7] == b'-' && d(8)
    });
    if dated {
        return Some("dates a measurement (dates go to docs/ and git)");
    }
    None
}

/// Comment lines that keep a date for a reason: a test vector of the UTC stamp format.
const DATED_EXCEPTIONS: [(&str, &str); 1] = [("rl/src/run_dir.rs", "2026-12-04 05:28:58 UTC")];

#[test]
fn comments_do_not_point_outside_name_issues_or_date_measurements() {
    let mut paths = rust_files();
    for c in CRATES {
        files(&root().join(c), &[".wgsl", "Cargo.toml"], &mut paths);
    }
    files(&root().join("configs"), &[".toml"], &mut paths);
    files(&root().join("scripts"), &[".sh", ".py"], &mut paths);
    paths.push(root().join("Cargo.toml"));
    let mut found = Vec::new();
    for p in &paths {
        let name = rel(p);
        for (i, line) in std::fs::read_to_string(p).unwrap().lines().enumerate() {
            let t = line.trim_start();
            let comment = t.starts_with("//") || (t.starts_with('#') && !name.ends_with(".rs"));
            if !comment || DATED_EXCEPTIONS.iter().any(|(f, t)| name == *f && line.contains(t)) {
                continue;
            }
            if let Some(why) = forbidden(line) {
                found.push(format!("{name}:{}: {why}: {}", i + 1, line.trim()));
            }
        }
    }
    assert!(found.is_empty(), "{} comment lines break the rules:\n{}", found.len(), found.join("\n"));
}

/// The rule's own check on lines it must catch and lines it must let pass.
#[test]
fn the_comment_rule_catches_outside_paths_issue_numbers_and_dates() {
    for bad in [
        "// see ../shared/DESIGN.md section 4",
        "/// Issue 21: the gripper holds",
        "// measured 64 of 64 (2026-12-04, commit f4fc108)",
    ] {
        assert!(forbidden(bad).is_some(), "not caught: {bad}");
    }
    for good in ["// the issue is the friction", "/// 2 substeps x 32 iterations", "// docs/ARCHITECTURE.md section 6"]
    {
        assert!(forbidden(good).is_none(), "caught: {good}");
    }
}

//! Records the commit the crate is built from (`FACTORY_BUILD_COMMIT`, `git describe --always --dirty`;
//! `unknown` outside a git checkout) for the provenance of evaluation reports.

use std::process::Command;

fn main() {
    let commit = Command::new("git")
        .args(["describe", "--always", "--dirty", "--abbrev=12"])
        .output()
        .ok()
        .filter(|o| o.status.success())
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| "unknown".into());
    println!("cargo:rustc-env=FACTORY_BUILD_COMMIT={commit}");
    // Rebuild when HEAD moves or the working tree's index changes (a commit, a checkout, `git add`).
    let git_dir = Command::new("git")
        .args(["rev-parse", "--absolute-git-dir"])
        .output()
        .ok()
        .filter(|o| o.status.success())
        .and_then(|o| String::from_utf8(o.stdout).ok());
    if let Some(dir) = git_dir {
        let dir = std::path::Path::new(dir.trim());
        for f in ["HEAD", "index", "refs/heads", "packed-refs"] {
            if dir.join(f).exists() {
                println!("cargo:rerun-if-changed={}", dir.join(f).display());
            }
        }
    } else {
        println!("cargo:rerun-if-changed=build.rs");
    }
}

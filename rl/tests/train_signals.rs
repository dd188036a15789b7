//! `factory-train` as a user runs it: a scheduler's SIGTERM (as Ctrl-C) ends the run after the update in
//! progress with a checkpoint and the policy written, and `--resume` continues it. Unix only (signals).
#![cfg(unix)]

use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn updates_in(csv: &std::path::Path) -> usize {
    std::fs::read_to_string(csv).map(|s| s.lines().count().saturating_sub(1)).unwrap_or(0)
}

#[test]
fn sigterm_saves_the_run_and_resume_continues_it() {
    let exe = env!("CARGO_BIN_EXE_factory-train");
    let config = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../configs/point_mass.toml");
    let run = std::env::temp_dir().join(format!("factory-rl-sigterm-{}", std::process::id()));
    std::fs::remove_dir_all(&run).ok();
    // Far more updates than run before the signal, so the run can only end by the signal.
    let mut child = Command::new(exe)
        .args(["--config", config.to_str().unwrap(), "--updates", "100000", "--json", "--run-dir"])
        .arg(&run)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("factory-train starts");
    let csv = run.join("metrics.csv");
    let t0 = Instant::now();
    while updates_in(&csv) < 2 {
        assert!(t0.elapsed() < Duration::from_secs(120), "no update logged within 120 s");
        assert!(child.try_wait().unwrap().is_none(), "factory-train exited before the signal");
        std::thread::sleep(Duration::from_millis(50));
    }
    // The shell's built-in kill (a fresh machine may have no kill executable).
    let status = Command::new("sh").args(["-c", &format!("kill -TERM {}", child.id())]).status().expect("sh runs");
    assert!(status.success());
    let out = child.wait_with_output().expect("factory-train exits");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "exit status {:?}; stderr:\n{stderr}", out.status);
    assert!(stderr.contains("interrupted at update"), "stderr:\n{stderr}");
    let saved = updates_in(&csv);
    assert!((2..100000).contains(&saved), "{saved} updates logged");
    assert!(run.join("checkpoint.bin").is_file() && run.join("policy.json").is_file());

    // The resumed run starts from the saved update and logs the next ones after it.
    let out = Command::new(exe)
        .args(["--resume", run.to_str().unwrap(), "--updates", &(saved + 2).to_string(), "--json"])
        .output()
        .expect("factory-train resumes");
    assert!(out.status.success(), "resume failed: {}", String::from_utf8_lossy(&out.stderr));
    let rows: Vec<String> = std::fs::read_to_string(&csv)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').next().unwrap().to_string())
        .collect();
    let expected: Vec<String> = (1..=saved + 2).map(|u| u.to_string()).collect();
    assert_eq!(rows, expected, "metrics.csv's update column after the resume");
    std::fs::remove_dir_all(&run).ok();
}

//! The `factory-assets` binary: files written, the summary lines, and clear errors for bad values.

use std::path::PathBuf;
use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_factory-assets"))
}

fn out_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("factory-assets-cli-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

#[test]
fn nut_bolt_writes_obj_and_urdf_and_prints_one_line_per_file() {
    let dir = out_dir("nb");
    let out = bin()
        .args(["nut-bolt", "--size", "M8", "--fit", "loose", "--segments", "48", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let stdout = String::from_utf8(out.stdout).unwrap();
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(lines.len(), 4, "{stdout}");
    for (line, file) in
        lines.iter().zip(["nut_m8_loose.obj", "nut_m8_loose.urdf", "bolt_m8_loose.obj", "bolt_m8_loose.urdf"])
    {
        assert!(
            line.contains(file) && line.contains("triangles") && line.contains("kg") && line.contains("m^3"),
            "{line}"
        );
        assert!(dir.join(file).is_file(), "{file} missing");
    }
    let urdf = std::fs::read_to_string(dir.join("bolt_m8_loose.urdf")).unwrap();
    assert!(urdf.contains("<sdf resolution=\"512\"/>") && urdf.contains("filename=\"bolt_m8_loose.obj\""));
    let obj = std::fs::read_to_string(dir.join("nut_m8_loose.obj")).unwrap();
    let faces = obj.lines().filter(|l| l.starts_with("f ")).count();
    assert!(lines[0].contains(&format!(": {faces} triangles")), "{} vs {faces}", lines[0]);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn peg_hole_writes_both_parts() {
    let dir = out_dir("ph");
    let out = bin().args(["peg-hole", "--size", "4", "--fit", "tight", "--out"]).arg(&dir).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    for f in ["round_peg_4mm_tight.obj", "round_peg_4mm_tight.urdf", "round_hole_4mm.obj", "round_hole_4mm.urdf"] {
        assert!(dir.join(f).is_file(), "{f} missing");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

fn fails_with(args: &[&str], needle: &str) {
    let dir = out_dir("bad");
    let out = bin().args(args).arg("--out").arg(&dir).output().unwrap();
    assert!(!out.status.success(), "{args:?} should fail");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains(needle), "{args:?}: {stderr}");
    assert!(!dir.exists(), "{args:?} wrote files");
}

#[test]
fn bad_values_list_the_valid_ones() {
    fails_with(&["nut-bolt", "--size", "M5", "--fit", "tight"], "unknown size M5; valid: M4, M8, M12, M16, M20");
    fails_with(&["nut-bolt", "--size", "M16", "--fit", "snug"], "unknown fit snug; valid: tight, loose");
    fails_with(&["nut-bolt", "--size", "M16", "--fit", "tight", "--segments", "100"], "multiple of 12");
    fails_with(&["peg-hole", "--size", "5", "--fit", "tight"], "unknown size 5; valid: 4, 8, 12, 16");
    fails_with(&["peg-hole", "--size", "8", "--fit", "tight", "--segments", "12"], "multiple of 8");
}

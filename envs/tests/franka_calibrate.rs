//! FrankaCalibrate for the Screw task (franka::nut_bolt::calibrate): stable starts kept from Table III's
//! ranges, written to a versioned file, drawn from by an env, and refused for other physics or formats.

use factory_envs::franka::nut_bolt::calibrate::{calibrate, CalibrationFile, CALIBRATION_FORMAT};
use factory_envs::franka::nut_bolt::ScrewRandomization;
use factory_envs::{Env, FrankaNutBolt, FrankaNutBoltConfig, StepBuffers};

fn table_iii() -> FrankaNutBoltConfig {
    FrankaNutBoltConfig { balanced_grip: true, randomize: ScrewRandomization::table_iii(), ..Default::default() }
}

/// One round of 4 starts held 1 s: the kept ones slipped under the bound, the file round-trips, an env
/// reading it starts every world from one of its states (nut pose and joints exactly, the draw recorded),
/// and a file for other physics or another format is refused naming what differs.
#[test]
fn calibrated_starts_are_kept_written_and_drawn_from() {
    let cfg = table_iii();
    let mut calls = Vec::new();
    let file = calibrate(&cfg, 4, 1, 3, 60, 1.0, |drawn, kept| calls.push((drawn, kept))).unwrap();
    assert_eq!((file.format.as_str(), file.drawn, file.hold_steps), (CALIBRATION_FORMAT, 4, 60));
    assert_eq!(calls, vec![(4, file.starts.len())]);
    assert!(!file.starts.is_empty(), "no stable start among 4 Table III draws");
    assert!(file.starts.iter().all(|s| s.slip_mm < 1.0 && s.joint_q.len() == 9));
    assert!(file.starts.iter().any(|s| s.draw.nut_in_gripper_yaw_deg != 0.0), "the draws are recorded");

    let dir = std::env::temp_dir().join(format!("factory-calibrate-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("starts.json");
    file.save(&path).unwrap();
    assert_eq!(CalibrationFile::load(&path).unwrap(), file);

    let mut reading = table_iii();
    reading.randomize.starts_file = Some(path.display().to_string());
    reading.failure_penalty = 20.0; // a key that does not change a held start
    let mut env = FrankaNutBolt::new(&reading, 3, 9).unwrap();
    let mut buf = StepBuffers::new(env.spec());
    env.reset(&mut buf);
    for w in 0..3 {
        let (p, q) = env.scene().nut_pose(w);
        let joints = &env.scene().sim.joints.joint_q[w * 9..(w + 1) * 9];
        let from = file.starts.iter().find(|s| s.nut_pos == p.to_array() && s.nut_quat == q.to_array());
        let s = from.unwrap_or_else(|| panic!("world {w} starts at {p}, none of the file's starts"));
        assert_eq!((joints, env.start_draws()[w]), (s.joint_q.as_slice(), s.draw));
    }

    let mut other = reading.clone();
    other.pos_iters = 16;
    let msg = FrankaNutBolt::new(&other, 1, 0).err().expect("other physics refused").to_string();
    assert!(msg.contains("randomize.starts_file") && msg.contains("`pos_iters`: 32 in the file, 16"), "{msg}");

    let text = std::fs::read_to_string(&path).unwrap().replace(CALIBRATION_FORMAT, "factory-calibration/0");
    std::fs::write(&path, text).unwrap();
    let msg = CalibrationFile::load(&path).unwrap_err().to_string();
    assert!(msg.contains("factory-calibration/0") && msg.contains(CALIBRATION_FORMAT), "{msg}");
    std::fs::remove_dir_all(&dir).ok();
}

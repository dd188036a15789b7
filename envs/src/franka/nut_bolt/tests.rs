use super::*;
use crate::franka::scene::ContactMaterials;

/// Regression: the Screw reward and slip test measured the nut from the fingertip, not from the pads'
/// midpoint (IsaacGymEnvs), so a grasp at the nut's bottom was rewarded for sliding the hand up.
#[test]
fn the_screw_reward_and_slip_test_measure_the_nut_from_the_pads_midpoint() {
    let nut_height = 0.0148;
    let task = Screw {
        target: Vec3::new(0.0, 0.0, 0.02),
        pitch: 0.002,
        nut_height,
        bolt_diameter: 0.016,
        bolt_top: 0.05,
        far_error: 0.1,
    };
    // The hand points down: the fingertip frame's z is the world's -z.
    let tip_quat = Quat::from_rotation_x(std::f32::consts::PI);
    let view = |tip: Vec3| WorldView {
        tip_pos: tip,
        tip_quat,
        tip_linvel: Vec3::ZERO,
        tip_angvel: Vec3::ZERO,
        nut_com: task.target,
        nut_quat: Quat::IDENTITY,
        nut_linvel: Vec3::ZERO,
        nut_angvel: Vec3::ZERO,
        nut_frame: Vec3::ZERO,
    };
    let half_pad = 0.5 * FINGERPAD_LENGTH;
    // The pads' centres level with the nut's centre of mass, which is at its target: no distance left.
    let level = task.target - Vec3::Z * half_pad;
    assert!((pad_midpoint(level, tip_quat) - task.target).length() < 1e-7);
    assert!(task.reward(&view(level)).abs() < 1e-6, "{}", task.reward(&view(level)));
    // The fingertip at the nut's centre puts the pads half a pad above it: 4 keypoints x half a pad.
    let r = task.reward(&view(task.target));
    assert!((r + 4.0 * half_pad).abs() < 1e-6, "{r}");
    // Slip: the nut's centre farther than half a pad plus half the nut from the pads' midpoint (the
    // nut 5 cm above its target: neither seated nor far).
    let limit = half_pad + 0.5 * nut_height;
    let above = Screw { target: task.target - Vec3::Z * 0.05, ..task.clone() };
    let at = |d: f32| above.outcome(&view(level + Vec3::Z * d));
    assert_eq!(at(limit - 1e-4), Outcome::Running);
    assert_eq!(at(limit + 1e-4), Outcome::Failure("slipped"));
    assert_eq!(at(-(limit - 1e-4)), Outcome::Running);
}

/// Bad config values are refused naming the field and the valid range, before any scene is built.
#[test]
fn bad_config_values_name_their_field() {
    let cases = [
        (FrankaNutBoltConfig { contact_descent_iters: 0, ..Default::default() }, "contact_descent_iters", "1..=64"),
        (FrankaNutBoltConfig { grasp_height: 0.02, ..Default::default() }, "grasp_height", "[-0.005, 0.01]"),
        (FrankaNutBoltConfig { segments_per_turn: 4, ..Default::default() }, "segments_per_turn", "below 8"),
        (
            FrankaNutBoltConfig { contact_candidates_per_invocation: 3, ..Default::default() },
            "contact_candidates_per_invocation",
            "1, 2 or 4",
        ),
        (
            FrankaNutBoltConfig {
                materials: ContactMaterials { finger_pads: -1.0, ..Default::default() },
                ..Default::default()
            },
            "materials.finger_pads",
            ">= 0",
        ),
        (FrankaNutBoltConfig { thread_mu: Some(f32::NAN), ..Default::default() }, "thread_mu", ">= 0"),
    ];
    for (cfg, field, valid) in cases {
        let e = cfg.check().unwrap_err().to_string();
        assert!(e.contains(field) && e.contains(valid), "{e}");
    }
    assert!(FrankaNutBoltConfig::default().check().is_ok());
}

/// Each failure is reported by its cause: off the axis below the bolt's top is `fallen` (whether or not the
/// pads still hold it), more than `far_error` from the target with the pads on the nut is `far`.
#[test]
fn screw_failures_name_their_cause() {
    let task = Screw {
        target: Vec3::ZERO,
        pitch: 0.002,
        nut_height: 0.0148,
        bolt_diameter: 0.016,
        bolt_top: 0.05,
        far_error: 0.1,
    };
    let tip_quat = Quat::from_rotation_x(std::f32::consts::PI);
    let view = |nut: Vec3| WorldView {
        // The pads' midpoint on the nut's centre of mass.
        tip_pos: nut - Vec3::Z * (0.5 * FINGERPAD_LENGTH),
        tip_quat,
        tip_linvel: Vec3::ZERO,
        tip_angvel: Vec3::ZERO,
        nut_com: nut,
        nut_quat: Quat::IDENTITY,
        nut_linvel: Vec3::ZERO,
        nut_angvel: Vec3::ZERO,
        nut_frame: Vec3::ZERO,
    };
    assert_eq!(task.outcome(&view(Vec3::new(0.0, 0.0, 0.03))), Outcome::Running);
    assert_eq!(task.outcome(&view(Vec3::new(0.0, 0.0, 0.0015))), Outcome::Success);
    assert_eq!(task.outcome(&view(Vec3::new(0.02, 0.0, 0.03))), Outcome::Failure("fallen"));
    assert_eq!(task.outcome(&view(Vec3::new(0.0, 0.0, 0.11))), Outcome::Failure("far"));
}

/// `[env.materials]` takes each surface's friction and the combine rule, refuses an unknown key naming it
/// (and the valid ones), and `thread_mu` (the thread pair's own coefficient) still reads as before.
#[test]
fn materials_read_from_toml_and_unknown_keys_are_named() {
    use super::super::scene::CombineRule;
    let cfg: FrankaNutBoltConfig =
        toml::from_str("thread_mu = 0.25\n[materials]\nfinger_pads = 0.8\ncombine = \"max\"\n").unwrap();
    assert_eq!(cfg.thread_mu, Some(0.25));
    assert_eq!(
        cfg.materials,
        ContactMaterials { finger_pads: 0.8, combine: CombineRule::Max, ..ContactMaterials::default() }
    );
    assert!(cfg.check().is_ok());
    let e = toml::from_str::<FrankaNutBoltConfig>("[materials]\nsteel = 0.3\n").unwrap_err().to_string();
    assert!(e.contains("steel") && e.contains("finger_pads") && e.contains("combine"), "{e}");
    let e = toml::from_str::<FrankaNutBoltConfig>("[materials]\ncombine = \"mean\"\n").unwrap_err().to_string();
    assert!(e.contains("mean") && e.contains("average"), "{e}");
    // The default leaves `thread_mu` out of a written config (the materials give the thread's).
    let written = toml::to_string(&FrankaNutBoltConfig::default()).unwrap();
    assert!(!written.contains("thread_mu") && written.contains("[materials]"), "{written}");
}

/// configs/screw.toml writes the materials out at their defaults.
#[test]
fn the_screw_config_shows_the_default_materials() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/screw.toml");
    let text = std::fs::read_to_string(path).unwrap();
    let file: toml::Value = toml::from_str(&text).unwrap();
    let materials = file["env"].get("materials").unwrap_or_else(|| panic!("{path} has no [env.materials]"));
    assert_eq!(materials.clone().try_into::<ContactMaterials>().unwrap(), ContactMaterials::default());
    for key in ["nut", "bolt", "finger_pads", "table", "combine"] {
        assert!(materials.get(key).is_some(), "{path}: [env.materials] does not write out `{key}`");
    }
}

/// configs/screw_table_iii.toml is configs/screw.toml with Table III's seven ranges and the balanced grip,
/// nothing else changed in `[env]`.
#[test]
fn the_table_iii_config_differs_from_screw_only_in_its_starts() {
    let env_of = |name: &str| {
        let path = format!("{}/../configs/{name}", env!("CARGO_MANIFEST_DIR"));
        let file: toml::Value = toml::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        let mut env = file["env"].clone();
        env.as_table_mut().unwrap().remove("type");
        env.try_into::<FrankaNutBoltConfig>().unwrap_or_else(|e| panic!("{path}: {e}"))
    };
    let (screw, table_iii) = (env_of("screw.toml"), env_of("screw_table_iii.toml"));
    assert_eq!(table_iii.randomize, ScrewRandomization::table_iii());
    assert!(table_iii.balanced_grip && table_iii.check().is_ok());
    assert_eq!(
        FrankaNutBoltConfig { randomize: ScrewRandomization::table_iii(), balanced_grip: true, ..screw },
        table_iii
    );
}

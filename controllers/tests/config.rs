//! Controller configs: TOML in, errors that name what is wrong, the registry.

use factory_controllers::config::*;
use factory_controllers::{build, ControllerConfig, ControllerError, JacobianKind, NAMES};

#[test]
fn every_registered_type_parses_with_defaults_and_builds() {
    for name in NAMES {
        let cfg = ControllerConfig::from_toml_str(&format!("type = \"{name}\"")).unwrap();
        assert_eq!(cfg.name(), *name);
        assert_eq!(cfg, ControllerConfig::default_for(name).unwrap());
        let ctrl = build(&cfg, 9, 7).unwrap();
        assert_eq!(ctrl.name(), *name);
        assert_eq!((ctrl.dof(), ctrl.arm_dof()), (9, 7));
    }
    assert_eq!(NAMES.len(), 7);
}

#[test]
fn isaacgymenvs_name_is_an_alias_for_osc() {
    let cfg = ControllerConfig::from_toml_str("type = \"operational_space_motion\"\nkd = 2").unwrap();
    match &cfg {
        ControllerConfig::Osc(c) => assert_eq!(c.kd, Gains::All(2.0)),
        other => panic!("{other:?}"),
    }
    assert_eq!(cfg.name(), "osc");
}

#[test]
fn screw_osc_config_reads_as_written() {
    let cfg = ControllerConfig::from_toml_str(
        r#"
        type = "osc"
        kp = [1, 1, 1, 1, 1, 200]
        kd = 1
        motion_axes = [0, 0, 1, 0, 0, 1]
        jacobian = "analytic"
        gripper_kp = [100, 100]
        gripper_kd = 1.0
        torque_limit = 80
        effort_limit = [87, 87, 87, 87, 12, 12, 12, 20, 20]
        gravity_compensation = false
        "#,
    )
    .unwrap();
    let ControllerConfig::Osc(c) = &cfg else { panic!("{cfg:?}") };
    assert_eq!(c.kp, Gains::Each(vec![1.0, 1.0, 1.0, 1.0, 1.0, 200.0]));
    assert_eq!(c.kd, Gains::All(1.0));
    assert_eq!(c.motion_axes, Gains::Each(vec![0.0, 0.0, 1.0, 0.0, 0.0, 1.0]));
    assert_eq!(c.jacobian, JacobianKind::Analytic);
    assert_eq!(c.gripper_kp, Gains::Each(vec![100.0, 100.0]));
    assert_eq!(c.torque_limit, 80.0);
    assert!(!c.gravity_compensation);
    build(&cfg, 9, 7).unwrap();
    // Serialising and reading back gives the same config.
    let text = toml::to_string(&cfg).unwrap();
    assert_eq!(ControllerConfig::from_toml_str(&text).unwrap(), cfg, "{text}");
}

#[test]
fn wrong_length_gain_is_refused_naming_the_field() {
    let cfg = ControllerConfig::from_toml_str("type = \"task_space_impedance\"\nkp = [40, 40, 40, 40, 40]").unwrap();
    let err = build(&cfg, 9, 7).err().expect("5 task gains must be refused");
    assert!(matches!(err, ControllerError::WrongLength { field: "kp", len: 5, expected: 6 }), "{err:?}");
    let msg = err.to_string();
    assert!(msg.contains("`kp`") && msg.contains('5') && msg.contains('6'), "{msg}");

    // Joint-space gains are per arm joint.
    let cfg = ControllerConfig::from_toml_str("type = \"joint_space_id\"\nkd = [8, 8, 8, 8, 8, 8]").unwrap();
    let err = build(&cfg, 9, 7).err().unwrap();
    assert!(matches!(err, ControllerError::WrongLength { field: "kd", len: 6, expected: 7 }), "{err:?}");

    // Fingers, axes and effort limits too.
    let cases = [
        ("type = \"osc\"\ngripper_kp = [100]", "gripper_kp", 1, 2),
        ("type = \"hybrid_force_motion\"\nforce_axes = [0, 0, 1]", "force_axes", 3, 6),
        ("type = \"closed_loop_force\"\nkf = [0.1, 0.1]", "kf", 2, 6),
        ("type = \"osc\"\nmotion_axes = [1, 1, 1, 1, 1, 1, 1]", "motion_axes", 7, 6),
        ("type = \"open_loop_force\"\neffort_limit = [87, 87]", "effort_limit", 2, 9),
    ];
    for (text, field, len, expected) in cases {
        let err = build(&ControllerConfig::from_toml_str(text).unwrap(), 9, 7).err().unwrap();
        match err {
            ControllerError::WrongLength { field: f, len: l, expected: e } => {
                assert_eq!((f, l, e), (field, len, expected), "{text}")
            }
            other => panic!("{text}: {other:?}"),
        }
    }
}

#[test]
fn scalar_gain_means_every_axis() {
    let cfg = ControllerConfig::from_toml_str("type = \"task_space_impedance\"\nkp = 25\nkd = 2.5").unwrap();
    let ControllerConfig::TaskSpaceImpedance(c) = &cfg else { panic!() };
    assert_eq!(c.kp.resolve("kp", 6).unwrap(), vec![25.0; 6]);
    assert_eq!(c.kd.resolve("kd", 6).unwrap(), vec![2.5; 6]);
}

#[test]
fn unknown_key_is_refused() {
    let err = ControllerConfig::from_toml_str("type = \"osc\"\nkp = 1\nstiffness = 3").unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, ControllerError::Parse(_)), "{err:?}");
    assert!(msg.contains("stiffness"), "{msg}");
    // A key of another controller is unknown here too.
    let err = ControllerConfig::from_toml_str("type = \"osc\"\nforce_axes = [0, 0, 1, 0, 0, 0]").unwrap_err();
    assert!(err.to_string().contains("force_axes"), "{err}");
}

#[test]
fn unknown_type_lists_the_valid_ones() {
    let err = ControllerConfig::from_toml_str("type = \"pid\"").unwrap_err();
    assert!(matches!(&err, ControllerError::UnknownType(t) if t == "pid"), "{err:?}");
    let msg = err.to_string();
    for name in NAMES {
        assert!(msg.contains(name), "{msg} lacks {name}");
    }
    assert!(matches!(ControllerConfig::from_toml_str("kp = 1").unwrap_err(), ControllerError::MissingType));
    assert!(matches!(ControllerConfig::default_for("pid").unwrap_err(), ControllerError::UnknownType(_)));
}

/// Embedded in a larger config and read by serde directly, the same rules hold.
#[test]
fn embedded_in_a_larger_config() {
    #[derive(serde::Deserialize, Debug)]
    #[allow(dead_code)]
    struct Train {
        controller: ControllerConfig,
    }
    let ok: Train = toml::from_str("[controller]\ntype = \"joint_space_ik\"\nik_method = \"svd\"").unwrap();
    let ControllerConfig::JointSpaceIk(c) = &ok.controller else { panic!() };
    assert_eq!(c.ik_method, IkMethod::Svd);
    let err = toml::from_str::<Train>("[controller]\ntype = \"joint_space_ik\"\nik = \"svd\"").unwrap_err();
    assert!(err.to_string().contains("ik"), "{err}");
    let err = toml::from_str::<Train>("[controller]\ntype = \"pid\"").unwrap_err().to_string();
    assert!(err.contains("pid") && err.contains("hybrid_force_motion"), "{err}");
}

#[test]
fn bad_values_are_refused() {
    let cases = [
        ("type = \"osc\"\nmotion_axes = [0, 0, 2, 0, 0, 1]", "motion_axes"),
        ("type = \"osc\"\nkp = -1", "kp"),
        ("type = \"osc\"\ntorque_limit = 0", "torque_limit"),
        ("type = \"joint_space_ik\"\ndls_lambda = -0.1", "dls_lambda"),
        ("type = \"open_loop_force\"\neffort_limit = [87, 87, 87, 87, 12, 12, 12, 0, 20]", "effort_limit"),
    ];
    for (text, field) in cases {
        let err = build(&ControllerConfig::from_toml_str(text).unwrap(), 9, 7).err().unwrap();
        assert!(matches!(err, ControllerError::InvalidValue { field: f, .. } if f == field), "{text}: {err:?}");
    }
    let err = ControllerConfig::from_toml_str("type = \"osc\"\nkp = \"stiff\"").unwrap_err();
    assert!(err.to_string().contains("a number or an array of numbers"), "{err}");
    let err = ControllerConfig::from_toml_str("type = \"joint_space_ik\"\nik_method = \"newton\"").unwrap_err();
    assert!(err.to_string().contains("dls"), "{err}");
}

#[test]
fn robot_dof_is_checked() {
    let cfg = ControllerConfig::default_for("osc").unwrap();
    assert!(matches!(build(&cfg, 9, 0).err().unwrap(), ControllerError::InvalidDof { .. }));
    assert!(matches!(build(&cfg, 12, 10).err().unwrap(), ControllerError::InvalidDof { .. }));
    assert!(matches!(build(&cfg, 6, 7).err().unwrap(), ControllerError::InvalidDof { .. }));
    // An arm without fingers, and a 6-joint arm, are fine.
    let cfg = ControllerConfig::from_toml_str("type = \"osc\"\ngripper_kp = []\ngripper_kd = []").unwrap();
    build(&cfg, 7, 7).unwrap();
    build(&ControllerConfig::default_for("joint_space_ik").unwrap(), 8, 6).unwrap();
}

#[test]
fn defaults_are_isaacgymenvs_values() {
    let ik = JointSpaceIkConfig::default();
    assert_eq!((ik.kp.clone(), ik.kd.clone(), ik.ik_method), (Gains::All(1.0), Gains::All(0.1), IkMethod::Dls));
    assert_eq!((ik.dls_lambda, ik.svd_min_singular_value), (0.1, 1e-5));
    let id = JointSpaceIdConfig::default();
    assert_eq!((id.kp, id.kd), (Gains::All(40.0), Gains::All(8.0)));
    let imp = TaskSpaceImpedanceConfig::default();
    assert_eq!((imp.kp, imp.kd), (Gains::All(40.0), Gains::All(8.0)));
    let osc = OscConfig::default();
    assert_eq!((osc.kp, osc.kd), (Gains::All(1.0), Gains::All(1.0)));
    let cl = ClosedLoopForceConfig::default();
    assert_eq!(cl.kf, Gains::All(0.1));
    let h = HybridForceMotionConfig::default();
    assert_eq!(h.motion_axes, Gains::Each(vec![1.0, 1.0, 0.0, 1.0, 1.0, 1.0]));
    assert_eq!(h.force_axes, Gains::Each(vec![0.0, 0.0, 1.0, 0.0, 0.0, 0.0]));
    assert_eq!((h.motion, h.force), (MotionLaw::Osc, ForceLaw::Closed));
    assert_eq!((ik.gripper_kp, ik.gripper_kd, ik.torque_limit), (Gains::All(50.0), Gains::All(2.0), 100.0));
    assert!(ik.gravity_compensation && ik.effort_limit.is_none());
}

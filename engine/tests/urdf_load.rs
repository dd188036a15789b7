//! URDF loading: collision shapes, Factory's `<sdf>` tag, joints, and error messages with file and line.

use factory_engine::urdf::{load_collision_mesh, load_urdf, parse_urdf, Collision, Geometry, JointType, Pose};
use factory_engine::EngineError;
use glam::{Mat3, Quat, Vec3};
use std::path::{Path, PathBuf};

/// A fresh directory for one test's fixtures: temp dir + process id + test name.
fn fixture_dir(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("factory-rs-urdf-{}", std::process::id())).join(test);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn write(path: &Path, text: &str) -> PathBuf {
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).unwrap();
    }
    std::fs::write(path, text).unwrap();
    path.to_path_buf()
}

/// The unit cube [0,1]^3, counter-clockwise from outside.
const CUBE_OBJ: &str = "# unit cube
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 1
v 1 0 1
v 1 1 1
v 0 1 1
f 1 4 3
f 1 3 2
f 5 6 7
f 5 7 8
f 1 2 6
f 1 6 5
f 2 3 7
f 2 7 6
f 3 4 8
f 3 8 7
f 4 1 5
f 4 5 8
";

/// The rotation R = Rz(yaw) Ry(pitch) Rx(roll) written out entry by entry (rows), independently of glam.
fn hand_rpy_matrix(roll: f32, pitch: f32, yaw: f32) -> [[f32; 3]; 3] {
    let (sr, cr) = roll.sin_cos();
    let (sp, cp) = pitch.sin_cos();
    let (sy, cy) = yaw.sin_cos();
    [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]
}

fn assert_close(a: Vec3, b: Vec3, tol: f32) {
    assert!((a - b).abs().max_element() <= tol, "{a} != {b} (tolerance {tol})");
}

fn parse_err_line(err: &EngineError) -> (PathBuf, usize, String) {
    match err {
        EngineError::Parse { path, line, message } => (path.clone(), *line, message.clone()),
        other => panic!("expected a Parse error, got {other:?}"),
    }
}

#[test]
fn mesh_collision_with_sdf_scale_and_origin() {
    let dir = fixture_dir("mesh_collision");
    write(&dir.join("meshes/cube.obj"), CUBE_OBJ);
    let urdf = write(
        &dir.join("part.urdf"),
        r#"<?xml version="1.0"?>
<robot name="part">
  <link name="body">
    <inertial>
      <origin xyz="0.01 0.02 0.03"/>
      <mass value="0.25"/>
      <inertia ixx="1e-4" ixy="2e-6" ixz="3e-6" iyy="5e-4" iyz="4e-6" izz="6e-4"/>
    </inertial>
    <visual><geometry><mesh filename="meshes/does_not_matter_for_visuals.obj"/></geometry></visual>
    <collision name="shell">
      <origin xyz="0.1 0.2 0.3" rpy="0.3 -0.5 1.2"/>
      <geometry>
        <mesh filename="meshes/cube.obj" scale="0.5 2 1"/>
      </geometry>
      <sdf resolution="256"/>
    </collision>
    <collision>
      <geometry><mesh filename="meshes/cube.obj"/></geometry>
    </collision>
  </link>
</robot>
"#,
    );
    let model = load_urdf(&urdf).unwrap();
    assert_eq!(model.name, "part");
    assert_eq!(model.links.len(), 1);
    assert!(model.joints.is_empty());
    let link = &model.links[0];
    assert_eq!(link.name, "body");
    assert_eq!(model.root_link().name, "body");

    let inertial = link.inertial.expect("inertial");
    assert_eq!(inertial.mass, 0.25);
    assert_close(inertial.origin.translation, Vec3::new(0.01, 0.02, 0.03), 0.0);
    assert_eq!(inertial.origin.rotation, Quat::IDENTITY);
    let expected_inertia =
        Mat3::from_cols(Vec3::new(1e-4, 2e-6, 3e-6), Vec3::new(2e-6, 5e-4, 4e-6), Vec3::new(3e-6, 4e-6, 6e-4));
    assert_eq!(inertial.inertia, expected_inertia);

    assert_eq!(link.collisions.len(), 2);
    let c = &link.collisions[0];
    assert_eq!(c.name.as_deref(), Some("shell"));
    assert_eq!(c.sdf_resolution, Some(256));
    assert_eq!(link.collisions[1].sdf_resolution, None, "the <sdf> of one collision must not leak to the next");
    assert_eq!(link.collisions[1].name, None);
    match &c.geometry {
        Geometry::Mesh { path, scale } => {
            assert_eq!(path, &dir.join("meshes/cube.obj"));
            assert_eq!(*scale, Vec3::new(0.5, 2.0, 1.0));
        }
        other => panic!("expected a mesh, got {other:?}"),
    }
    match &link.collisions[1].geometry {
        Geometry::Mesh { scale, .. } => assert_eq!(*scale, Vec3::ONE, "default scale"),
        other => panic!("expected a mesh, got {other:?}"),
    }

    // Origin: translation as written, rotation equal to the hand-computed Rz(yaw) Ry(pitch) Rx(roll).
    assert_close(c.origin.translation, Vec3::new(0.1, 0.2, 0.3), 0.0);
    let m = Mat3::from_quat(c.origin.rotation);
    let hand = hand_rpy_matrix(0.3, -0.5, 1.2);
    for (r, row) in hand.iter().enumerate() {
        assert_close(m.row(r), Vec3::from_array(*row), 1e-6);
    }
    assert!((c.origin.rotation.length() - 1.0).abs() < 1e-6);

    // The mesh is loaded in its own frame, scaled, with the origin NOT applied.
    let mesh = load_collision_mesh(c).unwrap();
    assert_eq!(mesh.triangle_count(), 12);
    let (lo, hi) = mesh.aabb();
    assert_close(lo, Vec3::ZERO, 0.0);
    assert_close(hi, Vec3::new(0.5, 2.0, 1.0), 0.0);
    assert!((mesh.signed_volume() - 1.0).abs() < 1e-6, "volume {}", mesh.signed_volume());
}

#[test]
fn rpy_is_fixed_axis_roll_then_pitch_then_yaw() {
    // Quarter turns, where the order of composition is visible: with R = Rz(90) Rx(90), x -> y and y -> z;
    // the reverse order Rx(90) Rz(90) would send x -> z.
    let h = std::f32::consts::FRAC_PI_2;
    let p = Pose::from_xyz_rpy(Vec3::new(1.0, 2.0, 3.0), Vec3::new(h, 0.0, h));
    assert_close(p.rotation * Vec3::X, Vec3::Y, 1e-6);
    assert_close(p.rotation * Vec3::Y, Vec3::Z, 1e-6);
    assert_close(p.rotation * Vec3::Z, Vec3::X, 1e-6);
    assert_close(p.transform_point(Vec3::X), Vec3::new(1.0, 3.0, 3.0), 1e-6);
    assert_close(p.to_affine().transform_point3(Vec3::Y), Vec3::new(1.0, 2.0, 4.0), 1e-6);
    // Pitch alone: Ry(90) sends z to x.
    let q = Pose::from_xyz_rpy(Vec3::ZERO, Vec3::new(0.0, h, 0.0));
    assert_close(q.rotation * Vec3::Z, Vec3::X, 1e-6);
}

#[test]
fn primitives_and_joints() {
    let dir = fixture_dir("primitives");
    let urdf = write(
        &dir.join("arm.urdf"),
        r#"<robot name="arm">
  <material name="grey"><color rgba="0.5 0.5 0.5 1"/></material>
  <link name="base">
    <collision><geometry><box size="0.2 0.4 0.6"/></geometry></collision>
    <collision><origin xyz="0 0 0.5"/><geometry><sphere radius="0.05"/></geometry></collision>
  </link>
  <link name="upper">
    <collision><geometry><cylinder radius="0.01" length="0.3"/></geometry><sdf resolution="64"/></collision>
    <collision><geometry><capsule radius="0.02" length="0.1"/></geometry></collision>
  </link>
  <link name="hand"/>
  <joint name="shoulder" type="revolute">
    <origin xyz="0 0 0.333" rpy="0 0 0"/>
    <parent link="base"/>
    <child link="upper"/>
    <axis xyz="0 0 2"/>
    <limit lower="-2.8973" upper="2.8973" effort="87" velocity="2.175"/>
    <dynamics damping="0.1"/>
  </joint>
  <joint name="wrist" type="fixed">
    <parent link="upper"/>
    <child link="hand"/>
  </joint>
</robot>
"#,
    );
    let model = load_urdf(&urdf).unwrap();
    assert_eq!(model.links.iter().map(|l| l.name.as_str()).collect::<Vec<_>>(), ["base", "upper", "hand"]);
    assert_eq!(model.root_link().name, "base");
    let base = model.link("base").unwrap();
    assert!(base.inertial.is_none());
    assert_eq!(base.collisions[0].geometry, Geometry::Box { half_extents: Vec3::new(0.1, 0.2, 0.3) });
    assert_eq!(base.collisions[1].geometry, Geometry::Sphere { radius: 0.05 });
    assert_close(base.collisions[1].origin.translation, Vec3::new(0.0, 0.0, 0.5), 0.0);
    let upper = model.link("upper").unwrap();
    assert_eq!(upper.collisions[0].geometry, Geometry::Cylinder { radius: 0.01, length: 0.3 });
    assert_eq!(upper.collisions[0].sdf_resolution, Some(64));
    assert_eq!(upper.collisions[1].geometry, Geometry::Capsule { radius: 0.02, length: 0.1 });
    assert!(model.link("hand").unwrap().collisions.is_empty());

    let shoulder = model.joint("shoulder").unwrap();
    assert_eq!(shoulder.joint_type, JointType::Revolute);
    assert_eq!((shoulder.parent.as_str(), shoulder.child.as_str()), ("base", "upper"));
    assert_close(shoulder.origin.translation, Vec3::new(0.0, 0.0, 0.333), 0.0);
    assert_eq!(shoulder.axis, Vec3::Z, "the axis is normalised");
    let limit = shoulder.limit.unwrap();
    assert_eq!((limit.lower, limit.upper, limit.effort, limit.velocity), (-2.8973, 2.8973, 87.0, 2.175));
    let dynamics = shoulder.dynamics.unwrap();
    assert_eq!((dynamics.damping, dynamics.friction), (0.1, 0.0));
    assert!(shoulder.mimic.is_none());

    let wrist = model.joint("wrist").unwrap();
    assert_eq!(wrist.joint_type, JointType::Fixed);
    assert_eq!(wrist.axis, Vec3::X, "default axis");
    assert_eq!(wrist.origin, Pose::IDENTITY);
    assert!(wrist.limit.is_none());

    // A primitive has no mesh file.
    assert!(matches!(load_collision_mesh(&base.collisions[0]), Err(EngineError::Config { .. })));
}

#[test]
fn franka_style_finger_joints_with_mimic() {
    let text = r#"<robot name="hand">
  <link name="panda_hand"/>
  <link name="panda_leftfinger"/>
  <link name="panda_rightfinger"/>
  <joint name="panda_finger_joint1" type="prismatic">
    <parent link="panda_hand"/>
    <child link="panda_leftfinger"/>
    <origin xyz="0 0 0.0584" rpy="0 0 0"/>
    <axis xyz="0 1 0"/>
    <limit effort="20" lower="0.0" upper="0.04" velocity="0.2"/>
  </joint>
  <joint name="panda_finger_joint2" type="prismatic">
    <parent link="panda_hand"/>
    <child link="panda_rightfinger"/>
    <origin xyz="0 0 0.0584" rpy="0 0 0"/>
    <axis xyz="0 -1 0"/>
    <limit effort="20" lower="0.0" upper="0.04" velocity="0.2"/>
    <mimic joint="panda_finger_joint1"/>
  </joint>
</robot>"#;
    let model = parse_urdf(text, Path::new("hand.urdf"), Path::new(".")).unwrap();
    let j2 = model.joint("panda_finger_joint2").unwrap();
    assert_eq!(j2.joint_type, JointType::Prismatic);
    assert_eq!(j2.axis, Vec3::NEG_Y);
    let mimic = j2.mimic.as_ref().unwrap();
    assert_eq!((mimic.joint.as_str(), mimic.multiplier, mimic.offset), ("panda_finger_joint1", 1.0, 0.0));
    assert_eq!(j2.limit.unwrap().upper, 0.04);
}

#[test]
fn factory_nut_urdf_style() {
    let dir = fixture_dir("factory_nut");
    write(&dir.join("factory_nut_m16_tight.obj"), CUBE_OBJ);
    let urdf = write(
        &dir.join("factory_nut_m16_tight.urdf"),
        r#"<?xml version="1.0"?>
<robot name="factory_nut_m16_tight">
    <link name="nut">
        <visual>
            <geometry>
                <mesh filename="factory_nut_m16_tight.obj"/>
            </geometry>
        </visual>
        <collision>
            <geometry>
                <mesh filename="factory_nut_m16_tight.obj"/>
            </geometry>
            <sdf resolution="256"/>
        </collision>
        <inertial>
            <density value="8000.0"/>
            <mass value="0.0293"/>
            <inertia ixx="0.0" ixy="0.0" ixz="0.0" iyy="0.0" iyz="0.0" izz="0.0"/>
        </inertial>
    </link>
</robot>
"#,
    );
    let model = load_urdf(&urdf).unwrap();
    assert_eq!(model.name, "factory_nut_m16_tight");
    let nut = model.link("nut").unwrap();
    assert_eq!(nut.collisions.len(), 1, "visuals are not collisions");
    let c: &Collision = &nut.collisions[0];
    assert_eq!(c.sdf_resolution, Some(256));
    assert_eq!(c.origin, Pose::IDENTITY);
    assert_eq!(c.geometry, Geometry::Mesh { path: dir.join("factory_nut_m16_tight.obj"), scale: Vec3::ONE });
    assert_eq!(nut.inertial.unwrap().mass, 0.0293);
    assert_eq!(load_collision_mesh(c).unwrap().triangle_count(), 12);
}

#[test]
fn package_and_file_uris() {
    let dir = fixture_dir("uris");
    let obj = write(&dir.join("my_pkg/meshes/cube.obj"), CUBE_OBJ);
    let text = format!(
        r#"<robot name="r">
  <link name="a">
    <collision><geometry><mesh filename="package://my_pkg/meshes/cube.obj"/></geometry></collision>
    <collision><geometry><mesh filename="file://{}"/></geometry></collision>
  </link>
</robot>"#,
        obj.display()
    );
    let urdf = write(&dir.join("my_pkg/urdf/r.urdf"), &text);
    let model = load_urdf(&urdf).unwrap();
    for c in &model.links[0].collisions {
        match &c.geometry {
            Geometry::Mesh { path, .. } => assert_eq!(path, &obj),
            other => panic!("expected a mesh, got {other:?}"),
        }
    }
}

#[test]
fn malformed_xml_names_file_and_line() {
    let dir = fixture_dir("malformed_xml");
    let urdf = write(
        &dir.join("broken_robot.urdf"),
        "<?xml version=\"1.0\"?>\n<robot name=\"r\">\n  <link name=\"a\"/>\n  <joint name=\"j\" type=fixed>\n  </joint>\n</robot>\n",
    );
    let err = load_urdf(&urdf).unwrap_err();
    let (path, line, _) = parse_err_line(&err);
    assert_eq!(path, urdf);
    assert_eq!(line, 4);
    let text = err.to_string();
    assert!(text.contains("broken_robot.urdf:4:"), "{text}");

    // An unclosed element: the error is where the document ends unexpectedly or the wrong tag closes.
    let err = parse_urdf("<robot name=\"r\">\n  <link name=\"a\">\n</robot>\n", Path::new("x.urdf"), Path::new("."))
        .unwrap_err();
    let (_, line, message) = parse_err_line(&err);
    assert_eq!(line, 3, "{message}");
}

#[test]
fn missing_required_attributes_name_the_element_line() {
    let dir = fixture_dir("missing_attrs");
    let no_filename = "<robot name=\"r\">\n  <link name=\"a\">\n    <collision>\n      <geometry>\n        <mesh scale=\"1 1 1\"/>\n      </geometry>\n    </collision>\n  </link>\n</robot>\n";
    let err = parse_urdf(no_filename, &dir.join("m.urdf"), &dir).unwrap_err();
    let (_, line, message) = parse_err_line(&err);
    assert_eq!(line, 5);
    assert!(message.contains("filename"), "{message}");
    assert!(err.to_string().contains("m.urdf:5:"), "{err}");

    let no_link_name = "<robot name=\"r\">\n\n  <link>\n  </link>\n</robot>\n";
    let (_, line, message) = parse_err_line(&parse_urdf(no_link_name, Path::new("l.urdf"), &dir).unwrap_err());
    assert_eq!(line, 3);
    assert!(message.contains("name"), "{message}");

    let bad_number = "<robot name=\"r\">\n  <link name=\"a\">\n    <collision>\n      <geometry><box size=\"0.1 nan 0.1\"/></geometry>\n    </collision>\n  </link>\n</robot>\n";
    let (_, line, message) = parse_err_line(&parse_urdf(bad_number, Path::new("b.urdf"), &dir).unwrap_err());
    assert_eq!(line, 4);
    assert!(message.contains("nan"), "{message}");

    let revolute_without_limit = "<robot name=\"r\">\n  <link name=\"a\"/>\n  <link name=\"b\"/>\n  <joint name=\"j\" type=\"revolute\">\n    <parent link=\"a\"/><child link=\"b\"/>\n  </joint>\n</robot>\n";
    let (_, line, message) =
        parse_err_line(&parse_urdf(revolute_without_limit, Path::new("j.urdf"), &dir).unwrap_err());
    assert_eq!(line, 4);
    assert!(message.contains("<limit>"), "{message}");

    let unknown_child = "<robot name=\"r\">\n  <link name=\"a\"/>\n  <joint name=\"j\" type=\"fixed\">\n    <parent link=\"a\"/><child link=\"ghost\"/>\n  </joint>\n</robot>\n";
    let (_, line, message) = parse_err_line(&parse_urdf(unknown_child, Path::new("j.urdf"), &dir).unwrap_err());
    assert_eq!(line, 3);
    assert!(message.contains("ghost"), "{message}");

    let two_roots = "<robot name=\"r\">\n  <link name=\"a\"/>\n  <link name=\"b\"/>\n</robot>\n";
    assert!(matches!(parse_urdf(two_roots, Path::new("t.urdf"), &dir), Err(EngineError::Asset { .. })));
}

#[test]
fn bad_sdf_resolution_names_line_and_range() {
    let dir = fixture_dir("bad_sdf");
    write(&dir.join("cube.obj"), CUBE_OBJ);
    for bad in ["1", "5000", "128.5", "-3", "lots"] {
        let text = format!(
            "<robot name=\"r\">\n  <link name=\"a\">\n    <collision>\n      <geometry><mesh filename=\"cube.obj\"/></geometry>\n      <sdf resolution=\"{bad}\"/>\n    </collision>\n  </link>\n</robot>\n"
        );
        let urdf = write(&dir.join("sdf.urdf"), &text);
        let err = load_urdf(&urdf).unwrap_err();
        let (path, line, message) = parse_err_line(&err);
        assert_eq!(path, urdf);
        assert_eq!(line, 5, "{bad}: {message}");
        assert!(message.contains("2..=4096"), "{bad}: {message}");
        assert!(message.contains(bad), "{bad}: {message}");
        assert!(err.to_string().contains("sdf.urdf:5:"), "{err}");
    }
    // The bounds themselves are accepted.
    for good in ["2", "4096"] {
        let text = format!(
            "<robot name=\"r\"><link name=\"a\"><collision><geometry><mesh filename=\"cube.obj\"/></geometry><sdf resolution=\"{good}\"/></collision></link></robot>"
        );
        let model = parse_urdf(&text, &dir.join("ok.urdf"), &dir).unwrap();
        assert_eq!(model.links[0].collisions[0].sdf_resolution, Some(good.parse().unwrap()));
    }
}

#[test]
fn missing_mesh_file_names_mesh_path_and_urdf_line() {
    let dir = fixture_dir("missing_mesh");
    let urdf = write(
        &dir.join("needs_mesh.urdf"),
        "<robot name=\"r\">\n  <link name=\"a\">\n    <collision>\n      <geometry>\n        <mesh filename=\"meshes/not_there.obj\"/>\n      </geometry>\n    </collision>\n  </link>\n</robot>\n",
    );
    let err = load_urdf(&urdf).unwrap_err();
    let (path, line, message) = parse_err_line(&err);
    assert_eq!(path, urdf);
    assert_eq!(line, 5);
    let expected = dir.join("meshes/not_there.obj");
    assert!(message.contains(&expected.display().to_string()), "{message}");
    let text = err.to_string();
    assert!(text.contains("needs_mesh.urdf:5:") && text.contains("not_there.obj"), "{text}");
}

#[test]
fn malformed_obj_error_names_the_obj_and_its_line() {
    let dir = fixture_dir("malformed_obj");
    let obj = write(&dir.join("bad.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 zero\nf 1 2 3\n");
    let urdf = write(
        &dir.join("uses_bad.urdf"),
        "<robot name=\"r\"><link name=\"a\"><collision><geometry><mesh filename=\"bad.obj\" scale=\"2 2 2\"/></geometry></collision></link></robot>",
    );
    let model = load_urdf(&urdf).unwrap();
    let err = load_collision_mesh(&model.links[0].collisions[0]).unwrap_err();
    let (path, line, _) = parse_err_line(&err);
    assert_eq!(path, obj);
    assert_eq!(line, 3);
    assert!(err.to_string().contains("bad.obj:3:"), "{err}");
}

#[test]
fn mirroring_scale_keeps_outward_winding() {
    let dir = fixture_dir("mirror");
    write(&dir.join("cube.obj"), CUBE_OBJ);
    let text = "<robot name=\"r\"><link name=\"a\"><collision><geometry><mesh filename=\"cube.obj\" scale=\"-1 2 1\"/></geometry></collision></link></robot>";
    let model = parse_urdf(text, &dir.join("m.urdf"), &dir).unwrap();
    let mesh = load_collision_mesh(&model.links[0].collisions[0]).unwrap();
    let (lo, hi) = mesh.aabb();
    assert_close(lo, Vec3::new(-1.0, 0.0, 0.0), 0.0);
    assert_close(hi, Vec3::new(0.0, 2.0, 1.0), 0.0);
    assert!((mesh.signed_volume() - 2.0).abs() < 1e-6, "volume {}", mesh.signed_volume());
}

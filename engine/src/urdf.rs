//! URDF loading: links with their inertials and collision shapes, and the joints that connect them.
//!
//! The whole file is read with `roxmltree` (urdf-rs is not used): every element keeps its byte range, so
//! every error can name the URDF file and the 1-based line of the offending element or attribute, and
//! Factory's `<sdf resolution="N"/>` extension inside `<collision>` (which urdf-rs drops) is read from the
//! same tree as the rest of the collision, with no need to pair two parses by element order.
//!
//! Conventions (those of the URDF specification, <http://wiki.ros.org/urdf/XML>):
//! - lengths in metres, angles in radians, mass in kg, inertia in kg m^2;
//! - `<origin xyz rpy>`: `rpy` are fixed-axis roll, pitch, yaw, i.e. R = Rz(yaw) Ry(pitch) Rx(roll);
//! - `<box size>` is the full edge length (stored here as half extents); cylinders and capsules lie along
//!   their local z axis with `length` the length of the cylindrical part;
//! - `<mesh filename>` is resolved relative to the URDF's directory; `file://` URIs are stripped (a relative
//!   remainder is again taken relative to the URDF's directory); `package://pkg/rest` is looked up, without
//!   ROS, as `<dir>/rest` for an ancestor `<dir>` of the URDF named `pkg`, then `<dir>/pkg/rest` for each
//!   ancestor `<dir>` and each entry of `ROS_PACKAGE_PATH`, then `rest` next to the URDF.
//!
//! Factory's SDF collision switch: `<sdf resolution="256"/>` inside a `<collision>` asks for a signed
//! distance field of that shape with 256 voxels along its longest axis; the resolution must be an integer in
//! [`SDF_RESOLUTION_RANGE`].
//!
//! Errors: malformed XML, missing or malformed attributes, unknown geometry, bad references between
//! joints and links, and a mesh file that does not exist are all [`EngineError::Parse`] with the URDF's
//! path and the line of the element (or attribute) at fault; a document with no link or without a single
//! root link is [`EngineError::Asset`]; an unreadable URDF is [`EngineError::Io`].

use crate::error::{EngineError, Result};
use crate::mesh::TriMesh;
use glam::{Affine3A, Mat3, Quat, Vec3};
use roxmltree::{Document, Node};
use std::collections::{HashMap, HashSet};
use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};

/// Valid values of `<sdf resolution="..."/>`: voxels along the shape's longest axis.
pub const SDF_RESOLUTION_RANGE: RangeInclusive<u32> = 2..=4096;

/// A rigid transform: rotate by `rotation`, then translate by `translation` [m].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    /// Translation [m].
    pub translation: Vec3,
    /// Rotation (unit quaternion).
    pub rotation: Quat,
}

impl Default for Pose {
    fn default() -> Self {
        Pose::IDENTITY
    }
}

impl Pose {
    /// No rotation, no translation.
    pub const IDENTITY: Pose = Pose { translation: Vec3::ZERO, rotation: Quat::IDENTITY };

    /// The pose of a URDF `<origin xyz="..." rpy="..."/>`: `xyz` [m], `rpy` = (roll, pitch, yaw) [rad].
    pub fn from_xyz_rpy(xyz: Vec3, rpy: Vec3) -> Pose {
        Pose { translation: xyz, rotation: rpy_to_quat(rpy) }
    }

    /// Maps a point from the child frame to the parent frame.
    pub fn transform_point(&self, p: Vec3) -> Vec3 {
        self.rotation * p + self.translation
    }

    /// The same transform as an affine matrix.
    pub fn to_affine(&self) -> Affine3A {
        Affine3A::from_rotation_translation(self.rotation, self.translation)
    }
}

/// URDF roll-pitch-yaw (fixed axes x, then y, then z) to a quaternion: R = Rz(yaw) Ry(pitch) Rx(roll).
pub fn rpy_to_quat(rpy: Vec3) -> Quat {
    (Quat::from_rotation_z(rpy.z) * Quat::from_rotation_y(rpy.y) * Quat::from_rotation_x(rpy.x)).normalize()
}

/// A robot or object description: its links and the joints between them.
#[derive(Clone, Debug, PartialEq)]
pub struct UrdfModel {
    /// The `<robot name="...">`.
    pub name: String,
    /// The file it was read from (used in later error messages).
    pub source: PathBuf,
    /// Links in document order.
    pub links: Vec<UrdfLink>,
    /// Joints in document order.
    pub joints: Vec<UrdfJoint>,
}

impl UrdfModel {
    /// The link named `name`.
    pub fn link(&self, name: &str) -> Option<&UrdfLink> {
        self.links.iter().find(|l| l.name == name)
    }

    /// The joint named `name`.
    pub fn joint(&self, name: &str) -> Option<&UrdfJoint> {
        self.joints.iter().find(|j| j.name == name)
    }

    /// The one link that is no joint's child (validated at load time).
    pub fn root_link(&self) -> &UrdfLink {
        let children: HashSet<&str> = self.joints.iter().map(|j| j.child.as_str()).collect();
        self.links.iter().find(|l| !children.contains(l.name.as_str())).expect("validated at load: one root link")
    }
}

/// A rigid body: optional mass properties and any number of collision shapes.
#[derive(Clone, Debug, PartialEq)]
pub struct UrdfLink {
    /// The `<link name="...">`.
    pub name: String,
    /// Mass properties, when the link has an `<inertial>`.
    pub inertial: Option<Inertial>,
    /// Collision shapes in document order.
    pub collisions: Vec<Collision>,
}

/// A link's mass properties.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Inertial {
    /// Mass [kg].
    pub mass: f32,
    /// Centre of mass and inertia axes, in the link frame.
    pub origin: Pose,
    /// Inertia tensor about the inertial origin, in the axes of the inertial origin [kg m^2] (symmetric).
    pub inertia: Mat3,
}

/// One collision shape of a link.
#[derive(Clone, Debug, PartialEq)]
pub struct Collision {
    /// The optional `<collision name="...">`.
    pub name: Option<String>,
    /// The shape's frame in the link frame.
    pub origin: Pose,
    /// The shape, in its own frame.
    pub geometry: Geometry,
    /// Factory's `<sdf resolution="N"/>`: SDF collision with N voxels along the longest axis; `None` when
    /// the shape has no `<sdf>` element.
    pub sdf_resolution: Option<u32>,
}

/// A collision shape in its own frame.
#[derive(Clone, Debug, PartialEq)]
pub enum Geometry {
    /// A triangle mesh file (OBJ), already resolved to a path that existed at load time.
    Mesh {
        /// The mesh file.
        path: PathBuf,
        /// Per-axis scale applied to the file's vertices (default 1 1 1).
        scale: Vec3,
    },
    /// A box centred on the origin.
    Box {
        /// Half the edge lengths [m] (URDF's `size` is the full length).
        half_extents: Vec3,
    },
    /// A sphere centred on the origin.
    Sphere {
        /// Radius [m].
        radius: f32,
    },
    /// A cylinder centred on the origin, along z.
    Cylinder {
        /// Radius [m].
        radius: f32,
        /// Full length along z [m].
        length: f32,
    },
    /// A capsule centred on the origin, along z (urdf-rs extension).
    Capsule {
        /// Radius [m].
        radius: f32,
        /// Length of the cylindrical part along z [m] (the caps add `radius` at each end).
        length: f32,
    },
}

impl Geometry {
    /// The URDF element name of this kind of geometry.
    pub fn kind(&self) -> &'static str {
        match self {
            Geometry::Mesh { .. } => "mesh",
            Geometry::Box { .. } => "box",
            Geometry::Sphere { .. } => "sphere",
            Geometry::Cylinder { .. } => "cylinder",
            Geometry::Capsule { .. } => "capsule",
        }
    }
}

/// The kinds of URDF joint.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum JointType {
    /// Rotation about `axis`, within limits.
    Revolute,
    /// Rotation about `axis`, unlimited.
    Continuous,
    /// Translation along `axis`, within limits.
    Prismatic,
    /// No motion.
    Fixed,
    /// All six degrees of freedom.
    Floating,
    /// Translation in the plane normal to `axis`.
    Planar,
}

impl JointType {
    /// The URDF `type` strings, in the order of the variants.
    pub const NAMES: [&'static str; 6] = ["revolute", "continuous", "prismatic", "fixed", "floating", "planar"];

    fn parse(s: &str) -> Option<JointType> {
        Some(match s {
            "revolute" => JointType::Revolute,
            "continuous" => JointType::Continuous,
            "prismatic" => JointType::Prismatic,
            "fixed" => JointType::Fixed,
            "floating" => JointType::Floating,
            "planar" => JointType::Planar,
            _ => return None,
        })
    }
}

/// A joint's `<limit>`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointLimit {
    /// Lower position limit [rad or m] (default 0).
    pub lower: f32,
    /// Upper position limit [rad or m] (default 0).
    pub upper: f32,
    /// Maximum effort [N m or N].
    pub effort: f32,
    /// Maximum speed [rad/s or m/s].
    pub velocity: f32,
}

/// A joint's `<dynamics>`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointDynamics {
    /// Viscous damping [N m s/rad or N s/m] (default 0).
    pub damping: f32,
    /// Static friction [N m or N] (default 0).
    pub friction: f32,
}

/// A joint's `<mimic>`: position = multiplier * position(joint) + offset.
#[derive(Clone, Debug, PartialEq)]
pub struct Mimic {
    /// The joint followed.
    pub joint: String,
    /// Default 1.
    pub multiplier: f32,
    /// Default 0.
    pub offset: f32,
}

/// A joint between a parent and a child link.
#[derive(Clone, Debug, PartialEq)]
pub struct UrdfJoint {
    /// The `<joint name="...">`.
    pub name: String,
    /// The `<joint type="...">`.
    pub joint_type: JointType,
    /// Parent link name.
    pub parent: String,
    /// Child link name.
    pub child: String,
    /// The child's joint frame in the parent link frame (at joint position zero).
    pub origin: Pose,
    /// Unit joint axis in the joint frame (default x).
    pub axis: Vec3,
    /// Required for revolute and prismatic joints, optional otherwise.
    pub limit: Option<JointLimit>,
    /// Damping and friction, when given.
    pub dynamics: Option<JointDynamics>,
    /// Coupling to another joint, when given.
    pub mimic: Option<Mimic>,
}

/// Reads and parses a URDF file; relative mesh paths are resolved against the file's directory.
pub fn load_urdf(path: &Path) -> Result<UrdfModel> {
    let text = std::fs::read_to_string(path).map_err(|e| EngineError::io(path, e))?;
    let base_dir = path.parent().unwrap_or(Path::new(""));
    parse_urdf(&text, path, base_dir)
}

/// Parses URDF text. `path` names the file in error messages; `base_dir` anchors relative mesh paths.
/// Mesh files are checked for existence here (not read).
pub fn parse_urdf(text: &str, path: &Path, base_dir: &Path) -> Result<UrdfModel> {
    let doc = Document::parse(text).map_err(|e| EngineError::Parse {
        path: path.to_path_buf(),
        line: e.pos().row as usize,
        message: format!("malformed XML: {e}"),
    })?;
    let cx = ParseContext { doc: &doc, path, base_dir };
    let robot = doc.root_element();
    if robot.tag_name().name() != "robot" {
        return Err(cx.err(robot, format!("the root element is <{}>; a URDF's is <robot>", robot.tag_name().name())));
    }
    let name = cx.attr(robot, "name")?.to_string();

    let mut links = Vec::new();
    let mut joints = Vec::new();
    let mut link_nodes: HashMap<String, Node> = HashMap::new();
    let mut joint_nodes = Vec::new();
    for node in robot.children().filter(Node::is_element) {
        match node.tag_name().name() {
            "link" => {
                let link = cx.link(node)?;
                if link_nodes.insert(link.name.clone(), node).is_some() {
                    return Err(cx.err(node, format!("a second link named {:?}; link names must be unique", link.name)));
                }
                links.push(link);
            }
            "joint" => {
                let joint = cx.joint(node)?;
                if joints.iter().any(|j: &UrdfJoint| j.name == joint.name) {
                    return Err(
                        cx.err(node, format!("a second joint named {:?}; joint names must be unique", joint.name))
                    );
                }
                joints.push(joint);
                joint_nodes.push(node);
            }
            _ => {} // materials, transmissions, gazebo extensions: not used here
        }
    }
    if links.is_empty() {
        return Err(EngineError::Asset { path: path.to_path_buf(), message: "the URDF has no <link>".into() });
    }

    // The joints must form a tree over the links.
    let mut parent_of: HashMap<&str, &str> = HashMap::new();
    for (j, node) in joints.iter().zip(&joint_nodes) {
        for (role, link) in [("parent", &j.parent), ("child", &j.child)] {
            if !link_nodes.contains_key(link.as_str()) {
                return Err(cx.err(*node, format!("joint {:?}: {role} link {link:?} is not defined", j.name)));
            }
        }
        if j.parent == j.child {
            return Err(cx.err(*node, format!("joint {:?}: link {:?} is its own parent", j.name, j.child)));
        }
        if let Some(other) = parent_of.insert(&j.child, &j.parent) {
            return Err(cx.err(
                *node,
                format!(
                    "joint {:?}: link {:?} already has parent {other:?}; a link has at most one parent joint",
                    j.name, j.child
                ),
            ));
        }
    }
    for (j, node) in joints.iter().zip(&joint_nodes) {
        if let Some(m) = j.mimic.as_ref().filter(|m| !joints.iter().any(|o| o.name == m.joint)) {
            return Err(cx.err(*node, format!("joint {:?}: mimics joint {:?}, which is not defined", j.name, m.joint)));
        }
    }
    let roots: Vec<&str> = links.iter().map(|l| l.name.as_str()).filter(|n| !parent_of.contains_key(n)).collect();
    if roots.len() != 1 {
        let message = if roots.is_empty() {
            "the joints form a cycle: no link is without a parent".to_string()
        } else {
            format!("{} root links {roots:?}; the joints must connect all links into one tree", roots.len())
        };
        return Err(EngineError::Asset { path: path.to_path_buf(), message });
    }
    // With one root and at most one parent per link, a link not reachable from the root lies on a cycle.
    let mut reached = HashSet::from([roots[0]]);
    let mut frontier = vec![roots[0]];
    while let Some(l) = frontier.pop() {
        for j in joints.iter().filter(|j| j.parent == l) {
            if reached.insert(j.child.as_str()) {
                frontier.push(j.child.as_str());
            }
        }
    }
    if reached.len() != links.len() {
        let stray: Vec<&str> = links.iter().map(|l| l.name.as_str()).filter(|n| !reached.contains(n)).collect();
        return Err(EngineError::Asset {
            path: path.to_path_buf(),
            message: format!("links {stray:?} are joined in a cycle, not reachable from the root link {:?}", roots[0]),
        });
    }

    Ok(UrdfModel { name, source: path.to_path_buf(), links, joints })
}

/// Loads a mesh collision's OBJ file and applies its scale. The collision's `origin` is NOT applied: the
/// mesh stays in the shape's own frame, and callers place it by `origin`. A scale with an odd number of
/// negative components mirrors the mesh; the triangles are then re-wound so they stay counter-clockwise
/// seen from outside. Primitive geometry is refused with [`EngineError::Config`].
pub fn load_collision_mesh(c: &Collision) -> Result<TriMesh> {
    let Geometry::Mesh { path, scale } = &c.geometry else {
        return Err(EngineError::Config {
            field: "collision geometry",
            value: format!("{} (collision {:?})", c.geometry.kind(), c.name.as_deref().unwrap_or("")),
            expected: "a <mesh>; primitives have no mesh file".into(),
        });
    };
    let scale = *scale;
    let mut mesh = TriMesh::load_obj(path)?.map_positions(|p| p * scale);
    if scale.x * scale.y * scale.z < 0.0 {
        for t in &mut mesh.triangles {
            t.swap(1, 2);
        }
    }
    Ok(mesh)
}

/// Parsing context: the document (for line numbers), the file name and the mesh base directory.
struct ParseContext<'d, 'i> {
    doc: &'d Document<'i>,
    path: &'d Path,
    base_dir: &'d Path,
}

impl<'d, 'i> ParseContext<'d, 'i> {
    fn line_at(&self, pos: usize) -> usize {
        self.doc.text_pos_at(pos).row as usize
    }

    fn err(&self, node: Node, message: String) -> EngineError {
        EngineError::Parse { path: self.path.to_path_buf(), line: self.line_at(node.range().start), message }
    }

    /// An error about attribute `name` of `node`, at the attribute's own line.
    fn attr_err(&self, node: Node, name: &str, message: String) -> EngineError {
        let pos = node.attribute_node(name).map_or(node.range().start, |a| a.range_value().start);
        EngineError::Parse { path: self.path.to_path_buf(), line: self.line_at(pos), message }
    }

    fn attr<'a>(&self, node: Node<'a, 'i>, name: &str) -> Result<&'a str> {
        node.attribute(name).ok_or_else(|| {
            self.err(node, format!("<{}> is missing the required attribute `{name}`", node.tag_name().name()))
        })
    }

    fn child<'a>(&self, node: Node<'a, 'i>, tag: &str) -> Option<Node<'a, 'i>> {
        node.children().find(|c| c.is_element() && c.tag_name().name() == tag)
    }

    fn req_child<'a>(&self, node: Node<'a, 'i>, tag: &str) -> Result<Node<'a, 'i>> {
        self.child(node, tag).ok_or_else(|| {
            self.err(node, format!("<{}> is missing the required element <{tag}>", node.tag_name().name()))
        })
    }

    /// `N` whitespace-separated finite numbers from attribute `name`; `default` when it is absent (or an
    /// error when `default` is `None`).
    fn floats<const N: usize>(&self, node: Node, name: &str, default: Option<[f32; N]>) -> Result<[f32; N]> {
        let Some(text) = node.attribute(name) else {
            return default.ok_or_else(|| {
                self.err(node, format!("<{}> is missing the required attribute `{name}`", node.tag_name().name()))
            });
        };
        let tag = node.tag_name().name();
        let toks: Vec<&str> = text.split_whitespace().collect();
        if toks.len() != N {
            let what = if N == 1 { "a number".to_string() } else { format!("{N} numbers") };
            return Err(self.attr_err(
                node,
                name,
                format!("<{tag} {name}=\"{text}\">: expected {what}, found {}", toks.len()),
            ));
        }
        let mut out = [0.0f32; N];
        for (slot, tok) in out.iter_mut().zip(toks) {
            *slot = tok.parse::<f32>().ok().filter(|v| v.is_finite()).ok_or_else(|| {
                self.attr_err(node, name, format!("<{tag} {name}=\"{text}\">: {tok:?} is not a finite number"))
            })?;
        }
        Ok(out)
    }

    fn float(&self, node: Node, name: &str, default: Option<f32>) -> Result<f32> {
        Ok(self.floats::<1>(node, name, default.map(|d| [d]))?[0])
    }

    /// A number that must be > 0 (or >= 0 when `allow_zero`).
    fn positive(&self, node: Node, name: &str, allow_zero: bool) -> Result<f32> {
        let v = self.float(node, name, None)?;
        if v < 0.0 || (v == 0.0 && !allow_zero) {
            let bound = if allow_zero { ">= 0" } else { "> 0" };
            return Err(self.attr_err(node, name, format!("<{} {name}>: {v} must be {bound}", node.tag_name().name())));
        }
        Ok(v)
    }

    /// The pose of the first `<origin>` child of `node`; identity without one.
    fn origin(&self, node: Node) -> Result<Pose> {
        let Some(o) = self.child(node, "origin") else { return Ok(Pose::IDENTITY) };
        let xyz = self.floats(o, "xyz", Some([0.0; 3]))?;
        let rpy = self.floats(o, "rpy", Some([0.0; 3]))?;
        Ok(Pose::from_xyz_rpy(Vec3::from_array(xyz), Vec3::from_array(rpy)))
    }

    fn link(&self, node: Node) -> Result<UrdfLink> {
        let name = self.attr(node, "name")?.to_string();
        let inertial = match self.child(node, "inertial") {
            Some(i) => Some(self.inertial(i)?),
            None => None,
        };
        let collisions = node
            .children()
            .filter(|c| c.is_element() && c.tag_name().name() == "collision")
            .map(|c| self.collision(c))
            .collect::<Result<Vec<_>>>()?;
        Ok(UrdfLink { name, inertial, collisions })
    }

    fn inertial(&self, node: Node) -> Result<Inertial> {
        let origin = self.origin(node)?;
        let mass = self.positive(self.req_child(node, "mass")?, "value", true)?;
        let i = self.req_child(node, "inertia")?;
        let [ixx, ixy, ixz, iyy, iyz, izz] = ["ixx", "ixy", "ixz", "iyy", "iyz", "izz"].map(|k| self.float(i, k, None));
        let (ixx, ixy, ixz, iyy, iyz, izz) = (ixx?, ixy?, ixz?, iyy?, iyz?, izz?);
        let inertia = Mat3::from_cols(Vec3::new(ixx, ixy, ixz), Vec3::new(ixy, iyy, iyz), Vec3::new(ixz, iyz, izz));
        Ok(Inertial { mass, origin, inertia })
    }

    fn collision(&self, node: Node) -> Result<Collision> {
        let name = node.attribute("name").map(str::to_string);
        let origin = self.origin(node)?;
        let g = self.req_child(node, "geometry")?;
        let shapes: Vec<Node> = g.children().filter(Node::is_element).collect();
        let shape = match shapes.as_slice() {
            [one] => *one,
            [] => {
                return Err(self.err(
                    g,
                    "<geometry> is empty; it needs one of <mesh>, <box>, <sphere>, <cylinder>, <capsule>".into(),
                ))
            }
            [_, second, ..] => {
                return Err(self.err(*second, format!("<geometry> has {} shapes; it takes exactly one", shapes.len())))
            }
        };
        let geometry = match shape.tag_name().name() {
            "mesh" => {
                let filename = self.attr(shape, "filename")?;
                let path = self.resolve_mesh(shape, filename)?;
                let scale = Vec3::from_array(self.floats(shape, "scale", Some([1.0; 3]))?);
                if scale.cmpeq(Vec3::ZERO).any() {
                    return Err(self.attr_err(shape, "scale", format!("<mesh scale>: {scale} has a zero component")));
                }
                Geometry::Mesh { path, scale }
            }
            "box" => {
                let size = Vec3::from_array(self.floats(shape, "size", None)?);
                if size.cmple(Vec3::ZERO).any() {
                    return Err(self.attr_err(shape, "size", format!("<box size>: {size} must be > 0 on every axis")));
                }
                Geometry::Box { half_extents: size * 0.5 }
            }
            "sphere" => Geometry::Sphere { radius: self.positive(shape, "radius", false)? },
            "cylinder" => Geometry::Cylinder {
                radius: self.positive(shape, "radius", false)?,
                length: self.positive(shape, "length", false)?,
            },
            "capsule" => Geometry::Capsule {
                radius: self.positive(shape, "radius", false)?,
                length: self.positive(shape, "length", true)?,
            },
            other => {
                return Err(self.err(
                    shape,
                    format!(
                        "unknown geometry <{other}>; expected one of <mesh>, <box>, <sphere>, <cylinder>, <capsule>"
                    ),
                ))
            }
        };
        let sdf_resolution = match self.child(node, "sdf") {
            None => None,
            Some(s) => {
                let text = self.attr(s, "resolution")?;
                let (lo, hi) = (*SDF_RESOLUTION_RANGE.start(), *SDF_RESOLUTION_RANGE.end());
                match text.trim().parse::<u32>() {
                    Ok(r) if SDF_RESOLUTION_RANGE.contains(&r) => Some(r),
                    _ => {
                        return Err(self.attr_err(
                            s,
                            "resolution",
                            format!("<sdf resolution=\"{text}\">: must be an integer in {lo}..={hi} (voxels along the longest axis)"),
                        ))
                    }
                }
            }
        };
        Ok(Collision { name, origin, geometry, sdf_resolution })
    }

    /// Resolves a `<mesh filename>` (see the module doc) and checks that the file exists.
    fn resolve_mesh(&self, node: Node, filename: &str) -> Result<PathBuf> {
        let candidates: Vec<PathBuf> = if let Some(rest) = filename.strip_prefix("package://") {
            let (pkg, rel) = rest.split_once('/').unwrap_or((rest, ""));
            if pkg.is_empty() || rel.is_empty() {
                return Err(self.attr_err(
                    node,
                    "filename",
                    format!("<mesh filename=\"{filename}\">: expected package://<package>/<path>"),
                ));
            }
            let mut c = Vec::new();
            let base = if self.base_dir.as_os_str().is_empty() { Path::new(".") } else { self.base_dir };
            c.extend(base.ancestors().filter(|a| a.file_name().is_some_and(|n| n == pkg)).map(|a| a.join(rel)));
            c.extend(base.ancestors().map(|a| a.join(pkg).join(rel)));
            if let Some(ros) = std::env::var_os("ROS_PACKAGE_PATH") {
                c.extend(std::env::split_paths(&ros).map(|d| d.join(pkg).join(rel)));
            }
            c.push(self.base_dir.join(rel));
            c
        } else if let Some(rest) = filename.strip_prefix("file://") {
            vec![self.base_dir.join(rest)] // join keeps an absolute `rest` as it is
        } else if filename.contains("://") {
            return Err(self.attr_err(
                node,
                "filename",
                format!("<mesh filename=\"{filename}\">: unsupported URI scheme; use a path, file:// or package://"),
            ));
        } else if filename.is_empty() {
            return Err(self.attr_err(node, "filename", "<mesh filename=\"\">: empty file name".into()));
        } else {
            vec![self.base_dir.join(filename)]
        };
        if let Some(found) = candidates.iter().find(|p| p.is_file()) {
            return Ok(found.clone());
        }
        let tried = if candidates.len() == 1 {
            candidates[0].display().to_string()
        } else {
            candidates.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ")
        };
        Err(self.attr_err(node, "filename", format!("mesh file \"{filename}\" not found (looked for {tried})")))
    }

    fn joint(&self, node: Node) -> Result<UrdfJoint> {
        let name = self.attr(node, "name")?.to_string();
        let type_text = self.attr(node, "type")?;
        let joint_type = JointType::parse(type_text).ok_or_else(|| {
            self.attr_err(
                node,
                "type",
                format!("joint {name:?}: unknown type {type_text:?}; expected one of {:?}", JointType::NAMES),
            )
        })?;
        let parent = self.attr(self.req_child(node, "parent")?, "link")?.to_string();
        let child = self.attr(self.req_child(node, "child")?, "link")?.to_string();
        let origin = self.origin(node)?;
        let axis = match self.child(node, "axis") {
            None => Vec3::X,
            Some(a) => {
                let v = Vec3::from_array(self.floats(a, "xyz", Some([1.0, 0.0, 0.0]))?);
                v.try_normalize()
                    .ok_or_else(|| self.attr_err(a, "xyz", format!("joint {name:?}: the axis {v} has zero length")))?
            }
        };
        let limit = match self.child(node, "limit") {
            None if matches!(joint_type, JointType::Revolute | JointType::Prismatic) => {
                return Err(self.err(node, format!("joint {name:?}: a {type_text} joint needs a <limit> element")))
            }
            None => None,
            Some(l) => {
                let lower = self.float(l, "lower", Some(0.0))?;
                let upper = self.float(l, "upper", Some(0.0))?;
                if lower > upper {
                    return Err(
                        self.err(l, format!("joint {name:?}: <limit lower=\"{lower}\"> is above upper=\"{upper}\""))
                    );
                }
                let effort = self.positive(l, "effort", true)?;
                let velocity = self.positive(l, "velocity", true)?;
                Some(JointLimit { lower, upper, effort, velocity })
            }
        };
        let dynamics = match self.child(node, "dynamics") {
            None => None,
            Some(d) => Some(JointDynamics {
                damping: self.float(d, "damping", Some(0.0))?,
                friction: self.float(d, "friction", Some(0.0))?,
            }),
        };
        let mimic = match self.child(node, "mimic") {
            None => None,
            Some(m) => Some(Mimic {
                joint: self.attr(m, "joint")?.to_string(),
                multiplier: self.float(m, "multiplier", Some(1.0))?,
                offset: self.float(m, "offset", Some(0.0))?,
            }),
        };
        Ok(UrdfJoint { name, joint_type, parent, child, origin, axis, limit, dynamics, mimic })
    }
}

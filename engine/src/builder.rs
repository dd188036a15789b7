//! `ModelBuilder`: one world's bodies and shapes, which shape pairs may collide (collision groups and
//! explicit filters), and how many worlds to run (`replicate`). `build` turns it into the contact model
//! (one `PairSpec` per colliding shape pair, through Factory's pair rules in [`crate::contact::roles`])
//! and the solver's `BodyModel`. Meshes and SDF grids are per shape, shared by every world (the world is
//! the batch axis of the pipelines; nothing is copied per world).
//!
//! Pair rules: two shapes are paired when at least one sits on a dynamic or kinematic body, they are not on the same
//! body, each one's group bits intersect the other's mask (PhysX-style collision filtering), and the pair
//! was not filtered out by [`ModelBuilder::filter_pair`]. A pair's friction is the mean of its shapes'
//! (PhysX's default "average" combine mode), its contact offset the larger of the two.

use crate::contact::roles::{pair_spec, ShapeDesc, ShapeGeometry};
use crate::contact::{ContactModel, NO_BODY};
use crate::error::{EngineError, Result};
use crate::mesh::MassProperties;
use crate::sdf::cache::SdfCache;
use crate::solver::BodyModel;
use glam::{Mat3, Quat, Vec3};
use std::collections::HashSet;

/// Index of a body within one world.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct BodyHandle(pub u32);

/// Index of a shape.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ShapeHandle(pub u32);

/// A shape with its collision settings.
#[derive(Clone, Debug)]
pub struct ShapeDef {
    /// The body carrying the shape, or `None` for a shape fixed in the world frame.
    pub body: Option<BodyHandle>,
    /// Shape frame in the body (or world) frame: position [m], rotation.
    pub pose: (Vec3, Quat),
    pub geometry: ShapeGeometry,
    /// Groups this shape belongs to (bit mask).
    pub group: u32,
    /// Groups this shape collides with (bit mask).
    pub mask: u32,
    /// Coulomb friction coefficient (unitless).
    pub friction: f32,
    /// Contact offset [m]: candidates farther apart are ignored.
    pub contact_offset: f32,
}

/// One world's scene and the number of worlds.
#[derive(Clone, Debug)]
pub struct ModelBuilder {
    bodies: BodyModel,
    dynamic: Vec<bool>,
    shapes: Vec<ShapeDef>,
    filtered: HashSet<(u32, u32)>,
    world_count: u32,
}

/// A built model: what the contact pipeline and the solver take.
#[derive(Clone, Debug)]
pub struct Model {
    pub contacts: ContactModel,
    pub bodies: BodyModel,
    /// Worlds to run (the batch axis).
    pub world_count: u32,
    /// The shapes of each contact pair, in `contacts.pairs` order (query shape, SDF shape).
    pub pair_shapes: Vec<(ShapeHandle, ShapeHandle)>,
}

impl Default for ModelBuilder {
    fn default() -> Self {
        Self::new(Vec3::new(0.0, 0.0, -9.81))
    }
}

impl ModelBuilder {
    /// An empty world with `gravity` [m/s^2] and one world to run.
    pub fn new(gravity: Vec3) -> Self {
        ModelBuilder {
            bodies: BodyModel { gravity, ..Default::default() },
            dynamic: Vec::new(),
            shapes: Vec::new(),
            filtered: HashSet::new(),
            world_count: 1,
        }
    }

    /// A dynamic body with the given mass properties (mass [kg], COM [m] and inertia about it [kg m^2] in
    /// the body frame), e.g. `TriMesh::mass_properties(density)`. Non-positive or non-finite masses and
    /// inertias are refused when the model is built.
    pub fn add_dynamic_body(&mut self, mp: &MassProperties) -> BodyHandle {
        self.bodies.body_inv_mass.push(if mp.mass > 0.0 { 1.0 / mp.mass } else { f32::NAN });
        self.bodies.body_inv_inertia.push(mp.inertia.inverse());
        self.bodies.body_com.push(mp.com);
        self.dynamic.push(true);
        BodyHandle(self.dynamic.len() as u32 - 1)
    }

    /// A body that is link `link` of the world's articulation, its centre of mass at `com` [m] in the link
    /// frame: it moves with the joints, and contact impulses on it act through the articulation
    /// (solver::step_cpu_articulated). Its shapes collide like those of a moving body.
    pub fn add_articulated_body(&mut self, link: u32, com: Vec3) -> BodyHandle {
        self.bodies.add_articulated(link, com);
        self.dynamic.push(false);
        BodyHandle(self.dynamic.len() as u32 - 1)
    }

    /// Adds link `link_name` of `articulation` as a link body with the collision shapes its URDF link
    /// carries (boxes, spheres, capsules as themselves; meshes loaded, tagged with their `<sdf>`), each with
    /// `friction` and `contact_offset` [m]. Cylinders are refused (the contact pipeline has no cylinder;
    /// use a capsule), naming the link and the file.
    pub fn add_urdf_link(
        &mut self,
        urdf: &crate::urdf::UrdfModel,
        articulation: &crate::articulation::ArticulationModel,
        link_name: &str,
        friction: f32,
        contact_offset: f32,
    ) -> Result<(BodyHandle, Vec<ShapeHandle>)> {
        use crate::urdf::Geometry;
        let missing = || EngineError::Asset {
            path: urdf.source.clone(),
            message: format!("no link '{link_name}' in the articulation '{}'", articulation.name),
        };
        let link = articulation.link_index(link_name).ok_or_else(missing)?;
        let ul = urdf.link(link_name).ok_or_else(missing)?;
        let body = self.add_articulated_body(link, articulation.link_com[link as usize]);
        let mut shapes = Vec::new();
        for c in &ul.collisions {
            let geometry = match &c.geometry {
                Geometry::Box { half_extents } => ShapeGeometry::Box { half_extents: *half_extents },
                Geometry::Sphere { radius } => ShapeGeometry::Sphere { radius: *radius },
                Geometry::Capsule { radius, length } => {
                    ShapeGeometry::Capsule { radius: *radius, half_length: 0.5 * length }
                }
                Geometry::Mesh { .. } => ShapeGeometry::Mesh {
                    mesh: std::sync::Arc::new(crate::urdf::load_collision_mesh(c)?),
                    sdf_resolution: c.sdf_resolution,
                },
                Geometry::Cylinder { .. } => {
                    return Err(EngineError::Asset {
                        path: urdf.source.clone(),
                        message: format!(
                            "link '{link_name}': a cylinder collision shape is not supported (box, sphere, \
                             capsule or mesh)"
                        ),
                    })
                }
            };
            let s = self.add_shape(Some(body), (c.origin.translation, c.origin.rotation), geometry);
            let def = self.shape_mut(s);
            def.friction = friction;
            def.contact_offset = contact_offset;
            shapes.push(s);
        }
        Ok((body, shapes))
    }

    /// A kinematic body: moved by the velocity set in the state, unaffected by gravity and contacts.
    pub fn add_kinematic_body(&mut self) -> BodyHandle {
        self.bodies.add_kinematic();
        self.dynamic.push(false);
        BodyHandle(self.dynamic.len() as u32 - 1)
    }

    /// A static body (it never moves; its pose is set in the state).
    pub fn add_static_body(&mut self) -> BodyHandle {
        self.bodies.add_static();
        self.dynamic.push(false);
        BodyHandle(self.dynamic.len() as u32 - 1)
    }

    /// A shape on `body` (`None`: fixed in the world), in group 1 colliding with every group, friction 0.5,
    /// contact offset 5 mm; change them with [`shape_mut`](Self::shape_mut).
    pub fn add_shape(&mut self, body: Option<BodyHandle>, pose: (Vec3, Quat), geometry: ShapeGeometry) -> ShapeHandle {
        self.shapes.push(ShapeDef {
            body,
            pose,
            geometry,
            group: 1,
            mask: u32::MAX,
            friction: 0.5,
            contact_offset: 0.005,
        });
        ShapeHandle(self.shapes.len() as u32 - 1)
    }

    /// The shape's settings.
    pub fn shape_mut(&mut self, s: ShapeHandle) -> &mut ShapeDef {
        &mut self.shapes[s.0 as usize]
    }

    /// Shapes `a` and `b` never collide.
    pub fn filter_pair(&mut self, a: ShapeHandle, b: ShapeHandle) {
        self.filtered.insert((a.0.min(b.0), a.0.max(b.0)));
    }

    /// Runs `world_count` independent copies of this world (each with its own state).
    pub fn replicate(&mut self, world_count: u32) -> &mut Self {
        self.world_count = world_count;
        self
    }

    /// Dynamic or kinematic: a body whose shapes can meet a static shape.
    fn is_dynamic(&self, body: Option<BodyHandle>) -> bool {
        body.is_some_and(|b| {
            let i = b.0 as usize;
            self.dynamic[i] || self.bodies.is_kinematic(i) || self.bodies.link(i).is_some()
        })
    }

    /// Whether shapes `a` and `b` form a contact pair (see the module doc).
    pub fn collides(&self, a: ShapeHandle, b: ShapeHandle) -> bool {
        let (sa, sb) = (&self.shapes[a.0 as usize], &self.shapes[b.0 as usize]);
        a != b
            && (self.is_dynamic(sa.body) || self.is_dynamic(sb.body))
            && (sa.body.is_none() || sa.body != sb.body)
            && sa.group & sb.mask != 0
            && sb.group & sa.mask != 0
            && !self.filtered.contains(&(a.0.min(b.0), a.0.max(b.0)))
    }

    /// Validates and builds: one contact pair per colliding shape pair (SDFs baked through `cache`).
    pub fn build(&self, cache: &SdfCache) -> Result<Model> {
        if self.world_count == 0 {
            return Err(EngineError::Config { field: "world_count", value: "0".into(), expected: "at least 1".into() });
        }
        self.bodies.validate()?;
        let mut contacts = ContactModel { body_count: self.dynamic.len() as u32, pairs: Vec::new() };
        let mut pair_shapes = Vec::new();
        let desc = |s: &ShapeDef| ShapeDesc {
            body: s.body.map_or(NO_BODY, |b| b.0),
            pose: s.pose,
            geometry: s.geometry.clone(),
        };
        for i in 0..self.shapes.len() as u32 {
            for j in i + 1..self.shapes.len() as u32 {
                let (a, b) = (ShapeHandle(i), ShapeHandle(j));
                if !self.collides(a, b) {
                    continue;
                }
                let (sa, sb) = (&self.shapes[i as usize], &self.shapes[j as usize]);
                let mut spec = pair_spec(&desc(sa), &desc(sb), sa.contact_offset.max(sb.contact_offset), cache)?;
                spec.friction = 0.5 * (sa.friction + sb.friction);
                // pair_spec queries its first argument unless the roles swap them; record which is which.
                let query_is_a = spec.body_a == desc(sa).body && spec.a_pose == sa.pose && spec.body_b == desc(sb).body;
                pair_shapes.push(if query_is_a { (a, b) } else { (b, a) });
                contacts.pairs.push(spec);
            }
        }
        Ok(Model { contacts, bodies: self.bodies.clone(), world_count: self.world_count, pair_shapes })
    }
}

/// Mass properties of a solid box of half extents `h` [m] and `mass` [kg] (centre at the origin).
pub fn box_mass_properties(h: Vec3, mass: f32) -> MassProperties {
    let d = Vec3::new(h.y * h.y + h.z * h.z, h.x * h.x + h.z * h.z, h.x * h.x + h.y * h.y) * mass / 3.0;
    MassProperties { volume: 8.0 * h.x * h.y * h.z, mass, com: Vec3::ZERO, inertia: Mat3::from_diagonal(d) }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cache() -> SdfCache {
        SdfCache::new(std::env::temp_dir().join(format!("factory-builder-{}", std::process::id())))
    }

    #[test]
    fn pairs_follow_bodies_groups_and_filters() {
        let mut b = ModelBuilder::default();
        let table = b.add_shape(None, (Vec3::ZERO, Quat::IDENTITY), ShapeGeometry::Plane);
        let box_body = b.add_dynamic_body(&box_mass_properties(Vec3::splat(0.01), 0.1));
        let ball_body = b.add_dynamic_body(&box_mass_properties(Vec3::splat(0.01), 0.1));
        let wall_body = b.add_static_body();
        let bx = b.add_shape(
            Some(box_body),
            (Vec3::ZERO, Quat::IDENTITY),
            ShapeGeometry::Box { half_extents: Vec3::splat(0.01) },
        );
        let ball = b.add_shape(Some(ball_body), (Vec3::ZERO, Quat::IDENTITY), ShapeGeometry::Sphere { radius: 0.01 });
        let wall = b.add_shape(Some(wall_body), (Vec3::ZERO, Quat::IDENTITY), ShapeGeometry::Plane);
        // Static-static never pairs; dynamic-anything does.
        assert!(!b.collides(table, wall));
        assert!(b.collides(table, bx) && b.collides(bx, ball) && b.collides(ball, wall));
        // Groups: the ball (group 2) ignores group 1 except the table, which it lists in its mask.
        b.shape_mut(ball).group = 2;
        b.shape_mut(ball).mask = 2;
        b.shape_mut(table).mask = 1 | 2;
        b.shape_mut(table).group = 2;
        assert!(b.collides(ball, table) && !b.collides(ball, bx) && !b.collides(ball, wall));
        b.filter_pair(bx, table);
        assert!(!b.collides(table, bx));
        let m = b.replicate(8).build(&cache()).unwrap();
        assert_eq!(m.world_count, 8);
        assert_eq!(m.contacts.body_count, 3);
        // Remaining pairs: ball-table, box-wall.
        assert_eq!(m.contacts.pairs.len(), 2, "{:?}", m.pair_shapes);
        assert!(m.pair_shapes.contains(&(ball, table)) && m.pair_shapes.contains(&(bx, wall)));
        assert!(m.contacts.pairs.iter().all(|p| (p.friction - 0.5).abs() < 1e-6));
    }

    #[test]
    fn bad_inputs_are_refused() {
        let mut b = ModelBuilder::default();
        b.add_dynamic_body(&box_mass_properties(Vec3::splat(0.01), 0.0));
        let e = b.build(&cache()).unwrap_err().to_string();
        assert!(e.contains("mass"), "{e}");
        let mut b = ModelBuilder::default();
        b.replicate(0);
        assert!(b.build(&cache()).unwrap_err().to_string().contains("world_count"));
    }
}

//! What the solver steps: the bodies of a world ([`BodyModel`]), every world's poses and velocities
//! ([`BodyState`]), the external wrenches held over a frame ([`Control`]) and the settings
//! ([`SolverConfig`]).

use crate::contact::TransformGpu;
use glam::{Mat3, Quat, Vec3};

/// Static description of the bodies of one world (all worlds share it).
#[derive(Clone, Debug, Default)]
pub struct BodyModel {
    /// Inverse mass [1/kg], shape [body_count]; 0 for static bodies.
    pub body_inv_mass: Vec<f32>,
    /// Inverse inertia about the centre of mass in body axes [1/(kg m^2)], shape [body_count].
    pub body_inv_inertia: Vec<Mat3>,
    /// Centre of mass in the body frame [m], shape [body_count].
    pub body_com: Vec<Vec3>,
    /// Kinematic bodies move with the velocity in the state (no gravity, no contact impulses), shape
    /// [body_count] or shorter (missing entries: not kinematic).
    pub body_kinematic: Vec<bool>,
    /// The articulation link a body is ([`crate::articulation`]; its pose and velocity follow the joints,
    /// and contact impulses on it act through the articulation's joint-space inertia), shape [body_count]
    /// or shorter (missing entries and [`crate::articulation::NO_LINK`]: not a link).
    pub body_link: Vec<u32>,
    /// Gravity [m/s^2].
    pub gravity: Vec3,
}

impl BodyModel {
    pub fn body_count(&self) -> usize {
        self.body_inv_mass.len()
    }

    /// Adds a dynamic body of `mass` [kg], inertia about its COM `inertia` [kg m^2], COM `com` [m].
    pub fn add_dynamic(&mut self, mass: f32, inertia: Mat3, com: Vec3) -> u32 {
        self.body_inv_mass.push(1.0 / mass);
        self.body_inv_inertia.push(inertia.inverse());
        self.body_com.push(com);
        self.body_inv_mass.len() as u32 - 1
    }

    /// Whether body `i` is kinematic.
    pub fn is_kinematic(&self, i: usize) -> bool {
        self.body_kinematic.get(i).copied().unwrap_or(false)
    }

    /// Adds a kinematic body: infinite mass for contacts, moved by the velocity set in the state.
    pub fn add_kinematic(&mut self) -> u32 {
        let i = self.add_static();
        self.body_kinematic.resize(i as usize + 1, false);
        self.body_kinematic[i as usize] = true;
        i
    }

    /// Adds a body that is link `link` of the world's articulation, with its centre of mass `com` [m] in
    /// the link frame (the point its velocity is given at). Only
    /// [`step_cpu_articulated`](super::step_cpu_articulated) steps such bodies; the GPU solver refuses them.
    pub fn add_articulated(&mut self, link: u32, com: Vec3) -> u32 {
        let i = self.add_static();
        self.body_com[i as usize] = com;
        self.body_link.resize(i as usize + 1, crate::articulation::NO_LINK);
        self.body_link[i as usize] = link;
        i
    }

    /// The articulation link body `i` is, if it is one.
    pub fn link(&self, i: usize) -> Option<u32> {
        self.body_link.get(i).copied().filter(|&l| l != crate::articulation::NO_LINK)
    }

    /// Adds a static body (never moves).
    pub fn add_static(&mut self) -> u32 {
        self.body_inv_mass.push(0.0);
        self.body_inv_inertia.push(Mat3::ZERO);
        self.body_com.push(Vec3::ZERO);
        self.body_inv_mass.len() as u32 - 1
    }
}

/// Solver settings (the paper's Table II columns).
#[derive(Clone, Debug, PartialEq)]
pub struct SolverConfig {
    /// Frame time step [s].
    pub dt: f32,
    pub substeps: u32,
    /// Gauss-Seidel sweeps with position bias per substep.
    pub pos_iters: u32,
    /// Sweeps without penetration bias per substep.
    pub vel_iters: u32,
    /// Penetration is resolved no faster than this [m/s].
    pub max_depenetration_velocity: f32,
    /// Separation the solver keeps at rest [m].
    pub rest_offset: f32,
    /// A world whose body exceeds this speed [m/s] (or turns non-finite) is flagged as diverged.
    pub max_speed: f32,
    /// Gauss-Seidel passes over each patch's (up to 4) contacts per sweep, on the geometry sampled for the
    /// sweep (no SDF samples): a cheap inner solve of the patch. Plain Gauss-Seidel (1) converges slowly
    /// where a patch's contacts act almost alike, as on the small base of a tall body (module doc).
    pub patch_iters: u32,
    /// Gauss-Seidel passes per sweep over each patch that touches an articulation link (at least
    /// `patch_iters`; [`step_cpu_articulated`](super::step_cpu_articulated) only). A finger pad holding a
    /// 30 g nut against a 20 kg arm is a chain with a mass ratio near 1:100, which plain sweeps converge
    /// slowly: the pads crept down a nut pressed on its bolt. The rows are few (a pad's few contacts), and
    /// the passes after a sweep's first run on the patch's own Delassus matrix
    /// ([`PatchSweep::Block`](super::PatchSweep::Block)), so extra passes are cheap.
    pub link_patch_iters: u32,
    /// Coulomb friction per patch (the paper's III-B: "Coulomb friction per patch"): each contact may carry
    /// tangential impulse up to mu times an equal share of its patch's total normal impulse, so the patch
    /// as a whole obeys the cone and a contact that momentarily carries little load does not slip. Off:
    /// per contact (each contact's own cone), the measured default of the tests.
    pub friction_per_patch: bool,
}

impl Default for SolverConfig {
    fn default() -> Self {
        SolverConfig {
            dt: 1.0 / 60.0,
            substeps: 1,
            pos_iters: 20,
            vel_iters: 1,
            max_depenetration_velocity: 0.5,
            rest_offset: 0.0,
            max_speed: 100.0,
            patch_iters: 1,
            link_patch_iters: 1,
            friction_per_patch: false,
        }
    }
}

/// Per-step state of every world.
#[derive(Clone, Debug, PartialEq)]
pub struct BodyState {
    /// Body frame poses, shape [world_count * body_count].
    pub body_q: Vec<TransformGpu>,
    /// Linear velocity of the centre of mass [m/s] and angular velocity [rad/s], world frame,
    /// shape [world_count * body_count].
    pub body_qd: Vec<[Vec3; 2]>,
}

/// External wrenches on the bodies, held constant over a frame (the step's control data in
/// docs/ARCHITECTURE.md: what a controller or a test pushes with). Kinematic and static bodies ignore it,
/// as they ignore gravity.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Control {
    /// Force through the centre of mass [N] and torque about it [N m], world frame,
    /// shape [world_count * body_count]; empty for no external wrench.
    pub body_f: Vec<[Vec3; 2]>,
}

impl Control {
    /// No wrench on any of `world_count * body_count` bodies.
    pub fn zeros(world_count: usize, body_count: usize) -> Self {
        Control { body_f: vec![[Vec3::ZERO; 2]; world_count * body_count] }
    }

    /// Adds `force` [N] acting at `point` [m] (both world frame) on body `body` of world `world`: the
    /// force plus its moment about the body's centre of mass at the state's pose.
    pub fn add_force_at(
        &mut self,
        model: &BodyModel,
        state: &BodyState,
        world: usize,
        body: usize,
        force: Vec3,
        point: Vec3,
    ) {
        let g = world * model.body_count() + body;
        let (p, q) = xf(&state.body_q[g]);
        let com = p + q * model.body_com[body];
        self.body_f[g][0] += force;
        self.body_f[g][1] += (point - com).cross(force);
    }

    /// The wrench on global body index `g` (zero where none is set).
    pub(super) fn wrench(&self, g: usize) -> [Vec3; 2] {
        self.body_f.get(g).copied().unwrap_or([Vec3::ZERO; 2])
    }
}

/// A kernel transform's position and rotation.
pub(super) fn xf(t: &TransformGpu) -> (Vec3, Quat) {
    (Vec3::new(t.p[0], t.p[1], t.p[2]), Quat::from_xyzw(t.q[0], t.q[1], t.q[2], t.q[3]))
}

/// Converts a host pose to the kernels' transform (re-exported for callers building states).
pub fn transform(p: Vec3, q: Quat) -> TransformGpu {
    TransformGpu::new(p, q)
}

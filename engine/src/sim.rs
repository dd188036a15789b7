//! Worlds with an articulation and free bodies, stepped frame by frame: contacts generated and reduced
//! on the GPU (or lavapipe) at each frame's start, then the mixed-coordinate Gauss-Seidel step, on the
//! host ([`crate::solver::step_cpu_articulated`], the default) or on the device
//! ([`crate::solver::articulated::GpuArticulatedSolver`], [`ArticulatedSim::use_device_solver`]). The link
//! bodies' poses in the state always follow the joints (forward kinematics), so the contact pipeline sees
//! the fingers where the joints put them.
//!
//! It sits above the layers it combines: the articulation ([`crate::articulation`]), the scene builder
//! ([`crate::builder`]), the contact pipeline ([`crate::contact`]) and the solvers ([`crate::solver`]);
//! none of them refers back to it.
//!
//! On the device the state still comes back to the host every frame (bodies and joints: a few KiB), so
//! the host may read and edit it between frames as with the host solve; the contacts and the warm-start
//! rows stay on the device ([`ArticulatedSim::read_contacts`] reads the contacts when asked).

use crate::articulation::dynamics::forward_kinematics;
use crate::articulation::{ArticulationControl, ArticulationModel, ArticulationState};
use crate::builder::Model;
use crate::contact::{ContactConfig, ContactPipeline, ContactsHost, TransformGpu};
use crate::error::{EngineError, Result};
use crate::gpu::GpuContext;
use crate::solver::articulated::GpuArticulatedSolver;
use crate::solver::{step_cpu_articulated, ArticulationStep, BodyState, Control, SolverConfig, WarmStart};
use glam::{Quat, Vec3};

/// Where the arm, fingers and parts are solved together.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CoupledSolve {
    /// The device on a hardware GPU, the host on a software adapter (lavapipe), where the host was the
    /// faster at 128 worlds in the contact phases (docs/BENCHMARKS.md).
    #[default]
    Auto,
    /// The host reference, [`step_cpu_articulated`] (rayon over worlds).
    Host,
    /// The device kernel, [`GpuArticulatedSolver`] (lavapipe where there is no GPU).
    Device,
}

impl CoupledSolve {
    /// Host or device for `gpu` (auto resolved).
    pub fn resolve(self, gpu: &GpuContext) -> Self {
        match self {
            CoupledSolve::Auto if gpu.is_software() => CoupledSolve::Host,
            CoupledSolve::Auto => CoupledSolve::Device,
            other => other,
        }
    }
}

/// Every world's bodies and joints, and what steps them.
pub struct ArticulatedSim {
    pub model: Model,
    pub articulation: ArticulationModel,
    pub solver: SolverConfig,
    pub pipe: ContactPipeline,
    /// Body poses and velocities, shape [world_count * body_count]; link bodies follow the joints.
    pub state: BodyState,
    /// Joint positions and velocities, shape [world_count * dof_count].
    pub joints: ArticulationState,
    /// The host solve's warm start (unused while the device solves: its rows stay there).
    pub warm: WarmStart,
    /// The contacts of the last frame (generated at its start), each contact with its patch's normal (the
    /// solve samples its own; `pipe.read` gives each contact's); None while the device solves (see
    /// [`read_contacts`](Self::read_contacts)).
    pub contacts: Option<ContactsHost>,
    /// Wall time of the last frame's contact handling (generation, reduction and readback) and of its
    /// coupled solve [s].
    pub last_handling_s: f64,
    pub last_solve_s: f64,
    /// The coupled solve on the device, once [`use_device_solver`](Self::use_device_solver) built it.
    device: Option<GpuArticulatedSolver>,
}

impl ArticulatedSim {
    /// Builds the contact pipeline for `model` (whose link bodies name links of `articulation`) and sets
    /// the link bodies' poses from `joints`.
    pub fn new(
        gpu: &GpuContext,
        model: Model,
        articulation: ArticulationModel,
        solver: SolverConfig,
        contact: &ContactConfig,
        state: BodyState,
        joints: ArticulationState,
    ) -> Result<Self> {
        solver.validate()?;
        let nb = model.bodies.body_count();
        let worlds = model.world_count as usize;
        if state.body_q.len() != worlds * nb || state.body_qd.len() != worlds * nb {
            return Err(EngineError::Config {
                field: "state",
                value: format!("{} poses, {} velocities", state.body_q.len(), state.body_qd.len()),
                expected: format!("{worlds} worlds x {nb} bodies = {}", worlds * nb),
            });
        }
        let dof = articulation.dof_count();
        if joints.joint_q.len() != worlds * dof || joints.joint_qd.len() != worlds * dof {
            return Err(EngineError::Config {
                field: "joints",
                value: format!("{} positions, {} velocities", joints.joint_q.len(), joints.joint_qd.len()),
                expected: format!("{worlds} worlds x {dof} joints = {}", worlds * dof),
            });
        }
        for i in 0..nb {
            if let Some(l) = model.bodies.link(i) {
                if l as usize >= articulation.link_count() {
                    return Err(EngineError::Config {
                        field: "body_link",
                        value: format!("body {i} is link {l}"),
                        expected: format!("a link of '{}' (0..{})", articulation.name, articulation.link_count()),
                    });
                }
            }
        }
        let pipe = ContactPipeline::new(gpu, &model.contacts, model.world_count, contact)?;
        let mut sim = ArticulatedSim {
            model,
            articulation,
            solver,
            pipe,
            state,
            joints,
            warm: WarmStart::default(),
            contacts: None,
            last_handling_s: 0.0,
            last_solve_s: 0.0,
            device: None,
        };
        sim.sync_links();
        Ok(sim)
    }

    pub fn world_count(&self) -> usize {
        self.model.world_count as usize
    }

    /// Puts every link body where the joints put its link (after the joints were set from outside).
    pub fn sync_links(&mut self) {
        for w in 0..self.world_count() {
            self.sync_world_links(w);
        }
    }

    /// [`sync_links`](Self::sync_links) for world `w` alone.
    pub fn sync_world_links(&mut self, w: usize) {
        let nb = self.model.bodies.body_count();
        let dof = self.articulation.dof_count();
        let mut poses = vec![(Vec3::ZERO, Quat::IDENTITY); self.articulation.link_count()];
        forward_kinematics(&self.articulation, &self.joints.joint_q[w * dof..(w + 1) * dof], &mut poses);
        for i in 0..nb {
            if let Some(l) = self.model.bodies.link(i) {
                let (p, q) = poses[l as usize];
                self.state.body_q[w * nb + i] = TransformGpu::new(p, q);
            }
        }
    }

    /// Solves on the device from the next frame on ([`GpuArticulatedSolver`]); every world starts cold
    /// there (no warm start carried over from the host's rows). Refuses what
    /// [`GpuArticulatedSolver::new`] refuses.
    pub fn use_device_solver(&mut self, gpu: &GpuContext) -> Result<()> {
        let dev = GpuArticulatedSolver::new(gpu, &self.pipe, &self.model.bodies, &self.articulation, &self.solver)?;
        dev.write_state(gpu, &self.pipe, &self.state, &self.joints)?;
        self.device = Some(dev);
        Ok(())
    }

    /// Solves where `solve` resolves to on `gpu` (the host unless it resolves to the device).
    pub fn solve_on(&mut self, gpu: &GpuContext, solve: CoupledSolve) -> Result<()> {
        if solve.resolve(gpu) == CoupledSolve::Device && self.device.is_none() {
            self.use_device_solver(gpu)?;
        }
        Ok(())
    }

    /// The device solve, once built: its buffers are the state while a caller steps the worlds on the device
    /// without this type's per-frame upload and readback (an env's resident step: the contact pipeline's
    /// `body_q`, the solver's `body_qd` and the joints in its `scratch`); `state` and `joints` here are then
    /// stale until read back.
    pub fn device_solver(&self) -> Option<&GpuArticulatedSolver> {
        self.device.as_ref()
    }

    /// [`device_solver`](Self::device_solver), mutable (to set the control it holds).
    pub fn device_solver_mut(&mut self) -> Option<&mut GpuArticulatedSolver> {
        self.device.as_mut()
    }

    /// Whether the coupled solve runs on the device.
    pub fn on_device(&self) -> bool {
        self.device.is_some()
    }

    /// Forgets world `w`'s warm start (after the caller reset it: last frame's impulses belong to contacts
    /// that no longer exist), wherever the solve runs.
    pub fn forget_world(&mut self, gpu: &GpuContext, w: usize) {
        self.warm.clear_world(w);
        if let Some(dev) = &self.device {
            dev.forget_world(gpu, w as u32);
        }
    }

    /// The contacts generated at the last frame's start (read back from the device when it solves there,
    /// with each contact's sampled normal; after a host solve, with its patch's).
    pub fn read_contacts(&self, gpu: &GpuContext) -> ContactsHost {
        match &self.contacts {
            Some(c) => c.clone(),
            None => self.pipe.read(gpu),
        }
    }

    /// One frame: contacts at the current poses, then the coupled step under the body wrenches `control`
    /// and the joint torques and drive targets `joint_control`. Returns per world whether it diverged
    /// (non-finite or over the solver's speed bound): such a world is left for the caller to reset.
    /// Panics if a control's shape is not [world_count * body_count] / [world_count * dof_count] (or
    /// empty).
    pub fn step(&mut self, gpu: &GpuContext, control: &Control, joint_control: &ArticulationControl) -> Vec<bool> {
        if self.device.is_some() {
            return self.step_device(gpu, control, joint_control);
        }
        let start = std::time::Instant::now();
        self.pipe.write_body_q(gpu, &self.state.body_q);
        self.pipe.run(gpu);
        let contacts = self.pipe.read_for_solver(gpu);
        let handled = std::time::Instant::now();
        let ok = step_cpu_articulated(
            &self.model.bodies,
            &mut self.state,
            &contacts,
            &self.pipe.flat,
            &self.solver,
            control,
            &mut self.warm,
            Some(ArticulationStep { model: &self.articulation, state: &mut self.joints, control: joint_control }),
        );
        self.last_handling_s = (handled - start).as_secs_f64();
        self.last_solve_s = handled.elapsed().as_secs_f64();
        self.contacts = Some(contacts);
        ok.into_iter().map(|ok| !ok).collect()
    }

    /// [`step`](Self::step) on the device: the state up, contacts and the coupled step in two submissions
    /// (waited for in between, so the two times are apart), the state back.
    fn step_device(&mut self, gpu: &GpuContext, control: &Control, joint_control: &ArticulationControl) -> Vec<bool> {
        let dev = self.device.as_mut().expect("device solver");
        let start = std::time::Instant::now();
        dev.upload(gpu, &self.pipe, &self.state, &self.joints).expect("the state keeps the shapes new() checked");
        if let Err(e) = dev.write_control(gpu, control, joint_control) {
            panic!("ArticulatedSim::step: {e}");
        }
        self.pipe.run(gpu);
        gpu.wait();
        let handled = std::time::Instant::now();
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        dev.encode(&mut enc);
        gpu.queue.submit([enc.finish()]);
        let (state, joints, ok) = dev.read_state(gpu, &self.pipe);
        self.state = state;
        self.joints = joints;
        self.contacts = None;
        self.last_handling_s = (handled - start).as_secs_f64();
        self.last_solve_s = handled.elapsed().as_secs_f64();
        ok.into_iter().map(|ok| !ok).collect()
    }

    /// The mean contact force [N] on pair `pair`'s query shape in world `world` over the last substep
    /// (world frame; the SDF shape's body felt the opposite). On the device this reads the world's rows
    /// back (waits for the GPU).
    pub fn pair_force(&self, gpu: &GpuContext, world: usize, pair: usize) -> Vec3 {
        let impulse = match &self.device {
            Some(dev) => dev.pair_impulse(gpu, world as u32, pair as u32),
            None => self.warm.pair_impulse(world, pair),
        };
        impulse * (self.solver.substeps as f32 / self.solver.dt)
    }

    /// [`pair_force`](Self::pair_force) of each of `pairs` in every world, shape [world_count *
    /// pairs.len()] (world-major). On the device one readback of every world's rows serves them all.
    pub fn pair_forces(&self, gpu: &GpuContext, pairs: &[usize]) -> Vec<Vec3> {
        let per_s = self.solver.substeps as f32 / self.solver.dt;
        match &self.device {
            Some(dev) => dev.pair_impulses(gpu, pairs).into_iter().map(|i| i * per_s).collect(),
            None => (0..self.world_count())
                .flat_map(|w| pairs.iter().map(move |&p| (w, p)))
                .map(|(w, p)| self.warm.pair_impulse(w, p) * per_s)
                .collect(),
        }
    }
}

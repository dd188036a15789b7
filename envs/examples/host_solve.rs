//! The host's coupled solve alone (`solver::step_cpu_articulated_with`), repeated from one Screw state: the
//! nut started on the first full thread and turned down for 30 control steps, then the same frame's contacts
//! solved again and again from the same state, the pads' passes as blocks (`PatchSweep::Block`, the
//! default) and row by row (`PatchSweep::Rows`), alternating.
//!
//!   cargo run --release -p factory-envs --example host_solve -- [worlds] [solves per round] [rounds]

use factory_engine::articulation::ArticulationControl;
use factory_engine::gpu::GpuContext;
use factory_engine::solver::{step_cpu_articulated_with, ArticulationStep, Control, PatchSweep};
use factory_envs::{Env, FrankaNutBolt, FrankaNutBoltConfig, StepBuffers};
use std::time::Instant;

fn main() {
    let arg = |i: usize, default: usize| std::env::args().nth(i).map(|s| s.parse().unwrap()).unwrap_or(default);
    let (worlds, reps, rounds) = (arg(1, 32), arg(2, 10), arg(3, 2));
    let cfg = FrankaNutBoltConfig { start_engaged: true, ..Default::default() };
    let mut env = FrankaNutBolt::new(&cfg, worlds, 0).unwrap();
    let mut buf = StepBuffers::new(env.spec());
    env.reset(&mut buf);
    // Down (z) and the full clockwise yaw increment: the nut turns on the thread in the closed hand.
    let mut action = vec![0.0f32; worlds * 12];
    for a in action.chunks_mut(12) {
        (a[2], a[5]) = (-0.3, 1.0);
    }
    for _ in 0..30 {
        env.step(&action, &mut buf);
    }
    let gpu = GpuContext::global().unwrap();
    let sim = &env.scene().sim;
    sim.pipe.write_body_q(gpu, &sim.state.body_q);
    sim.pipe.run(gpu);
    let contacts = sim.pipe.read(gpu);
    let rows: usize = contacts.patches.iter().flatten().map(|p| p.contacts.len()).sum();
    println!("{worlds} worlds, {:.0} contact rows per world", rows as f64 / worlds as f64);
    let control = Control::zeros(worlds, sim.model.bodies.body_count());
    let dof = sim.articulation.dof_count();
    let joint_control = ArticulationControl { joint_tau: vec![0.0; worlds * dof], joint_target_q: vec![] };
    for round in 1..=rounds {
        for sweep in [PatchSweep::Block, PatchSweep::Rows] {
            let start = Instant::now();
            for _ in 0..reps {
                let (mut state, mut joints, mut warm) = (sim.state.clone(), sim.joints.clone(), sim.warm.clone());
                step_cpu_articulated_with(
                    &sim.model.bodies,
                    &mut state,
                    &contacts,
                    &sim.pipe.flat,
                    &sim.solver,
                    &control,
                    &mut warm,
                    Some(ArticulationStep { model: &sim.articulation, state: &mut joints, control: &joint_control }),
                    sweep,
                );
            }
            let ms = start.elapsed().as_secs_f64() * 1e3 / reps as f64;
            println!("round {round}: {sweep:?} {ms:.1} ms per frame's solve");
        }
    }
}

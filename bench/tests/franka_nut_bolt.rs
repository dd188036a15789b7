//! The Franka with the generated ISO M16 nut (factory-bench scene franka-nut-bolt): the gripper holds the nut
//! against gravity, and the scripted pick-place-screw seats it on its bolt. Contacts on the GPU pipeline
//! (lavapipe on CI), the coupled arm-and-parts solve on the host.

use factory_bench::franka::{run_franka_nut_bolt, CoupledSolve, FrankaNutBolt, FrankaNutBoltRun, Stage};
use factory_engine::articulation::dynamics::world_dynamics;
use factory_engine::gpu::GpuContext;
use glam::Vec3;

/// Issue 21: the gripper holds the M16 nut against gravity for 10 s with less than 0.5 mm slip.
const SLIP_MAX: f32 = 0.5e-3;

/// The nut's origin in the fingertip frame of world `w` [m].
fn nut_in_tip(scene: &FrankaNutBolt, w: usize) -> Vec3 {
    let dof = scene.sim.articulation.dof_count();
    let q = &scene.sim.joints.joint_q[w * dof..(w + 1) * dof];
    let (tp, tq) = world_dynamics(&scene.sim.articulation, q, &vec![0.0; dof], &scene.tip).frame_pose;
    tq.inverse() * (scene.nut_pose(w).0 - tp)
}

#[test]
fn gripper_holds_the_m16_nut_against_gravity_for_10_s() {
    let gpu = GpuContext::global().unwrap();
    let run = FrankaNutBoltRun { worlds: 2, ..Default::default() };
    let mut scene = FrankaNutBolt::new(gpu, &run).unwrap();
    // Pick the nut and lift it, then hold it where the lift ended.
    scene.freeze_at = Some(Stage::OverBolt);
    let dt = run.solver.dt;
    let mut t = 0.0;
    while (0..2).any(|w| scene.stage(w) < Stage::OverBolt) {
        assert!(
            t < 15.0,
            "the nut was not picked and lifted within 15 s: stages {:?}",
            [scene.stage(0), scene.stage(1)]
        );
        let (diverged, _) = scene.frame(gpu, t);
        assert!(diverged.iter().all(|d| !d));
        t += dt;
    }
    for _ in 0..30 {
        scene.frame(gpu, t);
        t += dt;
    }
    let start: Vec<Vec3> = (0..2).map(|w| nut_in_tip(&scene, w)).collect();
    let lifted: Vec<f32> = (0..2).map(|w| scene.nut_pose(w).0.z).collect();
    let mut worst = [0.0f32; 2];
    for _ in 0..600 {
        let (diverged, _) = scene.frame(gpu, t);
        assert!(diverged.iter().all(|d| !d));
        t += dt;
        for w in 0..2 {
            worst[w] = worst[w].max((nut_in_tip(&scene, w) - start[w]).length());
        }
    }
    for w in 0..2 {
        eprintln!(
            "world {w}: nut lifted to {:.1} mm above its seat height, slip over 10 s {:.4} mm",
            lifted[w] * 1e3,
            worst[w] * 1e3
        );
        assert!(lifted[w] > 0.03, "world {w}: the nut was not lifted ({} m)", lifted[w]);
        assert!(worst[w] < SLIP_MAX, "world {w}: the nut slipped {} m in the hand", worst[w]);
    }
}

/// The scripted Franka + nut-and-bolt scene over 64 worlds, each with its own drawn nut position and yaw:
/// no world diverges, and the nut ends seated (within one pitch of seated, on the bolt's axis) in at least
/// SEATED_MIN of them, issue 21's 95%. Measured 64 of 64 (2026-12-04, commit f4fc108 plus the chamfer on).
/// Regression test for the bolt's flat-cut tip: 47 of 64 (73%), the nut jamming part-way down the thread or
/// the pads slipping on it as it landed on the tip (docs/BENCHMARKS.md).
const SEATED_MIN: f64 = 0.95;

#[test]
fn franka_nut_bolt_seats_the_nut_in_most_of_64_worlds() {
    let gpu = GpuContext::global().unwrap();
    let report = run_franka_nut_bolt(gpu, &FrankaNutBoltRun { worlds: 64, ..Default::default() }).unwrap();
    eprintln!("{}", report.summary());
    for (w, (h, off)) in report.nut_height_mm.iter().zip(&report.nut_off_axis_mm).enumerate() {
        if *h > 2.0 || *off > 8.0 {
            eprintln!("  world {w}: nut {h:.2} mm above seated, {off:.2} mm off the bolt's axis");
        }
    }
    assert_eq!(report.diverged_worlds, 0);
    assert!(report.stage_reached[5] == 64, "every world should reach the screw stage: {:?}", report.stage_reached);
    assert!(report.success_rate >= SEATED_MIN, "seated in {:.1}% of 64 worlds", report.success_rate * 100.0);
}

/// The same script with the coupled solve on the device (solver::articulated; lavapipe on CI), one world
/// through the whole episode: picked, placed and seated, nothing diverged. Measured: seated at 39.0 s (the
/// host: 39.2 s), deepest contact 0.15 mm (2026-12-05).
#[test]
fn the_device_solve_seats_the_nut() {
    let gpu = GpuContext::global().unwrap();
    let report =
        run_franka_nut_bolt(gpu, &FrankaNutBoltRun { worlds: 1, solve: CoupledSolve::Device, ..Default::default() })
            .unwrap();
    eprintln!("{}", report.summary());
    assert_eq!(report.solve, CoupledSolve::Device);
    assert_eq!(report.diverged_worlds, 0);
    assert_eq!(report.success_rate, 1.0, "the nut ended {:?} mm above its seat", report.nut_height_mm);
    assert!(report.max_penetration_mm < 1.0, "contacts penetrated {} mm", report.max_penetration_mm);
}

//! One world of the Screw env under a constant yaw action; prints the fingertip, the nut and joint 7 every
//! 10 steps (EVERY=n) until the episode ends, and the mean force on the finger pads every 50.
//!
//!   cargo run --release -p factory-envs --example screw_diag -- <a_yaw> [a_z] [steps]
//!
//! Config overrides from the environment: ARM_DAMPING, WRIST_DAMPING, SUBSTEPS, POS_ITERS, PATCH_ITERS,
//! GRASP_HEIGHT, FINGER_KP, FINGER_KD, START_ENGAGED, BOLT_TIP_CHAMFER. DUMP=t1,t2,... prints the pad
//! contacts at those steps; FK_START prints where Q_START puts the fingertip and exits.

use factory_engine::gpu::GpuContext;
use factory_envs::{Env, FrankaNutBolt, FrankaNutBoltConfig, StepBuffers};

/// Where the finger-force observation starts: after the 26 of fingertip and nut pose and twist.
const FINGER_FORCE: usize = 26;

/// Overrides `field` from the environment variable `name` when it is set.
fn set<T: std::str::FromStr>(name: &str, field: &mut T) {
    if let Ok(v) = std::env::var(name) {
        *field = v.parse().unwrap_or_else(|_| panic!("{name}={v} does not parse"));
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let yaw: f32 = args.get(1).map(|s| s.parse().unwrap()).unwrap_or(-0.8);
    let z: f32 = args.get(2).map(|s| s.parse().unwrap()).unwrap_or(0.0);
    let steps: usize = args.get(3).map(|s| s.parse().unwrap()).unwrap_or(1000);
    let mut cfg = FrankaNutBoltConfig::default();
    set("ARM_DAMPING", &mut cfg.arm_damping);
    set("WRIST_DAMPING", &mut cfg.wrist_damping);
    set("SUBSTEPS", &mut cfg.substeps);
    set("POS_ITERS", &mut cfg.pos_iters);
    set("PATCH_ITERS", &mut cfg.link_patch_iters);
    set("GRASP_HEIGHT", &mut cfg.grasp_height);
    set("FINGER_KP", &mut cfg.finger_stiffness);
    set("FINGER_KD", &mut cfg.finger_damping);
    set("START_ENGAGED", &mut cfg.start_engaged);
    set("BOLT_TIP_CHAMFER", &mut cfg.bolt_tip_chamfer);
    cfg.observe_finger_force = true;
    let mut e = FrankaNutBolt::new(&cfg, 1, 0).unwrap();
    let mut b = StepBuffers::new(e.spec());
    e.reset(&mut b);
    if std::env::var("FK_START").is_ok() {
        let s = e.scene_mut();
        let pose = s.nut_pose(0);
        s.reset_world(
            factory_engine::gpu::GpuContext::global().unwrap(),
            0,
            pose,
            &factory_envs::franka::scene::Q_START,
        );
        s.sim.sync_links();
        let arm = s.arm();
        println!("fingertip at Q_START: {:?} quat {:?}", arm.ee_pos[0], arm.ee_quat[0]);
        return;
    }
    // DUMP=t1,t2,...: print the contacts other than the thread's at those steps.
    let dump: Vec<usize> =
        std::env::var("DUMP").map(|v| v.split(',').map(|x| x.parse().unwrap()).collect()).unwrap_or_default();
    let every: usize = std::env::var("EVERY").map(|v| v.parse().unwrap()).unwrap_or(10);
    let mut fz_sum = glam::Vec3::ZERO;
    let mut a = [0.0f32; 12];
    a[2] = z;
    a[5] = yaw;
    for t in 0..steps {
        let prev = b.observation.clone();
        let q = e.scene().sim.joints.joint_q.clone();
        e.step(&a, &mut b);
        let o = if b.done(0) { &prev } else { &b.observation };
        {
            // The env's finger-force observation: the pads' forces on the nut; the pads felt the opposite.
            let on_nut = |i: usize| glam::Vec3::new(o[i], o[i + 1], o[i + 2]);
            fz_sum -= on_nut(FINGER_FORCE) + on_nut(FINGER_FORCE + 3);
            if t % 50 == 49 {
                println!("  mean pad force over the last 50 steps {:?} N", fz_sum / 50.0);
                fz_sum = glam::Vec3::ZERO;
            }
        }
        if dump.contains(&t) {
            let s = e.scene();
            let (np, _) = s.nut_pose(0);
            let pc = s.sim.model.contacts.pairs.len();
            // Read again for each contact's own normal (the step keeps its patch's), sampled at the poses now.
            {
                let c = &s.sim.pipe.read(GpuContext::global().unwrap());
                for p in (0..pc).filter(|&p| p != s.thread_pair) {
                    println!(
                        "  pair {p} force on the query shape {:?} N",
                        s.sim.pair_force(GpuContext::global().unwrap(), 0, p)
                    );
                    for patch in &c.patches[p] {
                        println!("  pair {p} patch n {:?} area {:.2e}", patch.normal, patch.area);
                        for k in &patch.contacts {
                            let r = k.point - np;
                            println!(
                                "    at nut+[{:6.2} {:6.2} {:6.2}] mm depth {:6.3} mm n [{:6.3} {:6.3} {:6.3}]",
                                r.x * 1e3,
                                r.y * 1e3,
                                r.z * 1e3,
                                k.depth * 1e3,
                                k.normal.x,
                                k.normal.y,
                                k.normal.z
                            );
                        }
                    }
                }
            }
        }
        if t % every == 0 || b.done(0) {
            let d = ((o[0] - o[13]).powi(2) + (o[1] - o[14]).powi(2) + (o[2] - o[15]).powi(2)).sqrt();
            println!(
                "t {t:4} tip [{:7.4} {:7.4} {:7.4}] nut [{:7.4} {:7.4} {:7.4}] |tip-nut| {:.4} q {:?} fingers {:.4} {:.4}",
                o[0], o[1], o[2], o[13], o[14], o[15], d,
                q[..7].iter().map(|x| (x * 1000.0).round() / 1000.0).collect::<Vec<_>>(), q[7], q[8]
            );
        }
        if b.done(0) {
            println!("ended at step {} success {}", t + 1, b.success[0]);
            break;
        }
    }
}

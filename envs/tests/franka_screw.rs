//! The FrankaNutBolt env with the Screw task on the simulator (lavapipe or a GPU).

use factory_envs::franka::nut_bolt::{ScrewRandomization, StartDraw};
use factory_envs::{Env, FrankaNutBolt, FrankaNutBoltConfig, StepBuffers};

/// The nut started on the bolt's first full thread (below the tip's chamfer), not on the tip.
fn engaged() -> FrankaNutBoltConfig {
    FrankaNutBoltConfig { start_engaged: true, ..Default::default() }
}

fn env(worlds: usize, cfg: FrankaNutBoltConfig) -> (FrankaNutBolt, StepBuffers) {
    let e = FrankaNutBolt::new(&cfg, worlds, 0).unwrap();
    let b = StepBuffers::new(e.spec());
    (e, b)
}

/// The reset: fingertip on the bolt's axis at `grasp_height` above the nut's bottom, the nut on the bolt's
/// first full thread (11 pitches of 2 mm above its seat: the bolt's tip is 25 mm above the 16 mm head and
/// its chamfer takes the top 1.2 mm); 26 observations, 12 actions; a negative reward.
#[test]
fn screw_reset_puts_the_nut_on_the_first_thread_in_the_hand() {
    let cfg = engaged();
    let (mut e, mut b) = env(2, cfg.clone());
    assert_eq!(e.spec().observation_dim(), 26);
    assert_eq!(e.spec().action_dim(), 12);
    e.reset(&mut b);
    for w in 0..2 {
        let o = &b.observation[w * 26..(w + 1) * 26];
        let (tip, nut) = ([o[0], o[1], o[2]], [o[13], o[14], o[15]]);
        assert!(tip[0].abs() < 1e-3 && tip[1].abs() < 1e-3, "{tip:?}");
        assert!((tip[2] - (0.016 + 0.022 + cfg.grasp_height)).abs() < 1e-3, "{tip:?}");
        assert!(nut[0].abs() < 1e-4 && nut[1].abs() < 1e-4, "{nut:?}");
        assert!((nut[2] - (0.022 + 0.016 + 0.0065)).abs() < 5e-4, "nut centre of mass {nut:?}");
    }
    e.step(&[0.0; 24], &mut b);
    assert!(b.reward.iter().all(|r| r.is_finite() && *r < 0.0), "{:?}", b.reward);
}

/// `start_turns_down` puts the nut whole pitches below the first full thread (5 of the 11: 12 mm above its
/// seat, 0.52 of the descent from the tip's 25 mm), and the env's profile counts each world-step in that
/// tenth of its progress and times the step's stages. Deeper than two pitches above the seat, or without
/// `start_engaged`, is refused by name.
#[test]
fn deeper_starts_and_the_progress_profile() {
    let cfg = FrankaNutBoltConfig { start_turns_down: 5, ..engaged() };
    let (mut e, mut b) = env(2, cfg);
    e.reset(&mut b);
    for w in 0..2 {
        let nut_z = b.observation[w * 26 + 15];
        assert!((nut_z - (0.012 + 0.016 + 0.0065)).abs() < 5e-4, "nut centre of mass z {nut_z}");
    }
    for _ in 0..3 {
        e.step(&[0.0; 24], &mut b);
    }
    let p = e.profile().expect("the Franka env keeps a profile");
    assert_eq!(p.progress_steps, [0, 0, 0, 0, 0, 6, 0, 0, 0, 0]);
    let names: Vec<&str> = p.stage_seconds.iter().map(|(n, _)| *n).collect();
    assert_eq!(names, ["controller", "contacts", "solve", "task"]);
    assert!(p.stage_seconds.iter().all(|(_, s)| *s >= 0.0) && p.stage_seconds[1].1 > 0.0, "{p:?}");
    // The nut on the thread and the pads on its flats: contacts every step, from more candidates.
    let work: Vec<&str> = p.work.iter().map(|(n, _)| *n).collect();
    assert_eq!(work, ["candidates", "contacts"]);
    assert!(p.work[1].1 >= 6 && p.work[0].1 >= p.work[1].1, "{:?}", p.work);
    for (cfg, needle) in [
        (FrankaNutBoltConfig { start_turns_down: 10, ..engaged() }, "valid: 0..=9"),
        (FrankaNutBoltConfig { start_turns_down: 1, ..Default::default() }, "needs start_engaged"),
    ] {
        let err = FrankaNutBolt::new(&cfg, 1, 0).err().expect("refused").to_string();
        assert!(err.contains("start_turns_down") && err.contains(needle), "{err}");
    }
}

/// With zero actions (yaw not turning) the closed hand holds the nut on the bolt's first thread for 5 s: the
/// episode still running (no slip, fall or far error), the nut's height within 0.5 mm of its start (the nut
/// stays on its thread) and the nut within 0.5 mm of the bolt's axis. Regression test for Factory's 2
/// substeps x 16 iterations, under which the pads slid up the nut and dropped it within 0.7 s, and for the
/// start on the tip, where the hand drifted 4.7 mm.
#[test]
fn zero_actions_hold_the_nut_on_the_thread_for_5_s() {
    let cfg = FrankaNutBoltConfig { unidirectional_rot: false, ..engaged() };
    let (mut e, mut b) = env(1, cfg);
    e.reset(&mut b);
    let nut0 = e.scene().nut_pose(0).0;
    let tip0 = [b.observation[0], b.observation[1], b.observation[2]];
    for t in 0..300 {
        e.step(&[0.0; 12], &mut b);
        assert!(!b.done(0), "episode ended at step {t}");
    }
    let nut = e.scene().nut_pose(0).0;
    let tip = [b.observation[0], b.observation[1], b.observation[2]];
    let d_tip = ((tip[0] - tip0[0]).powi(2) + (tip[1] - tip0[1]).powi(2) + (tip[2] - tip0[2]).powi(2)).sqrt();
    eprintln!("nut moved {:.3} mm, fingertip {:.3} mm", 1e3 * nut.distance(nut0), 1e3 * d_tip);
    assert!((nut.z - nut0.z).abs() < 5e-4, "nut height changed {} m", nut.z - nut0.z);
    assert!(nut.truncate().length() < 5e-4, "nut off the bolt's axis by {} m", nut.truncate().length());
}

/// With the nut still on its thread and the hand not turning, the fingertip stays where it grasped the nut,
/// held there by the pads' friction, within 1 mm over 500 steps. Regression test: with the fingers' drive at
/// 2000 N/m (24 N of squeeze a pad) the fingertip rose 7.6 mm along the nut and stopped near its top, and
/// while screwing the pads climbed off the nut before it was seated; at Factory's 500 N/m it stays.
#[test]
fn the_pads_do_not_creep_up_a_still_nut() {
    let cfg = FrankaNutBoltConfig { unidirectional_rot: false, ..engaged() };
    let (mut e, mut b) = env(1, cfg);
    e.reset(&mut b);
    let gap0 = b.observation[15] - b.observation[2];
    for _ in 0..500 {
        e.step(&[0.0; 12], &mut b);
    }
    let gap = b.observation[15] - b.observation[2];
    eprintln!("the fingertip moved {:.3} mm along the nut", 1e3 * (gap0 - gap));
    assert!((gap0 - gap).abs() < 1e-3, "the fingertip moved {:.2} mm along the nut", 1e3 * (gap0 - gap));
}

/// Full clockwise yaw for 48 steps (0.8 s): the hand turns the nut and the nut follows the thread, sinking
/// one pitch per turn (within 25%: the loose fit's clearance lets it sit on either flank).
#[test]
fn clockwise_yaw_drives_the_nut_down_the_thread() {
    let (mut e, mut b) = env(1, engaged());
    e.reset(&mut b);
    let (p0, q0) = e.scene().nut_pose(0);
    let mut a = [0.0f32; 12];
    a[5] = 1.0; // unidirectional: the full clockwise increment
    let mut turned = 0.0f32;
    let mut last = q0;
    for t in 0..48 {
        e.step(&a, &mut b);
        assert!(!b.done(0), "episode ended at step {t}");
        let q = e.scene().nut_pose(0).1;
        // Accumulate the yaw increments (the nut turns more than half a turn).
        let dq = q * last.conjugate();
        let (axis, angle) = dq.to_axis_angle();
        turned += if axis.z < 0.0 { -angle } else { angle };
        last = q;
    }
    let p = e.scene().nut_pose(0).0;
    let turns = -turned / std::f32::consts::TAU;
    let sunk = p0.z - p.z;
    let pitch = e.scene().nb.pitch;
    eprintln!("turned {turns:.3} turns clockwise, sank {:.3} mm: {:.3} mm per turn", 1e3 * sunk, 1e3 * sunk / turns);
    assert!(turns > 0.25, "the nut turned {turns} turns");
    assert!(
        (sunk / turns - pitch).abs() < 0.25 * pitch,
        "{} mm per turn, pitch {} mm",
        1e3 * sunk / turns,
        1e3 * pitch
    );
}

/// A moderate constant clockwise yaw (a = -0.6: 0.02 rad per step) screws the nut down for 5 s: the nut sinks
/// at least 3 mm (1.5 pitches; the wrist turns at ~2.4 rad/s) and the fingertip stays within 1.5 mm of where
/// it sat on the nut (the hand follows the nut down instead of climbing its flats). Regression test for arm damping 0.1 on every joint
/// and the robot standing on the table top instead of on the floor below it: the free axes of Factory's
/// z-and-yaw controller drifted, the hand rose ~9 mm along the nut within 2 s of turning and dropped it,
/// and no constant action screwed the nut more than 2 mm.
#[test]
fn the_hand_screws_the_nut_down_without_climbing_it() {
    let (mut e, mut b) = env(1, engaged());
    e.reset(&mut b);
    let gap = |o: &[f32]| glam::Vec3::new(o[0] - o[13], o[1] - o[14], o[2] - o[15]);
    let gap0 = gap(&b.observation);
    let z0 = e.scene().nut_pose(0).0.z;
    let mut a = [0.0f32; 12];
    a[5] = -0.6;
    for t in 0..300 {
        e.step(&a, &mut b);
        assert!(!b.done(0), "episode ended at step {t}");
    }
    let sunk = z0 - e.scene().nut_pose(0).0.z;
    let moved = gap(&b.observation).distance(gap0);
    eprintln!("nut sank {:.2} mm; fingertip moved {:.2} mm relative to the nut", 1e3 * sunk, 1e3 * moved);
    assert!(sunk > 3e-3, "the nut sank {sunk} m in 5 s");
    assert!(moved < 1.5e-3, "the fingertip moved {moved} m relative to the nut");
}

/// The Screw task is solvable in the env's physics: a constant clockwise yaw (a = -0.6) with no other action
/// screws the nut from the first thread down to its seat (within one pitch: success) inside 2000 steps
/// (33 s; measured: success at step 1609), the fingertip riding down with it. Regression test
/// for the pads creeping up the nut under a 24 N squeeze: every constant action failed after 14-21 mm.
#[test]
fn a_constant_clockwise_yaw_seats_the_nut() {
    let (mut e, mut b) = env(1, engaged());
    e.reset(&mut b);
    let mut a = [0.0f32; 12];
    a[5] = -0.6;
    for t in 0..2000 {
        e.step(&a, &mut b);
        if b.done(0) {
            eprintln!("episode ended at step {} (success {})", t + 1, b.success[0]);
            assert!(b.success[0] > 0.5, "the episode failed at step {} instead of seating the nut", t + 1);
            return;
        }
    }
    panic!("the nut was not seated in 2000 steps (it sank to {} m)", e.scene().nut_pose(0).0.z);
}

/// The env's scripted controller (`Env::scripted_actions`, factory-eval's `scripted` baseline) seats the nut
/// from Factory's start on the bolt's tip at Table III's hand angles: every world's first episode ends in
/// success (measured: steps 1620-1731). With the fingertip offsets drawn as well the script loses some
/// nuts off the tip (one of these four worlds, at step 109; docs/RESULTS.md has its rate).
#[test]
fn the_scripted_controller_seats_the_nut_from_table_iii_hand_angles() {
    let randomize = ScrewRandomization { hand_angle_deg: [-90.0, 90.0], ..Default::default() };
    let (mut e, mut b) = env(4, FrankaNutBoltConfig { randomize, ..Default::default() });
    e.reset(&mut b);
    let mut ended: [Option<(u32, bool, Option<&str>)>; 4] = [None; 4];
    for t in 1..=e.config().max_episode_steps {
        let a = e.scripted_actions().expect("the Screw env has a script");
        e.step(&a, &mut b);
        for w in 0..4 {
            if ended[w].is_none() && b.done(w) {
                ended[w] = Some((t, b.success[w] > 0.5, b.end_cause(w)));
            }
        }
        if ended.iter().all(Option::is_some) {
            break;
        }
    }
    eprintln!("scripted episodes (step, success, cause): {ended:?}");
    assert!(ended.iter().all(|e| matches!(e, Some((_, true, _)))), "{ended:?}");
}

/// A saved state restores exactly: two envs, one loaded from the other's state mid-episode, step the same
/// actions to the same observations and rewards, bitwise.
#[test]
fn saved_state_continues_bitwise() {
    let (mut a, mut ba) = env(2, FrankaNutBoltConfig::default());
    a.reset(&mut ba);
    let act: Vec<f32> = (0..24).map(|i| ((i * 5) % 7) as f32 / 7.0 - 0.5).collect();
    for _ in 0..10 {
        a.step(&act, &mut ba);
    }
    let saved = a.save_state().unwrap();
    let (mut b, mut bb) = env(2, FrankaNutBoltConfig::default());
    b.reset(&mut bb);
    b.load_state(&saved).unwrap();
    for _ in 0..10 {
        a.step(&act, &mut ba);
        b.step(&act, &mut bb);
    }
    assert_eq!(ba.observation, bb.observation);
    assert_eq!(ba.reward, bb.reward);
    assert!(b.load_state(&saved[..saved.len() - 1]).is_err());
}

/// The paper's Table III Screw ranges, all seven (hand angle +-90 deg; fingertip +-3 mm along the closing
/// axis and the flats, 0-3 mm up; the nut +-3.5 mm along the pads, -6.5-1.0 mm up and +-15 deg turned in the
/// hand), with the balanced grip that an off-centre nut needs: every drawn start is a grasp that holds still
/// with zero actions for 2 s (no episode ends, each nut within 0.5 mm of its start height), and the starts
/// differ.
#[test]
fn table_iii_resets_are_stable_grasps() {
    let randomize = ScrewRandomization::table_iii();
    let cfg = FrankaNutBoltConfig { unidirectional_rot: false, balanced_grip: true, randomize, ..engaged() };
    let (mut e, mut b) = env(4, cfg);
    e.reset(&mut b);
    let start: Vec<_> = (0..4).map(|w| e.scene().nut_pose(w)).collect();
    for w in 0..4 {
        let o = &b.observation[w * 26..(w + 1) * 26];
        let off = ((o[0] - o[13]).powi(2) + (o[1] - o[14]).powi(2)).sqrt();
        // At most the corner of the ranges: 3 mm along the closing axis, 3 + 3.5 mm along the flats.
        assert!(off < 7.2e-3, "world {w}: fingertip {off} m off the nut's axis");
    }
    let yaws: Vec<f32> = start.iter().map(|(_, q)| q.to_euler(glam::EulerRot::XYZ).2).collect();
    assert!(yaws.iter().any(|y| y.abs() > 0.1), "hand angles not drawn: {yaws:?}");
    for t in 0..120 {
        e.step(&[0.0; 48], &mut b);
        for w in 0..4 {
            assert!(!b.done(w), "world {w} ended at step {t}");
        }
    }
    for (w, (p0, _)) in start.iter().enumerate() {
        let p = e.scene().nut_pose(w).0;
        assert!((p.z - p0.z).abs() < 5e-4, "world {w}: nut height changed {} m", p.z - p0.z);
    }
}

/// Table III's seven Screw ranges are all drawn: over 256 starts (64 worlds reset 4 times) every draw lies
/// inside its range and spans at least 90% of it. And the state is the draw: the hand's yaw and the nut's
/// yaw in the hand, and the fingertip's offset from the nut's axis in the hand's frame (the fingertip
/// offset less the nut's offset in the hand), as drawn.
#[test]
fn table_iii_draws_span_every_range_and_place_hand_and_nut() {
    let r = ScrewRandomization::table_iii();
    let cfg = FrankaNutBoltConfig { balanced_grip: true, randomize: r.clone(), ..Default::default() };
    let (mut e, mut b) = env(64, cfg);
    type Field = fn(&StartDraw) -> f32;
    let fields: [(&str, [f32; 2], Field); 7] = [
        ("hand_angle_deg", r.hand_angle_deg, |d| d.hand_angle_deg),
        ("fingertip x", r.fingertip_offset_mm[0], |d| d.fingertip_offset_mm[0]),
        ("fingertip y", r.fingertip_offset_mm[1], |d| d.fingertip_offset_mm[1]),
        ("fingertip z", r.fingertip_offset_mm[2], |d| d.fingertip_offset_mm[2]),
        ("nut-in-gripper y", r.nut_in_gripper_mm[0], |d| d.nut_in_gripper_mm[0]),
        ("nut-in-gripper z", r.nut_in_gripper_mm[1], |d| d.nut_in_gripper_mm[1]),
        ("nut-in-gripper yaw", r.nut_in_gripper_yaw_deg, |d| d.nut_in_gripper_yaw_deg),
    ];
    let yaw_of = |q: glam::Quat| {
        let x = q * glam::Vec3::X;
        x.y.atan2(x.x)
    };
    let wrap = |a: f32| (a + std::f32::consts::PI).rem_euclid(std::f32::consts::TAU) - std::f32::consts::PI;
    let mut draws = Vec::new();
    let mut hand_yaw0 = None;
    let mut nut_yaw0 = None;
    for _ in 0..4 {
        e.reset(&mut b);
        for (w, d) in e.start_draws().iter().enumerate() {
            let o = &b.observation[w * 26..(w + 1) * 26];
            let tip_q = glam::Quat::from_slice(&o[3..7]);
            let nut_q = glam::Quat::from_slice(&o[16..20]);
            let angle = d.hand_angle_deg.to_radians();
            // Yaws up to a constant (the frames' own orientation at a zero draw), taken from the first world.
            let hand = *hand_yaw0.get_or_insert(wrap(yaw_of(tip_q) - angle));
            let nut = *nut_yaw0.get_or_insert(wrap(yaw_of(nut_q) - angle - d.nut_in_gripper_yaw_deg.to_radians()));
            assert!(wrap(yaw_of(tip_q) - angle - hand).abs() < 2e-3, "world {w}: hand yaw, {d:?}");
            let nut_err = wrap(yaw_of(nut_q) - angle - d.nut_in_gripper_yaw_deg.to_radians() - nut);
            assert!(nut_err.abs() < 2e-3, "world {w}: nut yaw off by {nut_err} rad, {d:?}");
            let off = glam::Quat::from_rotation_z(-angle) * glam::Vec3::new(o[0] - o[13], o[1] - o[14], 0.0) * 1e3;
            let want = [d.fingertip_offset_mm[0], d.fingertip_offset_mm[1] - d.nut_in_gripper_mm[0]];
            assert!(
                (off.x - want[0]).abs() < 0.2 && (off.y - want[1]).abs() < 0.2,
                "world {w}: fingertip at {off} mm from the nut's axis in the hand, drawn {want:?}"
            );
        }
        draws.extend_from_slice(e.start_draws());
    }
    for (name, [lo, hi], get) in fields {
        let v: Vec<f32> = draws.iter().map(get).collect();
        let (min, max) = v.iter().fold((f32::MAX, f32::MIN), |(a, b), &x| (a.min(x), b.max(x)));
        assert!(min >= lo && max <= hi, "{name}: draws [{min}, {max}] outside [{lo}, {hi}]");
        assert!(max - min >= 0.9 * (hi - lo), "{name}: draws span [{min}, {max}] of [{lo}, {hi}]");
    }
}

/// An offset along the closing axis without the balanced grip is refused, naming the key that allows it.
#[test]
fn closing_axis_offsets_need_the_balanced_grip() {
    let randomize = ScrewRandomization::table_iii();
    let Err(e) = FrankaNutBolt::new(&FrankaNutBoltConfig { randomize, ..Default::default() }, 1, 0) else {
        panic!("an off-centre grasp with independent finger drives was accepted");
    };
    let msg = e.to_string();
    assert!(msg.contains("randomize.fingertip_offset_mm") && msg.contains("balanced_grip = true"), "{msg}");
}

/// Factory's start, the nut resting on the bolt's tip (the default), on ISO 4753's chamfer: under 16
/// constant actions (8 yaws x a_z = -0.05, -0.2: `ZS=-0.05,-0.2 examples/screw_sweep`) at most 6 episodes
/// fail within 300 steps (measured 4; 3 of the 16 seat the nut within 2400 steps and 4 are
/// still screwing). Regression test for the flat-cut tip: its nut's bore edge sat on the crest and 12 of
/// the 16 failed within 300 steps, the nut and hand sliding off the bolt's axis (1 seated). Single
/// episodes from the tip are chaotic (a world's outcome changes with the batch it runs in), so the test
/// counts.
#[test]
fn from_the_tip_the_chamfer_keeps_most_constant_actions_on_the_bolt() {
    let cfg = FrankaNutBoltConfig::default();
    assert!(!cfg.start_engaged && cfg.bolt_tip_chamfer);
    let yaws = [-0.98f32, -0.95, -0.9, -0.8, -0.6, -0.2, 0.4, 1.0];
    let zs = [-0.05f32, -0.2];
    let worlds = yaws.len() * zs.len();
    let (mut e, mut b) = env(worlds, cfg);
    e.reset(&mut b);
    let mut act = vec![0.0f32; worlds * 12];
    for (i, &z) in zs.iter().enumerate() {
        for (j, &y) in yaws.iter().enumerate() {
            (act[(i * yaws.len() + j) * 12 + 2], act[(i * yaws.len() + j) * 12 + 5]) = (z, y);
        }
    }
    let mut ended = vec![None; worlds];
    for t in 0..300 {
        e.step(&act, &mut b);
        for (w, end) in ended.iter_mut().enumerate() {
            if end.is_none() && b.done(w) {
                *end = Some((t + 1, b.success[w] > 0.5));
            }
        }
    }
    let failed = ended.iter().filter(|e| matches!(e, Some((_, false)))).count();
    eprintln!("ended within 300 steps (step, success): {ended:?}");
    assert!(failed <= 6, "{failed} of {worlds} episodes failed within 300 steps: {ended:?}");
}

/// A world's trajectory does not depend on how many worlds are stepped with it. Left to the world count,
/// the contact pipeline splits each pair's query triangles into more jobs the fewer worlds there are (to
/// fill the device), and the split changes which candidates share a reduction batch, so the patches kept:
/// the same constant action (yaw -0.8) then drops the nut off the tip at step 706 in batches of 6 and 8
/// worlds and keeps it on in a batch of 1. The env fixes the split (`ContactConfig::chunk_world_count`),
/// so evaluating with any `--envs` replays the physics the policy was trained on.
#[test]
fn a_worlds_trajectory_does_not_depend_on_the_batch_size() {
    let world0 = |worlds: usize| {
        let (mut e, mut b) = env(worlds, FrankaNutBoltConfig::default());
        e.reset(&mut b);
        let mut act = vec![0.0f32; 12 * worlds];
        for w in 0..worlds {
            act[12 * w + 5] = -0.8;
        }
        let mut obs = Vec::new();
        for _ in 0..60 {
            e.step(&act, &mut b);
            obs.extend_from_slice(&b.observation[..e.spec().observation_dim()]);
        }
        obs
    };
    let (a, b) = (world0(1), world0(8));
    let first = a.iter().zip(&b).position(|(x, y)| x != y);
    assert!(first.is_none(), "world 0 differs from step {:?}", first.map(|i| i / 26));
}

/// `solve = "device"` (the coupled solve on the GPU kernel, lavapipe here) steps the env as the host
/// reference does: two worlds turning the nut clockwise (a = -0.6) from the first thread for 1 s, with the
/// pads' forces observed (read back for every world at once). The nut's position agrees within 0.25 mm
/// (measured 0.13 mm: float order over 60 steps of contact; engine/tests/articulation_contact.rs
/// bounds the kernel's parity frame by frame), where a nut slipping in the hand or a thread skipped would be
/// a pitch (2 mm) off, and the pads' squeeze within 25% (measured 0.5%); the device's state is not saved
/// (its warm start stays on the device).
#[test]
fn the_device_solve_steps_the_screw_env_as_the_host_does() {
    use factory_engine::sim::CoupledSolve;
    let run = |solve| {
        let cfg = FrankaNutBoltConfig { observe_finger_force: true, solve, ..engaged() };
        let (mut e, mut b) = env(2, cfg);
        assert_eq!(e.scene().sim.on_device(), solve == CoupledSolve::Device);
        e.reset(&mut b);
        let mut a = [0.0f32; 24];
        a[5] = -0.6;
        a[17] = -0.6;
        for t in 0..60 {
            e.step(&a, &mut b);
            assert!(!b.done(0) && !b.done(1), "{solve:?}: an episode ended at step {}", t + 1);
        }
        (b.observation.clone(), e.save_state().is_some())
    };
    let (host, host_saves) = run(CoupledSolve::Host);
    let (device, device_saves) = run(CoupledSolve::Device);
    assert!(host_saves && !device_saves);
    let d = 32;
    for w in 0..2 {
        let (h, g) = (&host[w * d..(w + 1) * d], &device[w * d..(w + 1) * d]);
        let nut = |o: &[f32]| glam::Vec3::new(o[13], o[14], o[15]);
        let gap = nut(h).distance(nut(g));
        eprintln!("world {w}: nut {:?} (host) vs {:?} (device), {:.3} mm apart", nut(h), nut(g), gap * 1e3);
        assert!(gap < 2.5e-4, "world {w}: the nuts are {:.3} mm apart", gap * 1e3);
        for pad in 0..2 {
            let f = |o: &[f32]| glam::Vec3::from_slice(&o[26 + 3 * pad..29 + 3 * pad]).length();
            eprintln!("world {w} pad {pad}: {:.2} N (host) vs {:.2} N (device)", f(h), f(g));
            assert!(f(h) > 1.0, "world {w} pad {pad}: the host's pad does not squeeze ({} N)", f(h));
            assert!((f(g) - f(h)).abs() < 0.25 * f(h), "world {w} pad {pad}: {} N vs {} N", f(g), f(h));
        }
    }
}

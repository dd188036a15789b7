//! Tasks on the nut-and-bolt env ([`NutBoltTask`]): what a task sees of a world, the Screw task's reward and
//! its end of an episode.

use glam::{Quat, Vec3};

/// Factory's hand plus finger length [m] (factory_asset_info_franka_table.yaml: 0.0584 + 0.053671): the
/// keypoint segment's length.
pub const KEYPOINT_AXIS: f32 = 0.112071;
/// Factory's finger pad length [m] (the slip test).
pub const FINGERPAD_LENGTH: f32 = 0.017608;

/// What a task sees of one world after a step.
#[derive(Clone, Copy, Debug)]
pub struct WorldView {
    /// Fingertip position [m], orientation, linear [m/s] and angular [rad/s] velocity.
    pub tip_pos: Vec3,
    pub tip_quat: Quat,
    pub tip_linvel: Vec3,
    pub tip_angvel: Vec3,
    /// Nut centre of mass [m], orientation, linear and angular velocity.
    pub nut_com: Vec3,
    pub nut_quat: Quat,
    pub nut_linvel: Vec3,
    pub nut_angvel: Vec3,
    /// The nut's frame position (its assembly frame: zero when seated) [m].
    pub nut_frame: Vec3,
}

/// Whether an episode ended and how.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// Still running.
    Running,
    /// Terminated in success.
    Success,
    /// Terminated in failure, and why (`far`, `slipped`, `fallen`, `diverged`).
    Failure(&'static str),
}

/// The midpoint between the finger pads' centres [m]: half a pad length up the fingers from the fingertip
/// frame (whose z points out of the hand). IsaacGymEnvs' `fingerpad_midpoint_pos` (the fingers' midpoint
/// moved `finger_length - fingerpad_length / 2` along the hand's z); its Screw reward and slip test measure
/// the nut from here. Measured from the fingertip instead, a grasp at the nut's bottom (Factory's) is
/// 7.4 mm short of the nut's centre and the reward pulls the hand up the nut (the mean action of a
/// 208-update policy trained so lifts the nut off the bolt's tip).
pub fn pad_midpoint(tip_pos: Vec3, tip_quat: Quat) -> Vec3 {
    tip_pos + tip_quat * -Vec3::Z * (0.5 * FINGERPAD_LENGTH)
}

/// Four keypoints spaced along the segment from `p` along `axis` by [`KEYPOINT_AXIS`].
fn keypoints(p: Vec3, axis: Vec3) -> [Vec3; 4] {
    [0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0].map(|t| p + axis * (t * KEYPOINT_AXIS))
}

fn keypoint_distance(a: [Vec3; 4], b: [Vec3; 4]) -> f32 {
    a.iter().zip(&b).map(|(x, y)| x.distance(*y)).sum()
}

/// A task on the nut-and-bolt env: what an episode rewards and when it ends. One required method and
/// defaulted hooks; the env owns the scene, the actions and the resets.
pub trait NutBoltTask: Send + Sync {
    /// The task's `task = "..."` name.
    fn name(&self) -> &'static str;

    /// The reward of a step that left the world as `v` shows.
    fn reward(&self, v: &WorldView) -> f32;

    /// Whether the episode ended (success or failure) in the world `v` shows; the env adds divergence and the
    /// time limit.
    fn outcome(&self, _v: &WorldView) -> Outcome {
        Outcome::Running
    }
}

/// The Screw task's geometry (FactoryTaskNutBoltScrew).
#[derive(Clone, Debug)]
pub struct Screw {
    /// Where the nut's centre of mass is when seated [m].
    pub target: Vec3,
    /// Thread pitch [m] (the success distance).
    pub pitch: f32,
    /// Nut height [m].
    pub nut_height: f32,
    /// Bolt nominal diameter [m].
    pub bolt_diameter: f32,
    /// Height of the bolt's top [m].
    pub bolt_top: f32,
    /// Failure distance [m].
    pub far_error: f32,
}

impl NutBoltTask for Screw {
    fn name(&self) -> &'static str {
        "screw"
    }

    fn reward(&self, v: &WorldView) -> f32 {
        let nut_kp = keypoints(v.nut_com, v.nut_quat * Vec3::Z);
        let target_kp = keypoints(self.target, Vec3::Z);
        // The fingertip's z points down, out of the hand: the pads' segment rises along -z.
        let pads_kp = keypoints(pad_midpoint(v.tip_pos, v.tip_quat), v.tip_quat * -Vec3::Z);
        -(keypoint_distance(nut_kp, target_kp) + keypoint_distance(nut_kp, pads_kp))
    }

    fn outcome(&self, v: &WorldView) -> Outcome {
        let to_target = v.nut_com.distance(self.target);
        if to_target < self.pitch {
            return Outcome::Success;
        }
        let pads = pad_midpoint(v.tip_pos, v.tip_quat);
        let off_axis = Vec3::new(v.nut_com.x, v.nut_com.y, 0.0).length() > 0.5 * self.bolt_diameter;
        // Several can hold at once (a fallen nut has usually slipped too); the first named is reported.
        if off_axis && v.nut_com.z < self.bolt_top + 0.5 * self.nut_height {
            Outcome::Failure("fallen")
        } else if v.nut_com.distance(pads) > 0.5 * FINGERPAD_LENGTH + 0.5 * self.nut_height {
            Outcome::Failure("slipped")
        } else if to_target > self.far_error {
            Outcome::Failure("far")
        } else {
            Outcome::Running
        }
    }
}

//! The robot's feedback: joint states and tip poses taken from DDS, as
//! the controller's plant state, and the tips against the path.

use std::time::SystemTime;

use tendril::ipc::planner::Planned;
use tendril::ipc::sim::analysis::Sample;
use tendril_shared::messages::{Header as MsgHeader, PlantState, MAX_TENDONS};

use super::Drive;
use crate::msg::Time;

/// The newest feedback from the robot, as the controller's plant state.
pub(super) struct Feedback {
    pub(super) tensions: Option<[f32; MAX_TENDONS]>,
    pub(super) tip: Option<([f32; 7], u64)>,
    pub(super) tip_seq: u32,
    pub(super) seq: u64,
}

impl Drive {
    /// Take the newest joint state and tip pose; returns the plant state
    /// (the tracker's frame, as a plant sends it) when anything new arrived
    /// and both kinds have been seen.
    pub(super) fn take_feedback(&mut self, t_wake: u64) -> Option<PlantState> {
        // The first period takes what the wait for the robot took.
        let mut fresh = self.stats.periods == 0;
        while let Ok(Some((js, _))) = self.ends.joint_states.take() {
            if js.effort.len() == self.n && js.effort.iter().all(|t| t.is_finite()) {
                let mut t = [0.0f32; MAX_TENDONS];
                for (dst, &v) in t.iter_mut().zip(&js.effort) {
                    *dst = v as f32;
                }
                self.feedback.tensions = Some(t);
                self.stats.joint_states += 1;
                fresh = true;
            } else {
                self.stats.joint_states_refused += 1;
            }
        }
        while let Ok(Some((tip, _))) = self.ends.tip_pose.take() {
            let p = &tip.pose;
            let pose = [
                p.position.x,
                p.position.y,
                p.position.z,
                p.orientation.w,
                p.orientation.x,
                p.orientation.y,
                p.orientation.z,
            ];
            if pose.iter().all(|v| v.is_finite()) {
                let age_ns = wall_age_ns(&tip.header.stamp);
                self.feedback.tip = Some((pose.map(|v| v as f32), t_wake.saturating_sub(age_ns)));
                self.feedback.tip_seq += 1;
                self.last_tip_ns = t_wake;
                self.stats.tip_poses += 1;
                fresh = true;
                self.track(pose, t_wake.saturating_sub(age_ns));
            } else {
                self.stats.tip_poses_refused += 1;
            }
        }
        if !fresh || self.feedback.tensions.is_none() || self.feedback.tip.is_none() {
            return None;
        }
        self.feedback.seq += 1;
        self.feedback_state(t_wake)
    }

    /// The newest feedback as a plant state in the tracker's frame, once
    /// both kinds have been seen.
    pub(super) fn feedback_state(&self, t_wake: u64) -> Option<PlantState> {
        let (tensions, (tip_pose, tip_stamp_ns)) = (self.feedback.tensions?, self.feedback.tip?);
        Some(PlantState {
            header: MsgHeader {
                seq: self.feedback.seq,
                stamp_ns: t_wake,
            },
            command_seq: 0,
            tensions,
            pad: Default::default(),
            tip_pose,
            count: self.n as u32,
            status: 0,
            tip_seq: self.feedback.tip_seq,
            tip_stamp_ns,
        })
    }

    /// The tip (tracker's frame) against the path where the planner was
    /// when it was sampled, once on the path.
    fn track(&mut self, tip: [f64; 7], stamp_ns: u64) {
        let t = self.since_start(stamp_ns);
        // Every frame of the path (not the wait for the robot's, timed on
        // no path) to the stiffness adaptation, in the model's base frame,
        // at the path time it was sampled, as the planner process gives it
        // its frames.
        let Planned {
            motion, stiffness, ..
        } = &mut self.planned;
        if let Some(s) = stiffness.as_mut().filter(|_| self.stats.periods > 0) {
            s.frame(motion, t, self.to_base.point([tip[0], tip[1], tip[2]]));
        }
        if t < self.settle_s || t > self.end_s {
            return;
        }
        let (want, hold, moving) = match &self.targets {
            Some(f) => match f.holding() {
                Some(pose) => (self.to_tracker.pose(pose), false, false),
                None => return,
            },
            None => {
                let desired = self.planned.motion.at(t);
                let want = self.to_tracker.pose(desired.point.pose);
                (want, desired.holding, desired.moving)
            }
        };
        // At most one a period (the vector's capacity, so a tracker faster
        // than the loop neither allocates in the period nor leaves the run's
        // end out of the verdicts); the tone test resamples them anyway.
        let period_s = self.ticker.period_ns() as f64 * 1e-9;
        let due = (self.samples.last()).is_none_or(|s| t - s.t >= 0.999 * period_s);
        if due && self.samples.len() < self.samples.capacity() {
            self.samples.push(Sample {
                t,
                desired: [want[0], want[1], want[2]],
                actual: [tip[0], tip[1], tip[2]],
                hold,
                moving,
            });
        }
        if hold || moving {
            return;
        }
        let e = (0..3)
            .map(|k| (tip[k] - want[k]).powi(2))
            .sum::<f64>()
            .sqrt()
            * 1e3;
        self.sum_sq += e * e;
        self.stats.tracked_frames += 1;
        let max = self.stats.tracking_max_mm.get_or_insert(0.0);
        *max = max.max(e);
    }
}

/// How long ago (ns) the wall-clock `stamp` was; 0 for a stamp from the
/// future (another machine's clock ahead of this one's).
fn wall_age_ns(stamp: &Time) -> u64 {
    let now = SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .unwrap_or_default();
    let then = std::time::Duration::new(stamp.sec.max(0) as u64, stamp.nanosec.min(999_999_999));
    now.saturating_sub(then).as_nanos() as u64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stamp_from_the_future_is_no_age_and_one_from_the_past_its_age() {
        let now = SystemTime::now()
            .duration_since(SystemTime::UNIX_EPOCH)
            .unwrap();
        let past = Time {
            sec: (now.as_secs() - 2) as i32,
            nanosec: now.subsec_nanos(),
        };
        let age = wall_age_ns(&past) as f64 * 1e-9;
        assert!((2.0..2.5).contains(&age), "{age}");
        let future = Time {
            sec: (now.as_secs() + 60) as i32,
            nanosec: 0,
        };
        assert_eq!(wall_age_ns(&future), 0);
    }
}

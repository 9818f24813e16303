//! The launcher's fault script: process kills and restarts and weight
//! updates at given times after the first setpoint. Faults inside a
//! process (NaN setpoints, a stuck motor, dropped commands) are part of
//! that process's own configuration.

use serde::{Deserialize, Serialize};
use tendril_shared::messages::{Header, WeightUpdate};

use super::supervisor::Role;
use super::SimError;

/// Process-level faults the launcher injects (times in s after the
/// planner's first setpoint).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SimFaults {
    /// SIGKILL the planner at this time.
    pub kill_planner_at: Option<f64>,
    /// Start a new planner this long after the kill.
    pub restart_planner_after: Option<f64>,
    /// SIGKILL the plant at this time.
    pub kill_plant_at: Option<f64>,
    /// Start a new plant this long after the kill.
    pub restart_plant_after: Option<f64>,
    /// Publish a corrupted weight update (bad CRC) at these times.
    pub corrupt_weights_at: Vec<f64>,
    /// Publish the model again (a valid hot swap) at these times.
    pub swap_weights_at: Vec<f64>,
    /// With the chip in the loop: SIGKILL the bridge (the link to the chip
    /// goes silent; the chip must hold on its own) at this time.
    pub cut_link_at: Option<f64>,
    /// Start a new bridge this long after the cut (it reconnects to the
    /// running chip, which keeps its configuration).
    pub restore_link_after: Option<f64>,
}

/// One launcher action.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Action {
    /// SIGKILL the newest process of this role.
    Kill(Role),
    /// Start a new process of this role.
    Restart(Role),
    /// Publish the model as a weight update, one bit flipped if `corrupt`.
    Weights {
        /// Flip a bit (the CRC must catch it).
        corrupt: bool,
    },
}

impl std::fmt::Display for Action {
    /// What the launcher did, in words (the console and the report).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Action::Kill(Role::Controller) => {
                write!(f, "cut the link: killed the bridge to the chip (SIGKILL)")
            }
            Action::Kill(role) => write!(f, "killed the {} (SIGKILL)", role.name()),
            Action::Restart(Role::Controller) => {
                write!(f, "restored the link: started a new bridge to the chip")
            }
            Action::Restart(role) => write!(f, "started a new {}", role.name()),
            Action::Weights { corrupt: true } => {
                write!(f, "published a weight update with one bit flipped")
            }
            Action::Weights { corrupt: false } => {
                write!(f, "published the net again as a weight update (hot swap)")
            }
        }
    }
}

impl SimFaults {
    /// Check every time: finite and ≥ 0; a restart only after a kill.
    pub fn validate(&self) -> Result<(), SimError> {
        let times = [
            ("kill-planner-at", self.kill_planner_at),
            ("restart-planner-after", self.restart_planner_after),
            ("kill-plant-at", self.kill_plant_at),
            ("restart-plant-after", self.restart_plant_after),
            ("cut-link-at", self.cut_link_at),
            ("restore-link-after", self.restore_link_after),
        ];
        let lists = [
            ("corrupt-weights-at", &self.corrupt_weights_at),
            ("swap-weights-at", &self.swap_weights_at),
        ];
        let all = times.iter().filter_map(|(n, t)| t.map(|t| (*n, t))).chain(
            lists
                .iter()
                .flat_map(|(n, v)| v.iter().map(move |&t| (*n, t))),
        );
        for (name, t) in all {
            if !(t.is_finite() && t >= 0.0) {
                return Err(SimError::Config(format!(
                    "--{name} {t}: must be a finite number of seconds ≥ 0"
                )));
            }
        }
        if self.restart_planner_after.is_some() && self.kill_planner_at.is_none() {
            return Err(SimError::Config(
                "--restart-planner-after needs --kill-planner-at".into(),
            ));
        }
        if self.restart_plant_after.is_some() && self.kill_plant_at.is_none() {
            return Err(SimError::Config(
                "--restart-plant-after needs --kill-plant-at".into(),
            ));
        }
        if self.restore_link_after.is_some() && self.cut_link_at.is_none() {
            return Err(SimError::Config(
                "--restore-link-after needs --cut-link-at".into(),
            ));
        }
        // The chip's hold is read back by the bridge that reconnects: with
        // no restore nothing reads the chip after the cut, and the fault
        // could only ever be reported as not detected.
        if self.cut_link_at.is_some() && self.restore_link_after.is_none() {
            return Err(SimError::Config(
                "--cut-link-at needs --restore-link-after: the chip's hold during the cut is \
                 read back by the bridge that reconnects"
                    .into(),
            ));
        }
        Ok(())
    }

    /// Every scheduled time, with the flag that set it: a restart at its
    /// kill's time plus its delay.
    pub fn scheduled(&self) -> Vec<(&'static str, f64)> {
        let mut out = Vec::new();
        for (kill, restart, k, r) in [
            (
                self.kill_planner_at,
                self.restart_planner_after,
                "kill-planner-at",
                "restart-planner-after",
            ),
            (
                self.kill_plant_at,
                self.restart_plant_after,
                "kill-plant-at",
                "restart-plant-after",
            ),
            (
                self.cut_link_at,
                self.restore_link_after,
                "cut-link-at",
                "restore-link-after",
            ),
        ] {
            if let Some(t) = kill {
                out.push((k, t));
                if let Some(d) = restart {
                    out.push((r, t + d));
                }
            }
        }
        out.extend(
            self.corrupt_weights_at
                .iter()
                .map(|&t| ("corrupt-weights-at", t)),
        );
        out.extend(self.swap_weights_at.iter().map(|&t| ("swap-weights-at", t)));
        out
    }

    /// The actions in time order, those before `end` only.
    pub fn script(&self, end: f64) -> Vec<(f64, Action)> {
        let mut plan: Vec<(f64, Action)> = Vec::new();
        for (kill, restart, role) in [
            (
                self.kill_planner_at,
                self.restart_planner_after,
                Role::Planner,
            ),
            (self.kill_plant_at, self.restart_plant_after, Role::Plant),
            (self.cut_link_at, self.restore_link_after, Role::Controller),
        ] {
            if let Some(t) = kill {
                plan.push((t, Action::Kill(role)));
                if let Some(d) = restart {
                    plan.push((t + d, Action::Restart(role)));
                }
            }
        }
        plan.extend(
            self.corrupt_weights_at
                .iter()
                .map(|&t| (t, Action::Weights { corrupt: true })),
        );
        plan.extend(
            self.swap_weights_at
                .iter()
                .map(|&t| (t, Action::Weights { corrupt: false })),
        );
        plan.retain(|(t, _)| *t < end);
        plan.sort_by(|a, b| a.0.total_cmp(&b.0));
        plan
    }
}

/// The model as a weight update; with `corrupt`, one bit in the middle of
/// the weights flipped.
pub fn weight_update(
    model: &[u8],
    header: Header,
    corrupt: bool,
) -> Result<WeightUpdate, SimError> {
    let mut msg = WeightUpdate::from_bytes(header, model)
        .ok_or_else(|| SimError::Config("model too large for a weight update".into()))?;
    if corrupt {
        let mid = msg.len as usize / 2;
        if let Some(b) = msg.bytes.get_mut(mid) {
            *b ^= 0x10;
        }
    }
    Ok(msg)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn script_orders_actions_and_drops_those_after_the_end() {
        let f = SimFaults {
            kill_plant_at: Some(3.0),
            restart_plant_after: Some(0.5),
            corrupt_weights_at: vec![2.0, 20.0],
            ..SimFaults::default()
        };
        assert_eq!(
            f.script(10.0),
            vec![
                (2.0, Action::Weights { corrupt: true }),
                (3.0, Action::Kill(Role::Plant)),
                (3.5, Action::Restart(Role::Plant)),
            ]
        );
    }

    #[test]
    fn non_finite_or_negative_times_and_orphan_restarts_are_rejected() {
        for f in [
            SimFaults {
                kill_plant_at: Some(f64::INFINITY),
                ..SimFaults::default()
            },
            SimFaults {
                swap_weights_at: vec![-1.0],
                ..SimFaults::default()
            },
            SimFaults {
                restart_planner_after: Some(1.0),
                ..SimFaults::default()
            },
        ] {
            assert!(f.validate().is_err(), "{f:?}");
        }
    }
}

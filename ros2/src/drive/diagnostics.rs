//! `drive`'s `/diagnostics`: the period's status and counters.

use tendril_shared::messages::command_status;

use super::Drive;
use crate::msg::{DiagnosticArray, DiagnosticStatus, Header, KeyValue};

impl Drive {
    /// The period's status and counters for `/diagnostics` (once a second:
    /// the controller's statistics are gathered here, not in every period).
    pub(super) fn diagnostics(&self, status: u32) -> DiagnosticArray {
        let s = self.stats();
        let c = self.ctl.stats(&self.ticker);
        let (level, message) = if status & command_status::SAFE_HOLD != 0 {
            (DiagnosticStatus::ERROR, "safe hold")
        } else if status & command_status::PLANT_STALE != 0 && c.plant_stale_cycles > 0 {
            (
                DiagnosticStatus::WARN,
                "the robot is silent: path held, correction frozen",
            )
        } else if s.joint_states_refused + s.tip_poses_refused > 0 {
            (DiagnosticStatus::WARN, "feedback refused")
        } else {
            (DiagnosticStatus::OK, "tracking")
        };
        let kv = |key: &str, value: String| KeyValue {
            key: key.into(),
            value,
        };
        let rms = s.tracking_rms_mm.map_or("—".into(), |r| format!("{r:.4}"));
        DiagnosticArray {
            header: Header::now(""),
            status: vec![DiagnosticStatus {
                level,
                name: "tendril_drive".into(),
                message: message.into(),
                hardware_id: "tendril controller (host period)".into(),
                values: vec![
                    kv("status_bits", format!("{status:#x}")),
                    kv("periods", s.periods.to_string()),
                    kv("overruns", s.overruns.to_string()),
                    kv("hold_periods", c.hold_cycles.to_string()),
                    kv("stale_periods", c.plant_stale_cycles.to_string()),
                    kv("path_held_periods", s.path_held_periods.to_string()),
                    kv("saturated_periods", c.saturated_cycles.to_string()),
                    kv("joint_states", s.joint_states.to_string()),
                    kv("joint_states_refused", s.joint_states_refused.to_string()),
                    kv("tip_poses", s.tip_poses.to_string()),
                    kv("tip_poses_refused", s.tip_poses_refused.to_string()),
                    kv("tracking_rms_mm", rms),
                ],
            }],
        }
    }
}

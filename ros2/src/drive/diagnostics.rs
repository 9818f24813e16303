//! `drive`'s `/diagnostics`: the period's status and counters.

use tendril_shared::messages::command_status;

use super::Drive;
use crate::msg::{DiagnosticArray, DiagnosticStatus, Header, KeyValue};

impl Drive {
    /// The period's status and counters for `/diagnostics` (once a second:
    /// the controller's statistics are gathered here, not in every period).
    pub(super) fn diagnostics(&self, status: u32) -> DiagnosticArray {
        let s = self.stats();
        // The host period's counters; the chip's come with its telemetry
        // at the run's end, so with the chip in the loop they are "—".
        let host = self.chip.is_none().then(|| self.ctl.stats(&self.ticker));
        let count = |f: fn(&tendril::ipc::controller::ControllerStats) -> u64| {
            host.as_ref().map_or("—".to_string(), |c| f(c).to_string())
        };
        let (level, message) = if status & command_status::SAFE_HOLD != 0 {
            (DiagnosticStatus::ERROR, "safe hold".to_string())
        } else if let Some(who) = self.silent {
            (
                DiagnosticStatus::WARN,
                format!("the {who} is silent: path held, correction frozen"),
            )
        } else if s.joint_states_refused + s.tip_poses_refused > 0 {
            (DiagnosticStatus::WARN, "feedback refused".to_string())
        } else {
            (DiagnosticStatus::OK, "tracking".to_string())
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
                message,
                hardware_id: match self.chip.is_some() {
                    true => "tendril controller (the STM32F405 image under QEMU)".into(),
                    false => "tendril controller (host period)".into(),
                },
                values: vec![
                    kv("status_bits", format!("{status:#x}")),
                    kv("periods", s.periods.to_string()),
                    kv("overruns", count(|c| c.overruns)),
                    kv("hold_periods", s.hold_periods.to_string()),
                    kv("stale_periods", count(|c| c.plant_stale_cycles)),
                    kv("path_held_periods", s.path_held_periods.to_string()),
                    kv("saturated_periods", count(|c| c.saturated_cycles)),
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

//! The run log's channels (docs/design.md §12): topic names, and the JSON
//! messages tendril defines beside Foxglove's well-known schemas.
//!
//! The 3-D scene, the frame transforms and the log lines use Foxglove's own
//! protobuf schemas (`foxglove.SceneUpdate`, `foxglove.FrameTransforms`,
//! `foxglove.Log`), so Foxglove draws them with no plugin. The per-step
//! numbers are JSON with a JSON Schema: Foxglove plots any field of them,
//! and any reader (Python's `mcap`, `jq`) decodes them with no code
//! generation.

use serde::{Deserialize, Serialize};

/// The robot's shape, the tips and the path: `foxglove.SceneUpdate`.
pub const SCENE: &str = "/robot/scene";
/// Base → tip (true) and base → measured tip: `foxglove.FrameTransforms`.
pub const TF: &str = "/tf";
/// Commanded and measured tensions, every plant step: [`TensionsMsg`].
pub const TENSIONS: &str = "/tensions";
/// Desired, true and measured tip and the errors, every plant step:
/// [`TrackingMsg`].
pub const TRACKING: &str = "/tracking";
/// The controller's and the plant's status bits, when they change and at
/// 10 Hz: [`StatusMsg`].
pub const STATUS: &str = "/status";
/// Faults, status changes and process events: `foxglove.Log`.
pub const LOG: &str = "/log";

/// Every topic a run log has, in the order they are created.
pub const ALL: [&str; 6] = [SCENE, TF, TENSIONS, TRACKING, STATUS, LOG];

/// The frame everything is drawn in: the tracker's (docs/design.md §2.4;
/// the robot's base frame when its file has no `[base]`).
pub const TRACKER_FRAME: &str = "tracker";
/// The robot's base, a child of [`TRACKER_FRAME`] at the plant robot's
/// `[base]`.
pub const BASE_FRAME: &str = "base";
/// The true tip's frame.
pub const TIP_FRAME: &str = "tip";
/// The tracker's tip frame (the last frame it delivered).
pub const MEASURED_TIP_FRAME: &str = "tip_measured";

/// One plant step's tensions, N (`/tensions`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TensionsMsg {
    /// What the controller's last command asked for (saturated to the
    /// robot's range by the plant).
    pub commanded_n: Vec<f64>,
    /// The tendons' tensions the plant applied this step.
    pub measured_n: Vec<f64>,
}

/// One plant step's tip positions, m, and errors, mm (`/tracking`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrackingMsg {
    /// The newest setpoint's position (None before the first).
    pub desired_m: Option<[f64; 3]>,
    /// The true tip.
    pub actual_m: [f64; 3],
    /// The tracker's newest frame (None before the first).
    pub measured_m: Option<[f64; 3]>,
    /// ‖desired − actual‖, mm.
    pub error_mm: Option<f64>,
    /// ‖desired − measured‖, mm: what the controller can see.
    pub measured_error_mm: Option<f64>,
}

/// One plant step's status bits (`/status`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StatusMsg {
    /// The last command the plant applied (0 = none yet).
    pub command_seq: u64,
    /// Its `command_status` bits (docs/design.md §6.1).
    pub controller: u32,
    /// Their names.
    pub controller_flags: Vec<String>,
    /// The plant's `plant_status` bits.
    pub plant: u32,
    /// Their names.
    pub plant_flags: Vec<String>,
}

/// JSON Schema of [`TensionsMsg`].
pub const TENSIONS_SCHEMA: &str = r#"{"title":"tendril.Tensions","type":"object","properties":{
"commanded_n":{"type":"array","items":{"type":"number"},"description":"commanded tensions, N"},
"measured_n":{"type":"array","items":{"type":"number"},"description":"applied tensions, N"}}}"#;

/// JSON Schema of [`TrackingMsg`].
pub const TRACKING_SCHEMA: &str = r#"{"title":"tendril.Tracking","type":"object","properties":{
"desired_m":{"type":["array","null"],"items":{"type":"number"}},
"actual_m":{"type":"array","items":{"type":"number"}},
"measured_m":{"type":["array","null"],"items":{"type":"number"}},
"error_mm":{"type":["number","null"],"description":"|desired - true tip|, mm"},
"measured_error_mm":{"type":["number","null"],"description":"|desired - tracker|, mm"}}}"#;

/// JSON Schema of [`StatusMsg`].
pub const STATUS_SCHEMA: &str = r#"{"title":"tendril.Status","type":"object","properties":{
"command_seq":{"type":"integer"},
"controller":{"type":"integer","description":"command_status bits"},
"controller_flags":{"type":"array","items":{"type":"string"}},
"plant":{"type":"integer","description":"plant_status bits"},
"plant_flags":{"type":"array","items":{"type":"string"}}}}"#;

/// Names of the `command_status` bits set in `bits` (wire bits only).
pub fn controller_flags(bits: u32) -> Vec<String> {
    use tendril_shared::messages::command_status as c;
    let names = [
        (c::SAFE_HOLD, "SAFE_HOLD"),
        (c::SETPOINT_REJECTED, "SETPOINT_REJECTED"),
        (c::SATURATED, "SATURATED"),
        (c::PLANT_STALE, "PLANT_STALE"),
        (c::CORRECTION, "CORRECTION"),
        (c::WEIGHTS_SWAPPED, "WEIGHTS_SWAPPED"),
        (c::WEIGHTS_REJECTED, "WEIGHTS_REJECTED"),
        (c::OVERRUN, "OVERRUN"),
        (c::NO_SETPOINT, "NO_SETPOINT"),
    ];
    flags(bits, &names)
}

/// Names of the `plant_status` bits set in `bits`.
pub fn plant_flags(bits: u32) -> Vec<String> {
    use tendril_shared::messages::plant_status as p;
    let names = [
        (p::MOTOR_STUCK, "MOTOR_STUCK"),
        (p::COMMAND_OUT_OF_RANGE, "COMMAND_OUT_OF_RANGE"),
        (p::SOLVE_FAILED, "SOLVE_FAILED"),
        (p::COMMAND_STALE, "COMMAND_STALE"),
        (p::DROPPING, "DROPPING"),
        (p::DELAYING, "DELAYING"),
    ];
    flags(bits, &names)
}

fn flags(bits: u32, names: &[(u32, &str)]) -> Vec<String> {
    names
        .iter()
        .filter(|(b, _)| bits & b != 0)
        .map(|(_, n)| (*n).to_string())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn schemas_are_json_and_name_every_field() {
        let fields = |s: &str| -> Vec<String> {
            let v: serde_json::Value = serde_json::from_str(s).unwrap();
            let mut k: Vec<String> = v["properties"]
                .as_object()
                .unwrap()
                .keys()
                .cloned()
                .collect();
            k.sort();
            k
        };
        let keys = |v: serde_json::Value| -> Vec<String> {
            let mut k: Vec<String> = v.as_object().unwrap().keys().cloned().collect();
            k.sort();
            k
        };
        let t = TensionsMsg {
            commanded_n: vec![1.0],
            measured_n: vec![1.0],
        };
        assert_eq!(
            fields(TENSIONS_SCHEMA),
            keys(serde_json::to_value(t).unwrap())
        );
        let t = TrackingMsg {
            desired_m: None,
            actual_m: [0.0; 3],
            measured_m: None,
            error_mm: None,
            measured_error_mm: None,
        };
        assert_eq!(
            fields(TRACKING_SCHEMA),
            keys(serde_json::to_value(t).unwrap())
        );
        let s = StatusMsg {
            command_seq: 1,
            controller: 0,
            controller_flags: vec![],
            plant: 0,
            plant_flags: vec![],
        };
        assert_eq!(
            fields(STATUS_SCHEMA),
            keys(serde_json::to_value(s).unwrap())
        );
    }

    #[test]
    fn flags_name_the_bits() {
        use tendril_shared::messages::{command_status as c, plant_status as p};
        assert_eq!(
            controller_flags(c::SAFE_HOLD | c::CORRECTION | (1 << 20)),
            ["SAFE_HOLD", "CORRECTION"]
        );
        assert_eq!(plant_flags(p::MOTOR_STUCK), ["MOTOR_STUCK"]);
        assert!(plant_flags(0).is_empty());
    }
}

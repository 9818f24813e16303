//! Arbitrary sequences of control-step inputs (any f32 bit patterns, any
//! timing, any sequence numbers) against the built-in flash net
//! (`tendril_firmware::DEFAULT_NET`, the default exported net): the
//! command must stay finite, inside [0, max_tension], and within the slew
//! limit of the previous command.
#![no_main]

use libfuzzer_sys::fuzz_target;
use tendril_firmware::control::{
    control_step, ControlConfig, ControlSetpoint, ControlState, ControlTangent, Feedback,
    IntegralConfig, SafeHold, StepInput,
};
use tendril_firmware::DEFAULT_NET;
use tendril_shared::{TendonLimits, MAX_TENDONS};

fn f32_at(b: &[u8], i: usize) -> f32 {
    let mut w = [0u8; 4];
    if let Some(s) = b.get(i..i + 4) {
        w.copy_from_slice(s);
    }
    f32::from_le_bytes(w)
}

fuzz_target!(|data: &[u8]| {
    let Some((&head, body)) = data.split_first() else {
        return;
    };
    let net = &DEFAULT_NET;
    let n = net.shape().outputs;
    let max_t = 10.0f32;
    let rate = 100.0f32;
    let mut cfg = ControlConfig::new(TendonLimits::uniform(n, max_t, rate).expect("limits"));
    cfg.watchdog_ns = 10_000_000;
    cfg.max_dt_ns = 3_000_000;
    if head & 1 != 0 {
        cfg.safe_hold = SafeHold::Ramp([5.0; MAX_TENDONS]);
    }
    if head & 2 != 0 {
        cfg.integral = IntegralConfig {
            ki: 50.0,
            limit: 0.01,
            feedback_timeout_ns: 4_000_000,
            window: 0.002,
            filter_tau_s: 0.05,
            map_gain: 2.0,
            map_scale: 0.01,
            map_limit: 0.5,
        };
    }
    let mut now: u64 = 1 << 40;
    let mut st = ControlState::new(&cfg.limits, &[f32_at(body, 0); MAX_TENDONS], now);
    // 48-byte records: dt (i32 ns), flags, seq (u32), pose 7×f32, tip 3×f32... padded.
    for rec in body.chunks(48) {
        let word = |i: usize| u32::from_le_bytes(f32_at(rec, i).to_le_bytes());
        let dt = word(0) as i32 as i64;
        now = if dt < 0 {
            now.saturating_sub(dt.unsigned_abs())
        } else {
            now + dt as u64
        };
        let flags = word(4);
        let mut pose = [0.0f32; 7];
        for (k, p) in pose.iter_mut().enumerate() {
            *p = f32_at(rec, 12 + 4 * k);
        }
        let tip = [f32_at(rec, 40), f32_at(rec, 44), f32_at(rec, 8)];
        let input = StepInput {
            now_ns: now,
            setpoint: (flags & 1 != 0).then_some(ControlSetpoint {
                seq: u64::from(word(8)),
                pose,
                // Arbitrary (NaN, ∞, huge) tangents and dimensions from the same bytes.
                tangent: (flags & 4 != 0).then_some(ControlTangent {
                    dim: (word(8) % 5) as usize,
                    columns: [pose, pose.map(|v| -3.0 * v), pose.map(|v| 0.5 * v)],
                    axes: [
                        [pose[0], pose[1], pose[2]],
                        [pose[3], pose[4], pose[5]],
                        tip,
                    ],
                }),
            }),
            feedback: (flags & 2 != 0).then_some(Feedback {
                seq: now,
                tip_position: tip,
                interval_s: 1e-3,
            }),
        };
        let prev = st.command;
        let dt_s = now.saturating_sub(st.last_step_ns).min(cfg.max_dt_ns) as f32 * 1e-9;
        let (next, out) = control_step(&cfg, net, &st, &input);
        for i in 0..MAX_TENDONS {
            let c = out.command[i];
            assert!(c.is_finite() && c >= 0.0 && c <= max_t, "range: {c}");
            assert!(
                (c - prev[i]).abs() <= rate * dt_s * (1.0 + 1e-5) + max_t * 3e-7,
                "slew"
            );
        }
        st = next;
    }
});

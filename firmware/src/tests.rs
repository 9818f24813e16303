//! Unit and property tests of inference, the control step, hot swap and the
//! vector format.

#![allow(clippy::needless_range_loop)] // index loops read like the formulas here

use std::vec::Vec;

use proptest::prelude::*;
use tendril_shared::{weight_capacity, CascadeNet, TendonLimits, MAX_TENDONS};

use crate::control::*;
use crate::infer::{dot8, infer};
use crate::swap::{FlashSlot, NetSlots, NetStore, SwapError};
use crate::synth::{synthetic_blob, SplitMix64, INPUT_HI, INPUT_LO};
use crate::vectors::{self, Record, VecHeader};

type Net = CascadeNet<7, 16, 8, { weight_capacity(7, 16, 8) }>;

type Net64 = CascadeNet<7, 64, 8, { weight_capacity(7, 64, 8) }>;

fn blob(seed: u64, hidden: usize, outputs: usize) -> Vec<u8> {
    let mut buf = std::vec![0u8; 16384];
    let n = synthetic_blob(seed, hidden, outputs, 10.0, &mut buf).unwrap();
    buf.truncate(n);
    buf
}

/// f64 reference straight from the documented flat layout, regenerating the
/// synthetic weights from the seed (independent of the decoder's storage).
fn reference(seed: u64, hidden: usize, outputs: usize, x: &[f32; 7]) -> Vec<f64> {
    let ni = 7;
    let nh_w: usize = (0..hidden).map(|k| 1 + ni + k).sum();
    let no_w = outputs * (1 + ni + hidden);
    let mut rng = SplitMix64(seed);
    let w: Vec<f64> = (0..nh_w + no_w)
        .map(|_| rng.uniform(-1.0, 1.0) as f64)
        .collect();
    let mut feat: Vec<f64> = std::vec![1.0];
    for i in 0..ni {
        let (lo, hi) = (INPUT_LO[i] as f64, INPUT_HI[i] as f64);
        feat.push((x[i] as f64 - lo) / (hi - lo));
    }
    let mut off = 0;
    for k in 0..hidden {
        let len = 1 + ni + k;
        let s: f64 = w[off..off + len]
            .iter()
            .zip(&feat)
            .map(|(a, b)| a * b)
            .sum();
        feat.push(1.0 / (1.0 + (-s).exp()) - 0.5);
        off += len;
    }
    (0..outputs)
        .map(|o| {
            let len = 1 + ni + hidden;
            let row = &w[nh_w + o * len..nh_w + (o + 1) * len];
            let s: f64 = row.iter().zip(&feat).map(|(a, b)| a * b).sum();
            10.0 * s
        })
        .collect()
}

/// The store bounds a net by its weights: the MCU's net type takes the
/// nine-tendon net with the most units that fit (7-63-9), infers it as the
/// f64 reference says, and refuses one unit more (7-64-9).
#[test]
fn nine_outputs_fit_the_store_with_one_unit_fewer() {
    use tendril_shared::{max_hidden_for, McuNet, TnetError};
    let h = max_hidden_for(9);
    assert_eq!(h, 63);
    let net = McuNet::decode(&blob(21, h, 9)).unwrap();
    let mut rng = SplitMix64(5);
    for _ in 0..50 {
        let mut x = [0.0f32; 7];
        for i in 0..7 {
            x[i] = rng.uniform(INPUT_LO[i], INPUT_HI[i]);
        }
        let y = infer(&net, &x);
        let r = reference(21, h, 9, &x);
        for o in 0..9 {
            assert!(
                (y[o] as f64 - r[o]).abs() < 1e-4 * (1.0 + r[o].abs()),
                "{o}"
            );
        }
    }
    assert!(matches!(
        McuNet::decode(&blob(21, h + 1, 9)),
        Err(TnetError::ShapeOverCapacity { .. })
    ));
}

/// The centre of the synthetic net's input box (every normalised input 0.5;
/// its quaternion is not unit, so the control step would refuse it).
fn box_centre() -> [f32; 7] {
    let mut p = [0.0f32; 7];
    for i in 0..7 {
        p[i] = 0.5 * (INPUT_LO[i] + INPUT_HI[i]);
    }
    p
}

/// A valid setpoint inside the box: centre position, unit quaternion.
fn mid_pose() -> [f32; 7] {
    let qx = (1.0f32 - 0.98 * 0.98).sqrt();
    [0.0, 0.0, 0.35, 0.98, qx, 0.0, 0.0]
}

#[test]
fn dot8_matches_a_plain_sum_over_whole_blocks_for_every_length() {
    for n in 0..42 {
        let w: Vec<f32> = (0..n).map(|i| 0.5 - 0.1 * i as f32).collect();
        let a: Vec<f32> = (0..n).map(|i| 1.0 + 0.25 * i as f32).collect();
        // Only the first 8 ⌊n/8⌋ products count.
        let whole = n / 8 * 8;
        let exact: f64 = w[..whole]
            .iter()
            .zip(&a[..whole])
            .map(|(x, y)| *x as f64 * *y as f64)
            .sum();
        assert!((dot8(&w, &a) as f64 - exact).abs() < 1e-4, "n={n}");
        // The longer slice's extra entries are ignored.
        let mut longer = a.clone();
        longer.extend([1e30; 8]);
        assert_eq!(dot8(&w, &longer), dot8(&w, &a));
    }
}

#[test]
fn inference_matches_an_f64_reference_of_the_documented_layout() {
    let mut rng = SplitMix64(99);
    let cases = [
        (1u64, 0usize, 4usize),
        (2, 1, 1),
        (3, 12, 4),
        (4, 16, 8),
        (5, 64, 8),
        (6, 63, 3),
        (7, 9, 4),
    ];
    for &(seed, hidden, outputs) in &cases {
        let b = blob(seed, hidden, outputs);
        // Every case through the 64-unit MCU capacity; those that fit also
        // through the 16-unit one (a different packing: same result).
        let net = Net64::decode(&b).unwrap();
        let small = Net::decode(&b).ok();
        for _ in 0..50 {
            let mut x = [0.0f32; 7];
            for i in 0..7 {
                x[i] = rng.uniform(INPUT_LO[i], INPUT_HI[i]);
            }
            let y = infer(&net, &x);
            if let Some(small) = &small {
                assert_eq!(infer(small, &x), y);
            }
            let r = reference(seed, hidden, outputs, &x);
            for o in 0..outputs {
                let tol = 1e-4 * (1.0 + r[o].abs());
                assert!(
                    (y[o] as f64 - r[o]).abs() < tol,
                    "{seed} {o}: {} vs {}",
                    y[o],
                    r[o]
                );
            }
            assert!(y[outputs..].iter().all(|&v| v == 0.0));
        }
    }
}

#[test]
fn one_hidden_unit_by_hand() {
    // 7-1-1 net with weights from the seed; check the closed form at the box
    // centre, where every normalised input is exactly 0.5.
    let seed = 5;
    let net = Net::decode(&blob(seed, 1, 1)).unwrap();
    let mut rng = SplitMix64(seed);
    let w: Vec<f32> = (0..8 + 9).map(|_| rng.uniform(-1.0, 1.0)).collect();
    let s_h: f64 = w[0] as f64 + 0.5 * w[1..8].iter().map(|&v| v as f64).sum::<f64>();
    let h = 1.0 / (1.0 + (-s_h).exp()) - 0.5;
    let s_o =
        w[8] as f64 + 0.5 * w[9..16].iter().map(|&v| v as f64).sum::<f64>() + w[16] as f64 * h;
    let y = infer(&net, &box_centre());
    assert!(
        (y[0] as f64 - 10.0 * s_o).abs() < 1e-5,
        "{} vs {}",
        y[0],
        10.0 * s_o
    );
}

#[test]
fn empty_net_infers_zeros() {
    assert_eq!(infer(&Net::empty(), &mid_pose()), [0.0; 8]);
}

fn cfg4() -> ControlConfig {
    let mut c = ControlConfig::new(TendonLimits::uniform(4, 10.0, 100.0).unwrap());
    c.watchdog_ns = 20_000_000;
    c.max_dt_ns = 2_000_000;
    c
}

fn sp(seq: u64, pose: [f32; 7]) -> Option<ControlSetpoint> {
    Some(ControlSetpoint {
        seq,
        pose,
        tangent: None,
    })
}

fn input(now_ns: u64, setpoint: Option<ControlSetpoint>) -> StepInput {
    StepInput {
        now_ns,
        setpoint,
        feedback: None,
    }
}

#[test]
fn tracking_converges_to_the_clamped_net_output_at_the_slew_rate() {
    let cfg = cfg4();
    let net = Net::decode(&blob(3, 12, 4)).unwrap();
    let pose = mid_pose();
    let y = infer(&net, &pose);
    let mut st = ControlState::new(&cfg.limits, &[0.0; MAX_TENDONS], 0);
    let (s1, o1) = control_step(&cfg, &net, &st, &input(1_000_000, sp(1, pose)));
    assert!(o1.status.contains(Status::NEW_SETPOINT));
    // 1 ms at 100 N/s: at most 0.1 N per tendon.
    for i in 0..4 {
        assert!((o1.command[i] - y[i].clamp(0.0, 10.0).min(0.1)).abs() < 1e-6);
    }
    st = s1;
    for k in 2..400u64 {
        st = control_step(&cfg, &net, &st, &input(k * 1_000_000, sp(k, pose))).0;
    }
    for i in 0..4 {
        assert!((st.command[i] - y[i].clamp(0.0, 10.0)).abs() < 1e-6, "{i}");
    }
    assert!(st.command[4..].iter().all(|&t| t == 0.0));
}

#[test]
fn nan_stale_and_out_of_box_setpoints_hold_the_target() {
    let cfg = cfg4();
    let net = Net::decode(&blob(3, 12, 4)).unwrap();
    let st0 = ControlState::new(&cfg.limits, &[0.0; MAX_TENDONS], 0);
    let (st, _) = control_step(&cfg, &net, &st0, &input(1_000_000, sp(5, mid_pose())));
    let target = st.target;

    let mut nan = mid_pose();
    nan[2] = f32::NAN;
    let (s, o) = control_step(&cfg, &net, &st, &input(2_000_000, sp(6, nan)));
    assert!(o
        .status
        .contains(Status::SETPOINT_REJECTED | Status::NONFINITE_SETPOINT));
    assert_eq!(s.target, target);

    let mut far = mid_pose();
    far[0] = 0.5; // outside px ∈ [−0.15, 0.15]
    let (s, o) = control_step(&cfg, &net, &st, &input(2_000_000, sp(6, far)));
    assert!(o.status.contains(Status::OUT_OF_WORKSPACE));
    assert_eq!(s.target, target);

    let mut skew = mid_pose();
    skew[3] = 0.5;
    let (_, o) = control_step(&cfg, &net, &st, &input(2_000_000, sp(6, skew)));
    assert!(o.status.contains(Status::BAD_QUATERNION));

    let (s, o) = control_step(&cfg, &net, &st, &input(2_000_000, sp(5, far)));
    assert!(o.status.contains(Status::STALE_SETPOINT));
    assert!(!o.status.contains(Status::SETPOINT_REJECTED));
    assert_eq!(s.target, target);
}

#[test]
fn watchdog_trips_after_the_configured_silence_and_recovers() {
    let cfg = cfg4();
    let net = Net::decode(&blob(3, 12, 4)).unwrap();
    let mut st = ControlState::new(&cfg.limits, &[0.0; MAX_TENDONS], 0);
    st = control_step(&cfg, &net, &st, &input(1_000_000, sp(1, mid_pose()))).0;
    // Silent until exactly the timeout: still tracking.
    let (_, o) = control_step(&cfg, &net, &st, &input(21_000_000, None));
    assert!(!o.status.contains(Status::SAFE_HOLD));
    let (s, o) = control_step(&cfg, &net, &st, &input(21_000_001, None));
    assert!(o.status.contains(Status::SAFE_HOLD));
    // Freeze: the command does not move while holding.
    assert_eq!(o.command, st.command);
    let (_, o) = control_step(&cfg, &net, &s, &input(22_000_000, sp(2, mid_pose())));
    assert!(!o.status.contains(Status::SAFE_HOLD));
    assert!(o.status.contains(Status::NEW_SETPOINT));
}

#[test]
fn ramp_safe_hold_relaxes_at_the_slew_rate() {
    let mut cfg = cfg4();
    cfg.safe_hold = SafeHold::Ramp([0.0; MAX_TENDONS]);
    let net = Net::decode(&blob(3, 12, 4)).unwrap();
    let mut st = ControlState::new(&cfg.limits, &[5.0; MAX_TENDONS], 0);
    st.watchdog = true;
    let (st, o) = control_step(&cfg, &net, &st, &input(1_000_000, None));
    assert!(o.status.contains(Status::SAFE_HOLD | Status::SLEW_LIMITED));
    assert!((o.command[0] - 4.9).abs() < 1e-5);
    assert!(st.command[..4].iter().all(|&c| (c - 4.9).abs() < 1e-5));
}

#[test]
fn clock_running_backwards_freezes_the_command() {
    let cfg = cfg4();
    let net = Net::decode(&blob(3, 12, 4)).unwrap();
    let st = ControlState::new(&cfg.limits, &[1.0; MAX_TENDONS], 10_000_000);
    let (_, o) = control_step(&cfg, &net, &st, &input(5_000_000, sp(1, mid_pose())));
    assert!(o.status.contains(Status::CLOCK_FAULT));
    assert_eq!(&o.command[..4], &[1.0; 4]);
}

#[test]
fn net_with_wrong_output_count_is_refused() {
    let cfg = cfg4();
    let net = Net::decode(&blob(3, 2, 3)).unwrap();
    let st = ControlState::new(&cfg.limits, &[0.0; MAX_TENDONS], 0);
    let (_, o) = control_step(&cfg, &net, &st, &input(1_000_000, sp(1, mid_pose())));
    assert!(o.status.contains(Status::NET_MISMATCH));
    assert_eq!(o.command, [0.0; MAX_TENDONS]);
}

/// The integral law as it was for the lateral (k = 2) tangent before the
/// law was generalised, kept as the independent reference: window on the
/// lateral error, integrate x and y, shift along the two columns.
fn lateral_law_reference(
    correction: &mut [f32; 3],
    pose: &[f32; 7],
    tip: &[f32; 3],
    ic: &IntegralConfig,
    dt: f32,
) {
    let (ex, ey) = (pose[0] - tip[0], pose[1] - tip[1]);
    if ex * ex + ey * ey <= ic.window * ic.window {
        for ((c, &p), &m) in correction.iter_mut().zip(pose).zip(tip).take(2) {
            *c = clamp(*c + ic.ki * (p - m) * dt, -ic.limit, ic.limit);
        }
    }
}

/// A plant whose tip is the commanded position shifted by `bias`; runs the
/// loop with `tangent` for `steps` periods and returns the state. With a
/// lateral tangent every step's correction is checked bit for bit against
/// [`lateral_law_reference`].
fn run_biased(
    cfg: &ControlConfig,
    tangent: Option<ControlTangent>,
    bias: [f32; 3],
    steps: u64,
) -> ControlState {
    let net = Net::decode(&blob(3, 12, 4)).unwrap();
    let pose = mid_pose();
    let mut st = ControlState::new(&cfg.limits, &[0.0; MAX_TENDONS], 0);
    let lateral =
        tangent.is_some_and(|t| t == ControlTangent::lateral([t.columns[0], t.columns[1]]));
    let mut reference = [0.0f32; 3];
    for k in 1..steps {
        let p = corrected_pose(&st);
        let tip = [p[0] - bias[0], p[1] - bias[1], p[2] - bias[2]];
        let inp = StepInput {
            now_ns: k * 1_000_000,
            setpoint: Some(ControlSetpoint {
                seq: k,
                pose,
                tangent,
            }),
            feedback: Some(Feedback {
                seq: k,
                tip_position: tip,
                interval_s: 1_000_000_f32 * 1e-9,
            }),
        };
        let slewing = st.slew_limited;
        let before = st.correction;
        st = control_step(cfg, &net, &st, &inp).0;
        if lateral && k > 1 {
            if !slewing {
                lateral_law_reference(
                    &mut reference,
                    &pose,
                    &tip,
                    &cfg.integral,
                    1_000_000_f32 * 1e-9,
                );
            }
            if st.correction == before && reference != before {
                // The step undid a correction that left the box: so does the reference.
                reference = before;
            }
            assert_eq!(
                st.correction.map(f32::to_bits),
                reference.map(f32::to_bits),
                "step {k}"
            );
        }
    }
    st
}

fn integral_cfg() -> ControlConfig {
    let mut cfg = cfg4();
    cfg.integral = IntegralConfig {
        filter_tau_s: 0.0,
        map_gain: 0.0,
        map_scale: 1.0,
        map_limit: 0.0,
        ki: 50.0,
        limit: 0.01,
        feedback_timeout_ns: 5_000_000,
        window: 0.01,
    };
    cfg
}

#[test]
fn integral_loop_moves_the_setpoint_along_the_tangent() {
    let cfg = integral_cfg();
    // A tangent that also tilts the tip: moving in x changes z and qy.
    let mut d = [[0.0f32; 7]; 2];
    d[0][0] = 1.0;
    d[0][2] = -0.2;
    d[0][5] = 2.5;
    d[1][1] = 1.0;
    d[1][4] = -2.5;
    let bias = [0.002f32, -0.001, 0.0];
    let st = run_biased(&cfg, Some(ControlTangent::lateral(d)), bias, 2000);
    assert!(
        (st.correction[0] - bias[0]).abs() < 1e-6,
        "{:?}",
        st.correction
    );
    assert!(
        (st.correction[1] - bias[1]).abs() < 1e-6,
        "{:?}",
        st.correction
    );
    assert_eq!(
        st.correction[2], 0.0,
        "height follows the tangent, not the integral"
    );
    let p = corrected_pose(&st);
    let pose = mid_pose();
    for k in 0..7 {
        let want = pose[k] + d[0][k] * st.correction[0] + d[1][k] * st.correction[1];
        assert!(
            (p[k] - want).abs() < 1e-7,
            "component {k}: {} vs {want}",
            p[k]
        );
    }
    // A non-finite tangent is dropped: the position alone moves.
    let mut bad = d;
    bad[1][3] = f32::NAN;
    let st = run_biased(&cfg, Some(ControlTangent::lateral(bad)), bias, 2000);
    assert!(st.tangent.is_none());
    assert!((corrected_pose(&st)[5] - mid_pose()[5]).abs() < 1e-9);
    assert!((st.correction[0] - bias[0]).abs() < 1e-6);
}

/// k = 3 (a two-segment robot): the correction along x, y, z converges to
/// the plant's bias on each axis, and the setpoint moves along all three
/// columns (one of which tilts the tip).
#[test]
fn integral_loop_corrects_a_volume_along_three_columns() {
    let cfg = integral_cfg();
    let mut columns = [[0.0f32; 7]; 3];
    columns[0][0] = 1.0;
    columns[0][5] = 2.0;
    columns[1][1] = 1.0;
    columns[2][2] = 1.0;
    columns[2][4] = -1.5;
    let tangent = ControlTangent {
        dim: 3,
        columns,
        axes: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
    };
    let bias = [0.001f32, -0.0015, 0.0007];
    let st = run_biased(&cfg, Some(tangent), bias, 2000);
    for j in 0..3 {
        assert!(
            (st.correction[j] - bias[j]).abs() < 1e-6,
            "{:?}",
            st.correction
        );
    }
    let p = corrected_pose(&st);
    let want_qx = mid_pose()[4] - 1.5 * st.correction[2];
    assert!((p[4] - want_qx).abs() < 1e-7, "{} vs {want_qx}", p[4]);
}

/// k = 1 along an oblique axis: only the error's component along the axis
/// is integrated (the tip cannot move across it), and it converges to the
/// bias's component a · b.
#[test]
fn integral_loop_on_a_curve_integrates_the_error_along_its_axis() {
    let cfg = integral_cfg();
    let a = [0.6f32, 0.8, 0.0];
    let mut columns = [[0.0f32; 7]; 3];
    columns[0][0] = a[0];
    columns[0][1] = a[1];
    columns[0][2] = -0.1;
    let tangent = ControlTangent {
        dim: 1,
        columns,
        axes: [a, [0.0; 3], [0.0; 3]],
    };
    // A bias along the axis: the shift along the column removes it.
    let bias = [0.0012f32, 0.0016, 0.0];
    let st = run_biased(&cfg, Some(tangent), bias, 2000);
    let along = a[0] * bias[0] + a[1] * bias[1];
    assert!(
        (st.correction[0] - along).abs() < 1e-6,
        "{:?} vs {along}",
        st.correction
    );
    assert_eq!((st.correction[1], st.correction[2]), (0.0, 0.0));
}

#[test]
fn tangents_of_no_dimension_or_too_many_are_ignored() {
    let mut t = ControlTangent::lateral([[0.0; 7]; 2]);
    assert!(t.is_valid());
    t.dim = 0;
    assert!(!t.is_valid());
    t.dim = 4;
    assert!(!t.is_valid());
    t.dim = 3;
    t.axes[2][1] = f32::INFINITY;
    assert!(!t.is_valid());
}

#[test]
fn integral_loop_waits_out_large_errors_and_slewing() {
    let mut cfg = cfg4();
    cfg.integral = IntegralConfig {
        filter_tau_s: 0.0,
        map_gain: 0.0,
        map_scale: 1.0,
        map_limit: 0.0,
        ki: 50.0,
        limit: 0.01,
        feedback_timeout_ns: 5_000_000,
        window: 0.002,
    };
    // 3 mm off: outside the 2 mm window, nothing is integrated.
    let st = run_biased(&cfg, None, [0.003, 0.0, 0.0], 500);
    assert_eq!(st.correction, [0.0; 3]);
    // 1 mm off: inside, removed.
    let st = run_biased(&cfg, None, [0.001, 0.0, 0.0], 2000);
    assert!(
        (st.correction[0] - 0.001).abs() < 1e-6,
        "{:?}",
        st.correction
    );
    // A slew limit so tight the command never reaches its target: no
    // integration while the tip is still on its way.
    let mut slow = cfg4();
    slow.limits = TendonLimits::uniform(4, 10.0, 1e-3).unwrap();
    slow.integral = cfg.integral;
    // (The first step integrates once, ki·e·dt = 5e-5 m: nothing was
    // commanded yet, so nothing was held back.)
    let st = run_biased(&slow, None, [0.001, 0.0, 0.0], 500);
    assert!(st.slew_limited);
    assert!(st.correction[0] <= 5.0001e-5, "{:?}", st.correction);
}

#[test]
fn integral_loop_removes_a_constant_plant_offset() {
    // Plant: the measured tip is the pose the net was asked for, shifted by a
    // constant bias. The integrator must converge to exactly that bias.
    let mut cfg = cfg4();
    cfg.integral = IntegralConfig {
        filter_tau_s: 0.0,
        map_gain: 0.0,
        map_scale: 1.0,
        map_limit: 0.0,
        ki: 50.0,
        limit: 0.01,
        feedback_timeout_ns: 5_000_000,
        window: f32::INFINITY,
    };
    let net = Net::decode(&blob(3, 12, 4)).unwrap();
    let pose = mid_pose();
    let bias = [0.002f32, -0.001, 0.0005];
    let mut st = ControlState::new(&cfg.limits, &[0.0; MAX_TENDONS], 0);
    let mut status = Status::empty();
    for k in 1..2000u64 {
        let tip = [
            pose[0] + st.correction[0] - bias[0],
            pose[1] + st.correction[1] - bias[1],
            pose[2] + st.correction[2] - bias[2],
        ];
        let inp = StepInput {
            now_ns: k * 1_000_000,
            setpoint: sp(k, pose),
            feedback: Some(Feedback {
                seq: k,
                tip_position: tip,
                interval_s: 1_000_000_f32 * 1e-9,
            }),
        };
        let (s, o) = control_step(&cfg, &net, &st, &inp);
        st = s;
        status = o.status;
    }
    assert!(status.contains(Status::CORRECTION));
    for i in 0..3 {
        assert!(
            (st.correction[i] - bias[i]).abs() < 1e-6,
            "{i}: {:?}",
            st.correction
        );
    }
    // Feedback stops: the correction freezes and the status says so.
    let (s, o) = control_step(&cfg, &net, &st, &input(2_010_000_000, sp(3000, pose)));
    assert!(o.status.contains(Status::PLANT_STALE));
    assert_eq!(s.correction, st.correction);
}

#[test]
fn a_rejected_blob_leaves_the_running_net_in_place() {
    let good = blob(3, 12, 4);
    let other = blob(8, 12, 4);
    let mut slots = NetSlots::<7, 16, 8, { weight_capacity(7, 16, 8) }>::new();
    slots.load(&good, (7, 4)).unwrap();
    let pose = mid_pose();
    let before = infer(slots.active(), &pose);
    let mut bad = other.clone();
    bad[30] ^= 1;
    assert!(matches!(
        slots.load(&bad, (7, 4)),
        Err(SwapError::Decode(_))
    ));
    assert_eq!(infer(slots.active(), &pose), before);
    assert!(matches!(
        slots.load(&blob(3, 12, 3), (7, 4)),
        Err(SwapError::ShapeMismatch { outputs: 3, .. })
    ));
    assert_eq!(infer(slots.active(), &pose), before);
    assert!(matches!(
        slots.load(&blob(3, 17, 4), (7, 4)),
        Err(SwapError::Decode(_))
    ));
    assert_eq!(infer(slots.active(), &pose), before);
    slots.load(&other, (7, 4)).unwrap();
    let after = infer(slots.active(), &pose);
    assert_eq!(after, infer(&Net::decode(&other).unwrap(), &pose));
    assert_ne!(after, before);
    // Swapping back and forth keeps working (both buffers reused).
    slots.load(&good, (7, 4)).unwrap();
    assert_eq!(infer(slots.active(), &pose), before);
}

/// `b` with its last weight (just before the CRC) NaN and the CRC
/// recomputed: passes every structural check, fails only on the value.
fn nan_blob(b: &[u8]) -> Vec<u8> {
    let mut bad = b.to_vec();
    let body = bad.len() - 4;
    bad[body - 4..body].copy_from_slice(&f32::NAN.to_le_bytes());
    let crc = tendril_shared::crc32::crc32(&bad[..body]);
    bad[body..].copy_from_slice(&crc.to_le_bytes());
    bad
}

#[test]
fn flash_slot_rejections_keep_the_running_net_flash_or_ram() {
    let flash = Net64::decode(&blob(3, 12, 4)).unwrap();
    let update = blob(8, 40, 4);
    let update2 = blob(9, 5, 4);
    let mut ram = std::boxed::Box::new(Net64::empty());
    let mut store = FlashSlot::new(&flash, &mut ram);
    let want = (7, 4);
    let mut crc_flip = update.clone();
    crc_flip[40] ^= 0x10;
    let rejects: [(&str, Vec<u8>); 5] = [
        ("NaN weight under a valid CRC", nan_blob(&update)),
        ("truncated", update[..update.len() - 1].to_vec()),
        ("corrupted byte", crc_flip),
        ("wrong output count", blob(8, 40, 3)),
        ("over capacity", blob(8, 65, 4)),
    ];
    let check_rejects = |store: &mut FlashSlot<'_, 7, 64, 8, { weight_capacity(7, 64, 8) }>,
                         running: &Net64,
                         on_ram: bool| {
        for (what, b) in &rejects {
            assert!(store.load(b, want).is_err(), "{what} accepted");
            assert_eq!(store.active(), running, "{what} changed the running net");
            assert_eq!(store.running_ram(), on_ram, "{what}");
        }
    };
    // The flash net runs; rejections leave it.
    check_rejects(&mut store, &flash, false);
    assert!(core::ptr::eq(store.active(), &flash));
    // An update goes to RAM and runs.
    let expected = Net64::decode(&update).unwrap();
    store.load(&update, want).unwrap();
    assert!(store.running_ram());
    assert_eq!(store.active(), &expected);
    // While the RAM slot runs, every rejection leaves it intact, including
    // the NaN blob that is only refused after the whole file was read.
    check_rejects(&mut store, &expected, true);
    // An update over the running RAM net; a smaller one leaves no stale weights.
    store.load(&update2, want).unwrap();
    assert_eq!(store.active(), &Net64::decode(&update2).unwrap());
    check_rejects(&mut store, &Net64::decode(&update2).unwrap(), true);
    // Back to flash.
    assert!(store.revert());
    assert!(!store.revert());
    assert!(core::ptr::eq(store.active(), &flash));
}

#[test]
fn the_flash_default_net_is_its_file_decoded_at_run_time() {
    // build.rs generated DEFAULT_NET from this file through `from_view` in
    // const context; the run-time decoder must give the same net.
    let file = include_bytes!(env!("TENDRIL_FW_NET_FILE"));
    let decoded = crate::McuNet::decode(file).unwrap();
    assert_eq!(crate::DEFAULT_NET, decoded);
    assert!(crate::DEFAULT_NET.shape().hidden <= tendril_shared::MAX_HIDDEN);
}

#[test]
fn vector_header_and_records_round_trip() {
    let h = VecHeader {
        count: 2,
        n_tendons: 4,
        max_tension: 10.0,
        slew_rate: 200.0,
        watchdog_ns: 7,
        max_dt_ns: 8,
        ki: 0.5,
        integral_limit: 0.01,
        feedback_timeout_ns: 9,
        quaternion_tolerance: 0.02,
        box_margin: 0.03,
    };
    let r = Record {
        now_ns: 123,
        flags: vectors::HAS_SETPOINT,
        seq: 4,
        pose: mid_pose(),
        tip: [1.0, 2.0, 3.0],
    };
    let mut bytes = std::vec![0u8; vectors::HEADER_LEN + 2 * vectors::RECORD_LEN];
    h.write((&mut bytes[..vectors::HEADER_LEN]).try_into().unwrap());
    for k in 0..2 {
        let at = vectors::HEADER_LEN + k * vectors::RECORD_LEN;
        r.write(
            (&mut bytes[at..at + vectors::RECORD_LEN])
                .try_into()
                .unwrap(),
        );
    }
    let (h2, recs) = vectors::parse(&bytes).unwrap();
    assert_eq!(h2, h);
    let recs: Vec<Record> = recs.collect();
    assert_eq!(recs, std::vec![r, r]);
    assert!(vectors::parse(&bytes[..bytes.len() - 1]).is_err());
}

// ---- property tests of the control step -------------------------------------

/// A float from the nasty corners: NaN, ±∞, huge, tiny, in-box, just out.
fn nasty_f32() -> impl Strategy<Value = f32> {
    prop_oneof![
        Just(f32::NAN),
        Just(f32::INFINITY),
        Just(f32::NEG_INFINITY),
        Just(f32::MAX),
        Just(-f32::MAX),
        Just(0.0f32),
        -1e6f32..1e6f32,
        -1.0f32..1.0f32,
    ]
}

#[derive(Clone, Debug)]
struct Event {
    dt_ns: i64,
    setpoint: Option<(u64, [f32; 7], bool)>,
    feedback: Option<[f32; 3]>,
}

fn pose_strategy() -> impl Strategy<Value = [f32; 7]> {
    let in_box = (0.0f32..1.0, 0.0f32..1.0, 0.0f32..1.0).prop_map(|(a, b, c)| {
        let mut p = box_centre();
        p[0] = INPUT_LO[0] + a * (INPUT_HI[0] - INPUT_LO[0]);
        p[1] = INPUT_LO[1] + b * (INPUT_HI[1] - INPUT_LO[1]);
        p[2] = INPUT_LO[2] + c * (INPUT_HI[2] - INPUT_LO[2]);
        let n = (p[3] * p[3] + p[4] * p[4] + p[5] * p[5] + p[6] * p[6]).sqrt();
        for q in &mut p[3..] {
            *q /= n;
        }
        p
    });
    let wild = proptest::array::uniform7(nasty_f32());
    prop_oneof![3 => in_box, 1 => wild]
}

fn event_strategy() -> impl Strategy<Value = Event> {
    (
        prop_oneof![8 => 0i64..3_000_000, 1 => -5_000_000i64..0, 1 => 0i64..100_000_000],
        proptest::option::weighted(0.7, (0u64..50, pose_strategy(), any::<bool>())),
        proptest::option::weighted(0.5, proptest::array::uniform3(nasty_f32())),
    )
        .prop_map(|(dt_ns, setpoint, feedback)| Event {
            dt_ns,
            setpoint,
            feedback,
        })
}

fn config_strategy() -> impl Strategy<Value = ControlConfig> {
    (
        1usize..=8,
        0.1f32..50.0,
        0.5f32..500.0,
        any::<bool>(),
        0.0f32..200.0,
        0.0f32..0.2,
        (
            prop_oneof![1 => Just(0.0f32), 1 => 0.0f32..0.6],
            any::<bool>(),
        ),
    )
        .prop_map(|(n, max_t, rate, ramp, ki, margin, (floor, sets))| {
            let limits = TendonLimits::uniform(n, max_t, rate)
                .unwrap()
                .with_min_tension(&[floor * max_t; MAX_TENDONS][..n])
                .unwrap();
            let limits = if sets {
                limits
                    .with_cocontraction(tendril_shared::CoContraction::opposite_pairs(n))
                    .unwrap()
            } else {
                limits
            };
            let mut c = ControlConfig::new(limits);
            c.watchdog_ns = 10_000_000;
            c.max_dt_ns = 3_000_000;
            c.box_margin = margin;
            if ramp {
                c.safe_hold = SafeHold::Ramp([max_t * 0.5; MAX_TENDONS]);
            }
            c.integral = IntegralConfig {
                filter_tau_s: 0.0,
                map_gain: 0.0,
                map_scale: 1.0,
                map_limit: 0.0,
                ki,
                limit: 0.02,
                feedback_timeout_ns: 4_000_000,
                window: f32::INFINITY,
            };
            c
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn command_stays_in_range_within_slew_and_watchdog_trips(
        cfg in config_strategy(),
        outputs in 1usize..=8,
        initial in proptest::array::uniform9(nasty_f32()),
        events in proptest::collection::vec(event_strategy(), 1..80),
    ) {
        // The net's outputs usually match the tendons (sometimes not: mismatch path).
        let n = cfg.limits.n_tendons();
        let net_out = if outputs % 3 == 0 { outputs } else { n };
        let net = Net::decode(&blob(11, 6, net_out)).unwrap();
        let max_t = *cfg.limits.max_tension_padded();
        let min_t = *cfg.limits.min_tension_padded();
        let rate = *cfg.limits.slew_rate_padded();
        let mut now: u64 = 1_000_000_000;
        let mut st = ControlState::new(&cfg.limits, &initial, now);
        let mut last_accepted = now;
        for ev in events {
            let prev = st.command;
            let prev_now = st.last_step_ns;
            now = if ev.dt_ns < 0 { now.saturating_sub(ev.dt_ns.unsigned_abs()) } else { now + ev.dt_ns as u64 };
            let inp = StepInput {
                now_ns: now,
                setpoint: ev.setpoint.map(|(seq, pose, _)| ControlSetpoint {
                    seq,
                    pose,
                    tangent: None,
                }),
                feedback: ev.feedback.map(|tip| Feedback { seq: now, tip_position: tip, interval_s: 1e-3 }),
            };
            let (s, o) = control_step(&cfg, &net, &st, &inp);
            let dt = now.saturating_sub(prev_now).min(cfg.max_dt_ns) as f32 * 1e-9;
            for i in 0..MAX_TENDONS {
                let c = o.command[i];
                prop_assert!(c.is_finite());
                prop_assert!(c >= min_t[i] && c <= max_t[i], "tendon {i}: {c} outside [{}, {}]", min_t[i], max_t[i]);
                let allowed = rate[i] * dt;
                // Up to the rounding of `prev + step` (an ulp of values ≤ max).
                prop_assert!((c - prev[i]).abs() <= allowed * (1.0 + 1e-5) + max_t[i] * 3e-7,
                    "tendon {i}: moved {} > {allowed}", (c - prev[i]).abs());
            }
            if o.status.contains(Status::NEW_SETPOINT) || o.status.contains(Status::OUT_OF_WORKSPACE) {
                last_accepted = now;
            }
            if now.saturating_sub(last_accepted) > cfg.watchdog_ns && !o.status.contains(Status::NEW_SETPOINT) {
                prop_assert!(s.watchdog, "silent for {} ns but no watchdog", now - last_accepted);
                prop_assert!(o.status.contains(Status::SAFE_HOLD));
            }
            prop_assert_eq!(o.command, s.command);
            st = s;
        }
    }

    #[test]
    fn inference_never_panics_on_any_pose(pose in proptest::array::uniform7(nasty_f32())) {
        let net = Net::decode(&blob(3, 12, 4)).unwrap();
        let _ = infer(&net, &pose);
    }
}

//! Unit and property tests of the control step (docs/design.md §5.2).

#![allow(clippy::needless_range_loop)] // index loops read like the formulas here

use proptest::prelude::*;
use tendril_shared::{TendonLimits, MAX_TENDONS};

use crate::control::integral::corrected_pose;
use crate::control::*;
use crate::infer::infer;
use crate::synth::{INPUT_HI, INPUT_LO};

use crate::test_support::*;

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

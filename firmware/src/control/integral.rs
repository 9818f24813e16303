//! The control step's integral outer loop (docs/design.md §5, §6.3): the
//! constant correction `c` and the error map `M` learned from the tracker's
//! frames, and the setpoint they correct.

use tendril_shared::CascadeNet;

use super::{clamp, in_box, ControlConfig, ControlState, StepInput, POSE_DIM};
use crate::status::Status;

/// Time constant of the running mean x̄ the error map learns about, s
/// ([`IntegralConfig::map_gain`]): the map's update is `ē (x − x̄)ᵀ`, so
/// the mean error is the constant correction's alone and the map learns
/// only how the error varies with x (the slope of a regression, from
/// centred data); the correction itself stays `c + M x`.
///
/// Why: with the update on x from a fixed point (where tracking began,
/// the rest pose) a path away from it gives the regressor a large constant
/// part, which the map and `c` both learned, and the two adaptations
/// together were unstable on a robot 10 % off its model: the circle's
/// error grew from 0.50 to 1.28 mm over 25 s at 0.4 Hz, and from 0.38 to
/// 1.04 mm over 40 s at the default 0.2 Hz (`everything`), where `c`
/// alone holds 0.9 mm flat. A linear model of the loop (first mode, motor
/// lag, the 80 ms filter, ki 4 /s, map gain 2 /s, the plant 9 % short
/// about its rest pose) grows the same way, and with the centred update
/// converges on circles at 0.1–0.4 Hz for time constants of 2–10 s,
/// fastest at 2 s (BENCHMARKS.md). Centring the correction too (`M (x −
/// x̄)`) was worse: a sweep along one axis cannot express the running
/// mean's phase in a scalar map.
pub const MAP_MEAN_TAU_S: f32 = 2.0;

/// Integral outer loop, applied to the setpoint before inference
/// (docs/design.md §5, §6: removes the net's steady-state error). `ki = 0`
/// disables it.
///
/// With a setpoint tangent ([`super::ControlSetpoint::tangent`], k columns
/// T_j along unit axes a_j) one law for every robot: the error along each
/// axis
/// `e_j = a_j · (p_setpoint − p_measured)` is integrated,
/// `c_j += ki · e_j · dt`, and the setpoint moves along the robot's
/// reachable poses, `pose + Σ_j c_j T_j` (k = 2 with axes x, y: the lateral
/// loop of a one-segment robot; k = 3 a volume; k = 1 a curve). Without one
/// the position alone moves, `p += c`, all three components. The second
/// leaves the poses a net trained on reachable poses has seen, and can turn
/// the loop's gain negative (measured on the default robot: the
/// position-only loop diverged to 31 mm RMS on the 30 mm circle). No
/// integration while the command is still slewing toward its target or the
/// error exceeds `window` (|e| over the k axes; the lateral error without a
/// tangent): those are transients, not IK error, and integrating them winds
/// the correction up.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IntegralConfig {
    /// Integral gain, 1/s (0 = off).
    pub ki: f32,
    /// Bound on each correction component, m (anti-windup).
    pub limit: f32,
    /// Feedback older than this freezes the correction ([`Status::PLANT_STALE`]), ns.
    pub feedback_timeout_ns: u64,
    /// Integrate only while the tip error along the tangent's axes (the
    /// lateral error without a tangent) is at most this, m
    /// (`f32::INFINITY`: always).
    pub window: f32,
    /// Time constant of the first-order low-pass filter on the error before
    /// it is integrated, s (0 = none): it takes the first bending mode's
    /// resonance and the tracker's jitter out of the loop (docs/design.md
    /// §6.3, the loop analysis).
    pub filter_tau_s: f32,
    /// Adaptation gain of the *error map*, 1/s (0 = off): besides the
    /// constant correction `c`, the loop learns how the robot's error
    /// varies with where it is sent, `c(x) = c + M x` (x the setpoint's
    /// position along the axes, from where tracking began; the map learns
    /// from x about its running mean, [`MAP_MEAN_TAU_S`]). A robot stiffer
    /// than its model or with its tendons off errs in proportion to how far
    /// it bends: a map, which a constant correction can only chase around a
    /// circle, but which, once learned, holds everywhere (normalised LMS on
    /// x̃ = x − x̄: `M += map_gain · ē x̃ᵀ dt / (map_scale² + |x̃|²)`).
    pub map_gain: f32,
    /// Length scale of the map's normalisation, m (> 0 when `map_gain` is).
    pub map_scale: f32,
    /// Bound on each entry of the map (dimensionless: 0.5 = the robot
    /// goes half again as far as asked).
    pub map_limit: f32,
}

impl IntegralConfig {
    /// The loop switched off.
    pub const OFF: IntegralConfig = IntegralConfig {
        ki: 0.0,
        limit: 0.0,
        feedback_timeout_ns: 0,
        window: f32::INFINITY,
        filter_tau_s: 0.0,
        map_gain: 0.0,
        map_scale: 1.0,
        map_limit: 0.0,
    };
}

/// Step 4 of [`control_step`]: integrate a fresh frame and return the
/// pose to infer (the corrected setpoint, or the setpoint when the
/// correction would leave the net's box). Out of line so its locals are
/// not on the stack while the net runs (the chip's RAM budget).
#[inline(never)]
pub(super) fn outer_loop<const H: usize, const OUT: usize, const W: usize>(
    cfg: &ControlConfig,
    net: &CascadeNet<POSE_DIM, H, OUT, W>,
    st: &mut ControlState,
    input: &StepInput,
    status: &mut Status,
) -> [f32; POSE_DIM] {
    let now = input.now_ns;
    let ic = cfg.integral;
    let mut pose = st.pose;
    let mut fresh = false;
    if let Some(fb) = input.feedback {
        if fb.tip_position.iter().any(|v| !v.is_finite()) {
            *status |= Status::BAD_FEEDBACK;
        } else if fb.seq > st.last_feedback_seq {
            st.last_feedback_seq = fb.seq;
            st.last_feedback_ns = now;
            fresh = true;
            let before = (st.correction, st.error_map);
            let interval = fb.interval_s.is_finite().then_some(fb.interval_s);
            let interval = clamp(
                interval.unwrap_or(0.0),
                0.0,
                ic.feedback_timeout_ns as f32 * 1e-9,
            );
            integrate(st, &fb.tip_position, ic, interval);
            if !in_box(net, &corrected_pose(st), cfg.box_margin) {
                (st.correction, st.error_map) = before;
            }
        }
    }
    if !fresh && now.saturating_sub(st.last_feedback_ns) > ic.feedback_timeout_ns {
        *status |= Status::PLANT_STALE;
    }
    let corrected = corrected_pose(st);
    if in_box(net, &corrected, cfg.box_margin) {
        pose = corrected;
        if st.correction.iter().any(|&c| c != 0.0) {
            *status |= Status::CORRECTION;
        }
    } else {
        *status |= Status::CORRECTION_LIMITED;
    }
    pose
}

/// One sample into the correction on the measured tip `tip` (module docs
/// of [`IntegralConfig`]): e_j = a_j · (p_set − p_meas) along the
/// tangent's k axes, or the position error without a tangent; the error
/// low-pass filtered over the sample's `dt` (backward Euler,
/// `ē += dt/(τ_f + dt) (e − ē)`, stable for any dt), then integrated,
/// `c_j += ki ē_j dt` — neither while the command is still slewing or the
/// raw error is outside the window (on its lateral part without a
/// tangent): transients, not IK error.
fn integrate(st: &mut ControlState, tip: &[f32; 3], ic: IntegralConfig, dt: f32) {
    if ic.map_gain > 0.0 {
        // The map's running mean follows the setpoint whatever the frame
        // (backward Euler, stable for any interval).
        let a = dt / (MAP_MEAN_TAU_S + dt);
        for (m, &p) in st.map_mean.iter_mut().zip(&st.pose) {
            *m += a * (p - *m);
        }
    }
    let mut error = [0.0f32; 3];
    for ((e, &p), &m) in error.iter_mut().zip(&st.pose).zip(tip) {
        *e = p - m;
    }
    let (along, axes) = match st.tangent {
        Some(t) => {
            let mut along = [0.0f32; 3];
            for (u, a) in along.iter_mut().zip(&t.axes).take(t.dim) {
                *u = a[0] * error[0] + a[1] * error[1] + a[2] * error[2];
            }
            (along, t.dim)
        }
        None => (error, 3),
    };
    // The window: |e| over the tangent's axes, the lateral error without.
    let windowed = if st.tangent.is_some() { axes } else { 2 };
    let size2 = along
        .iter()
        .take(windowed)
        .fold(0.0f32, |sum, e| sum + e * e);
    if st.slew_limited || size2 > ic.window * ic.window {
        // The filter holds too: after the transient it resumes from the
        // error before it, not from the transient's tail.
        return;
    }
    if ic.filter_tau_s > 0.0 {
        let a = dt / (ic.filter_tau_s + dt);
        for (f, &e) in st.filtered_error.iter_mut().zip(&along).take(axes) {
            *f += a * (e - *f);
        }
    } else {
        st.filtered_error = along;
    }
    for (c, &e) in st.correction.iter_mut().zip(&st.filtered_error).take(axes) {
        *c = clamp(*c + ic.ki * e * dt, -ic.limit, ic.limit);
    }
    if ic.map_gain > 0.0 {
        let x = map_coordinates(st, &st.map_mean);
        let x2 = x.iter().take(axes).fold(0.0f32, |s, v| s + v * v);
        let step = ic.map_gain * dt / (ic.map_scale * ic.map_scale + x2);
        let e = st.filtered_error;
        for (row, &ej) in st.error_map.iter_mut().zip(&e).take(axes) {
            for (m, &xi) in row.iter_mut().zip(&x).take(axes) {
                *m = clamp(*m + step * ej * xi, -ic.map_limit, ic.map_limit);
            }
        }
    }
}

/// The setpoint with the integral correction applied: along the tangent
/// if there is one, `pose + Σ_j c_j T_j` (first order; the quaternion's
/// norm changes by O(c²), far inside the quaternion tolerance for
/// millimetre corrections), else to the position alone.
pub(crate) fn corrected_pose(st: &ControlState) -> [f32; POSE_DIM] {
    let mut p = st.pose;
    let c = total_correction(st);
    match st.tangent {
        Some(t) => {
            // Σ_j c_j T_j first, then added: for k = 2 the same roundings
            // as the lateral law's `v + (T_x c_x + T_y c_y)`.
            let mut shift = [0.0f32; POSE_DIM];
            for (column, cj) in t.columns.iter().zip(c).take(t.dim) {
                for (s, d) in shift.iter_mut().zip(column) {
                    *s += d * cj;
                }
            }
            for (v, s) in p.iter_mut().zip(shift) {
                *v += s;
            }
        }
        None => {
            for (v, c) in p.iter_mut().zip(c) {
                *v += c;
            }
        }
    }
    p
}

/// The setpoint's position along the loop's axes (the tangent's, or x, y, z
/// without one), from `from` (m): the map's origin for the correction, its
/// running mean for the map's update.
fn map_coordinates(st: &ControlState, from: &[f32; 3]) -> [f32; 3] {
    let d = [
        st.pose[0] - from[0],
        st.pose[1] - from[1],
        st.pose[2] - from[2],
    ];
    match st.tangent {
        Some(t) => {
            let mut x = [0.0f32; 3];
            for (v, a) in x.iter_mut().zip(&t.axes).take(t.dim) {
                *v = a[0] * d[0] + a[1] * d[1] + a[2] * d[2];
            }
            x
        }
        None => d,
    }
}

/// The correction at the current setpoint: `c + M x`. With the map off
/// (all zero) exactly `c`.
fn total_correction(st: &ControlState) -> [f32; 3] {
    let mut c = st.correction;
    if st.error_map.iter().flatten().any(|&m| m != 0.0) {
        let x = map_coordinates(st, &st.map_origin);
        for (cj, row) in c.iter_mut().zip(&st.error_map) {
            *cj += row[0] * x[0] + row[1] * x[1] + row[2] * x[2];
        }
    }
    c
}

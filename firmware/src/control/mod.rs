//! The control step (docs/design.md §5): a pure, deterministic function of
//! (state, setpoint, feedback, time) → (state, tension command), with every
//! safety decision recorded in a [`Status`] word.
//!
//! Order of a step:
//! 1. time: `dt` since the previous step, capped at [`ControlConfig::max_dt_ns`]
//!    (a late step never earns a bigger jump); a clock that runs backwards
//!    gives `dt = 0` (command frozen) and [`Status::CLOCK_FAULT`];
//! 2. setpoint: a setpoint whose sequence number is not newer than the last
//!    one is stale and ignored; a NaN/∞ pose or a non-unit quaternion is
//!    rejected; a pose outside the net's normalisation box (plus
//!    [`ControlConfig::box_margin`]) is *held*: the previous target stays;
//! 3. watchdog: no acceptable setpoint for [`ControlConfig::watchdog_ns`] →
//!    safe hold until the next acceptable one;
//! 4. optional integral outer loop on the measured tip position;
//! 5. inference → target tensions; a non-finite output is rejected (hold);
//! 6. the command stage: shift each co-contraction set of the target into
//!    `[min_tension, max_tension]` ([`crate::command`], keeps the bend),
//!    clip what remains, then move the command toward it by at most
//!    `slew_rate · dt` per tendon.
//!
//! **Why hold rather than project an unreachable setpoint.** The net's box is
//! the axis-aligned hull of the training poses; clamping each coordinate into
//! it produces a pose with a non-unit quaternion that the robot cannot reach
//! and the net never saw, so the tensions it returns are arbitrary. Holding
//! the last good target keeps the robot at the last pose known to be
//! reachable, is trivially within limits, and the planner sees
//! [`Status::OUT_OF_WORKSPACE`] and can re-plan. `box_margin` admits poses
//! marginally outside the box (the net extrapolates smoothly a little way).

use tendril_shared::{CascadeNet, TendonLimits, MAX_TENDONS};

use crate::command::co_contract;
use crate::infer::infer;

pub use tendril_shared::POSE_DIM;

pub use crate::command::Tensions;

pub use crate::status::Status;

mod integral;

use integral::outer_loop;
pub use integral::{IntegralConfig, MAP_MEAN_TAU_S};

/// What the command does while the watchdog holds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SafeHold {
    /// Keep the last command (the robot stays where it is).
    Freeze,
    /// Move (at the slew rate) to these tensions, clamped to the limits,
    /// e.g. all zero to relax the robot.
    Ramp(Tensions),
}

/// Everything the control step needs besides the net. Build with
/// [`ControlConfig::new`] and adjust fields.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControlConfig {
    /// Tension range and slew rate per tendon.
    pub limits: TendonLimits,
    /// Silence after the last acceptable setpoint that trips the watchdog, ns.
    pub watchdog_ns: u64,
    /// Largest `dt` the slew limit credits for one step, ns.
    pub max_dt_ns: u64,
    /// Allowed `| |q|² − 1 |` of a setpoint quaternion.
    pub quaternion_tolerance: f32,
    /// How far outside the normalisation box (fraction of each range) a
    /// setpoint may lie and still be used.
    pub box_margin: f32,
    /// Behaviour while the watchdog holds.
    pub safe_hold: SafeHold,
    /// Optional integral outer loop.
    pub integral: IntegralConfig,
}

impl ControlConfig {
    /// Defaults for a 1 kHz loop: watchdog 50 ms, `dt` capped at 5 ms,
    /// quaternion tolerance 1e-2, no box margin, freeze on hold, no integral.
    pub const fn new(limits: TendonLimits) -> ControlConfig {
        ControlConfig {
            limits,
            watchdog_ns: 50_000_000,
            max_dt_ns: 5_000_000,
            quaternion_tolerance: 1e-2,
            box_margin: 0.0,
            safe_hold: SafeHold::Freeze,
            integral: IntegralConfig::OFF,
        }
    }
}

/// Most columns of a [`ControlTangent`]: a tip reaches at most a volume.
pub const MAX_TANGENT_DIM: usize = 3;

/// The robot's reachable poses near a setpoint, to first order: k columns
/// `∂pose/∂u_j` (per m), u_j = a_j · p the tip's coordinate along unit axis
/// a_j (base frame). Entries past `dim` are ignored.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControlTangent {
    /// k: how many columns and axes are valid (1..=[`MAX_TANGENT_DIM`]).
    pub dim: usize,
    /// `∂pose/∂u_j`.
    pub columns: [[f32; POSE_DIM]; MAX_TANGENT_DIM],
    /// The unit axes a_j.
    pub axes: [[f32; 3]; MAX_TANGENT_DIM],
}

impl ControlTangent {
    /// The lateral family of a one-segment robot: columns `∂pose/∂px`,
    /// `∂pose/∂py` along the axes x and y.
    pub const fn lateral(columns: [[f32; POSE_DIM]; 2]) -> ControlTangent {
        ControlTangent {
            dim: 2,
            columns: [columns[0], columns[1], [0.0; POSE_DIM]],
            axes: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0; 3]],
        }
    }

    /// Whether the loop may use it: k in 1..=3 and its valid columns and
    /// axes finite.
    pub fn is_valid(&self) -> bool {
        (1..=MAX_TANGENT_DIM).contains(&self.dim)
            && self
                .columns
                .iter()
                .take(self.dim)
                .flatten()
                .chain(self.axes.iter().take(self.dim).flatten())
                .all(|v| v.is_finite())
    }
}

/// A desired tip pose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControlSetpoint {
    /// Sender's sequence number; must increase for the setpoint to count.
    pub seq: u64,
    /// `px, py, pz` (m), `qw, qx, qy, qz`.
    pub pose: [f32; POSE_DIM],
    /// The robot's reachable poses about `pose`, if the planner knows
    /// them: lets the integral loop move the setpoint the way the robot can
    /// move ([`IntegralConfig`]). Ignored unless [`ControlTangent::is_valid`].
    pub tangent: Option<ControlTangent>,
}

/// One tracker sample of the tip, as the integral loop takes it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Feedback {
    /// Sample number; must increase to count as fresh (a sample is
    /// integrated once, however many periods it stays the newest).
    pub seq: u64,
    /// Measured tip position, m (already advanced along the path for its
    /// age and the motor lag by the caller: docs/design.md §5.5).
    pub tip_position: [f32; 3],
    /// Time this sample stands for: since the previous sample was taken,
    /// s (0 for the first). The loop integrates `ki · e · interval_s`, so
    /// its gain is the same whatever the tracker's rate.
    pub interval_s: f32,
}

/// Inputs of one step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepInput {
    /// Monotonic time of this step, ns.
    pub now_ns: u64,
    /// A setpoint received since the last step, if any.
    pub setpoint: Option<ControlSetpoint>,
    /// Plant feedback received since the last step, if any.
    pub feedback: Option<Feedback>,
}

/// The controller's memory between steps (small, `Copy`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControlState {
    /// Command sent last step, N.
    pub command: Tensions,
    /// Target the command is slewing toward, N (held when a setpoint is refused).
    pub target: Tensions,
    /// Time of the last step, ns.
    pub last_step_ns: u64,
    /// Time of the last acceptable setpoint (start time before the first), ns.
    pub last_setpoint_ns: u64,
    /// Sequence number of the last setpoint seen (0 = none).
    pub last_setpoint_seq: u64,
    /// Pose of the last accepted setpoint (valid when `has_setpoint`).
    pub pose: [f32; POSE_DIM],
    /// Its tangent along the reachable poses, if it came with a valid one.
    pub tangent: Option<ControlTangent>,
    /// The last command was held back by the slew limit (the tip is still
    /// on its way: the integral loop waits).
    pub slew_limited: bool,
    /// Whether a setpoint has been accepted yet.
    pub has_setpoint: bool,
    /// Whether the watchdog holds (latched until an acceptable setpoint).
    pub watchdog: bool,
    /// Integral correction, m: c_j along the tangent's axes (first k
    /// entries), or of the position without a tangent.
    pub correction: [f32; 3],
    /// The low-pass filtered error, m, in the same coordinates as
    /// `correction` ([`IntegralConfig::filter_tau_s`]).
    pub filtered_error: [f32; 3],
    /// The error map M ([`IntegralConfig::map_gain`]): row j, the
    /// correction along axis j per metre of setpoint along axis i.
    pub error_map: [[f32; 3]; 3],
    /// Where the map's x is measured from: the first accepted setpoint's
    /// position, m.
    pub map_origin: [f32; 3],
    /// The setpoint's position averaged over the last [`MAP_MEAN_TAU_S`],
    /// m: the map learns from x about it ([`IntegralConfig::map_gain`]).
    pub map_mean: [f32; 3],
    /// Sequence number of the last feedback used.
    pub last_feedback_seq: u64,
    /// Time of the last fresh feedback, ns.
    pub last_feedback_ns: u64,
}

impl ControlState {
    /// Start at time `now_ns` holding `initial` (clamped to the limits;
    /// NaN entries become the floor).
    pub fn new(limits: &TendonLimits, initial: &Tensions, now_ns: u64) -> ControlState {
        let mut command = [0.0f32; MAX_TENDONS];
        for (((c, &t), &min), &max) in command
            .iter_mut()
            .zip(initial)
            .zip(limits.min_tension_padded())
            .zip(limits.max_tension_padded())
        {
            *c = if t.is_finite() {
                clamp(t, min, max)
            } else {
                min
            };
        }
        ControlState::holding(command, now_ns)
    }

    /// Start at time `now_ns` holding `command` as it is (the caller has
    /// clamped it); `const`, for a period that is a constant before it is
    /// configured.
    pub const fn holding(command: Tensions, now_ns: u64) -> ControlState {
        ControlState {
            command,
            target: command,
            last_step_ns: now_ns,
            last_setpoint_ns: now_ns,
            last_setpoint_seq: 0,
            pose: [0.0; POSE_DIM],
            tangent: None,
            slew_limited: false,
            has_setpoint: false,
            watchdog: false,
            correction: [0.0; 3],
            filtered_error: [0.0; 3],
            error_map: [[0.0; 3]; 3],
            map_origin: [0.0; 3],
            map_mean: [0.0; 3],
            last_feedback_seq: 0,
            last_feedback_ns: now_ns,
        }
    }
}

/// The result of one step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepOutput {
    /// Tensions to apply, N (`count` valid entries, the rest 0).
    pub command: Tensions,
    /// Number of tendons.
    pub count: usize,
    /// What happened.
    pub status: Status,
}

/// Whether every normalised coordinate of `pose` lies in `[−m, 1 + m]`.
fn in_box<const H: usize, const OUT: usize, const W: usize>(
    net: &CascadeNet<POSE_DIM, H, OUT, W>,
    pose: &[f32; POSE_DIM],
    margin: f32,
) -> bool {
    let ranges = net.input_lo().iter().zip(net.input_hi());
    pose.iter().zip(ranges).all(|(&x, (&lo, &hi))| {
        let u = (x - lo) / (hi - lo);
        u >= -margin && u <= 1.0 + margin
    })
}

/// `x` limited to `[lo, hi]` (NaN → `lo`). Unlike `f32::clamp` it has no
/// panic path (`clamp` asserts `lo <= hi`, which would drag a panic and float
/// formatting into the MCU image).
#[inline]
pub fn clamp(x: f32, lo: f32, hi: f32) -> f32 {
    x.max(lo).min(hi)
}

fn quaternion_ok(pose: &[f32; POSE_DIM], tol: f32) -> bool {
    let [_, _, _, w, x, y, z] = *pose;
    let n2 = w * w + x * x + y * y + z * z;
    (n2 - 1.0).abs() <= tol
}

/// One control step. Pure: the same arguments always give the same result,
/// and nothing outside the return value changes.
///
/// Guarantees, for any input (NaN, ∞, huge, stale, out of workspace), with a
/// fixed `cfg`: every command entry is finite and in `[0, max_tension]`, and
/// differs from the previous command by at most `slew_rate · min(dt,
/// max_dt)`; after `watchdog_ns` without an acceptable setpoint the status
/// has [`Status::SAFE_HOLD`].
pub fn control_step<const H: usize, const OUT: usize, const W: usize>(
    cfg: &ControlConfig,
    net: &CascadeNet<POSE_DIM, H, OUT, W>,
    state: &ControlState,
    input: &StepInput,
) -> (ControlState, StepOutput) {
    let mut st = *state;
    let out = control_step_in_place(cfg, net, &mut st, input, true);
    (st, out)
}

/// [`control_step`] on the state in place (the period's: no copy of the
/// state on the chip's stack), and with `run_net = false` without running
/// the net: then the target the command slews toward stays the last
/// step's, and everything else (time, setpoint acceptance, watchdog, the
/// integral loop, limits, slew) runs as always, with the same guarantees.
///
/// `run_net = false` is for the one period in which a weight update is
/// written into the net store (docs/design.md §5.3): the write of a 7-64-8
/// net and the net's run together took 79,600 of the chip's
/// 80,000-instruction period budget (`tests/tests/mcu_budget.rs`), and the
/// write cannot be cut in slices without a second net slot the chip has
/// no RAM for. Holding the target for one period is what a refused
/// setpoint already does; the new net runs from the next period on.
#[inline(never)]
pub fn control_step_in_place<const H: usize, const OUT: usize, const W: usize>(
    cfg: &ControlConfig,
    net: &CascadeNet<POSE_DIM, H, OUT, W>,
    st: &mut ControlState,
    input: &StepInput,
    run_net: bool,
) -> StepOutput {
    let mut status = Status::empty();
    let n = cfg.limits.n_tendons();
    let now = input.now_ns;

    // 1. Time.
    let dt_ns = if now < st.last_step_ns {
        status |= Status::CLOCK_FAULT;
        0
    } else {
        (now - st.last_step_ns).min(cfg.max_dt_ns)
    };
    if now > st.last_step_ns {
        st.last_step_ns = now;
    }
    let dt = dt_ns as f32 * 1e-9;

    let shape = net.shape();
    let net_ok = shape.inputs == POSE_DIM && shape.outputs == n;
    if !net_ok {
        status |= Status::NET_MISMATCH;
    }

    // 2. Setpoint.
    if let Some(sp) = &input.setpoint {
        if st.has_setpoint && sp.seq <= st.last_setpoint_seq {
            status |= Status::STALE_SETPOINT;
        } else if sp.pose.iter().any(|v| !v.is_finite()) {
            st.last_setpoint_seq = sp.seq;
            status |= Status::SETPOINT_REJECTED | Status::NONFINITE_SETPOINT;
        } else if !quaternion_ok(&sp.pose, cfg.quaternion_tolerance) {
            st.last_setpoint_seq = sp.seq;
            status |= Status::SETPOINT_REJECTED | Status::BAD_QUATERNION;
        } else if !net_ok || !in_box(net, &sp.pose, cfg.box_margin) {
            // A live planner asking for an unreachable pose: feed the
            // watchdog, hold the target.
            st.last_setpoint_seq = sp.seq;
            st.last_setpoint_ns = now;
            status |= Status::SETPOINT_REJECTED | Status::OUT_OF_WORKSPACE;
        } else {
            st.last_setpoint_seq = sp.seq;
            st.last_setpoint_ns = now;
            if !st.has_setpoint {
                st.map_origin = [sp.pose[0], sp.pose[1], sp.pose[2]];
                st.map_mean = st.map_origin;
            }
            st.pose = sp.pose;
            st.tangent = sp.tangent.filter(ControlTangent::is_valid);
            st.has_setpoint = true;
            st.watchdog = false;
            status |= Status::NEW_SETPOINT;
        }
    }

    // 3. Watchdog (time since the last acceptable setpoint).
    if now.saturating_sub(st.last_setpoint_ns) > cfg.watchdog_ns {
        st.watchdog = true;
    }
    if !st.has_setpoint {
        status |= Status::NO_SETPOINT;
    }

    let tracking = st.has_setpoint && !st.watchdog && net_ok;

    // 4. Integral outer loop.
    let pose = if cfg.integral.ki > 0.0 && tracking {
        outer_loop(cfg, net, st, input, &mut status)
    } else {
        st.pose
    };

    // 5. Target.
    if st.watchdog || (!net_ok && st.has_setpoint) {
        status |= Status::SAFE_HOLD;
        st.target = match cfg.safe_hold {
            SafeHold::Freeze => st.command,
            SafeHold::Ramp(t) => t,
        };
    } else if tracking && run_net {
        let y = infer(net, &pose);
        if y.iter().take(n).all(|v| v.is_finite()) {
            st.target = [0.0; MAX_TENDONS];
            for (t, v) in st.target.iter_mut().zip(y.iter()).take(n) {
                *t = *v;
            }
        } else {
            status |= Status::NONFINITE_OUTPUT;
        }
    }

    // 6. Limits: shift co-contraction sets into range (keeps the bend),
    //    clip what remains to [min, max], slew the command, clip again (the
    //    previous command is in range unless the limits changed).
    let min_t = cfg.limits.min_tension_padded();
    let max_t = cfg.limits.max_tension_padded();
    let rate = cfg.limits.slew_rate_padded();
    let mut wanted = [0.0f32; MAX_TENDONS];
    for ((w, &tgt), &prev) in wanted.iter_mut().zip(&st.target).zip(&st.command).take(n) {
        *w = if tgt.is_finite() { tgt } else { prev };
    }
    if co_contract(&mut wanted, &cfg.limits) {
        status |= Status::CO_CONTRACTED;
    }
    let mut command = [0.0f32; MAX_TENDONS];
    for i in 0..n.min(MAX_TENDONS) {
        let (Some(&tgt), Some(&min), Some(&max), Some(&r), Some(&prev)) = (
            wanted.get(i),
            min_t.get(i),
            max_t.get(i),
            rate.get(i),
            st.command.get(i),
        ) else {
            continue;
        };
        let clamped = clamp(tgt, min, max);
        if clamped != tgt {
            status |= Status::RANGE_CLAMPED;
        }
        let max_step = r * dt;
        let delta = clamped - prev;
        let step = clamp(delta, -max_step, max_step);
        if step != delta {
            status |= Status::SLEW_LIMITED;
        }
        let c = clamp(prev + step, min, max);
        if let Some(slot) = command.get_mut(i) {
            *slot = if c.is_finite() { c } else { min };
        }
    }
    if status.intersects(Status::RANGE_CLAMPED | Status::SLEW_LIMITED | Status::CO_CONTRACTED) {
        status |= Status::SATURATED;
    }
    st.command = command;
    st.slew_limited = status.contains(Status::SLEW_LIMITED);
    StepOutput {
        command,
        count: n,
        status,
    }
}

#[cfg(test)]
mod tests;

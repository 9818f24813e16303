//! What the planner works out before it joins the loop, and the setpoint
//! it sends for an instant: the path lifted and shaped, the learning, the
//! stiffness adaptation, the net's error offset (`docs/design.md` §6.4,
//! §6.5). The planner process and `tendril-ros2 drive` both plan here.

use tendril_shared::messages::{setpoint_flags, Header, Setpoint};

use super::PlannerConfig;
use crate::ipc::IpcError;
use crate::plan::{
    Learner, LearningChoice, Motion, NetErrorOffset, StiffnessAdaptation, Trajectory,
    TENSION_HEADROOM,
};
use crate::robot::Robot;
use crate::statics::{SolverSettings, Statics};

/// What the planner works out before it joins the loop (the CPU-heavy
/// part: the path lifted to reachable poses, the shaping, the learning).
pub struct Planned {
    /// The path in time: settle, shaped moves, the dynamic offset's inverse.
    pub motion: Motion,
    /// Learning for repeated paths, when asked for and accepted.
    pub learner: Option<Learner>,
    /// The stiffness adaptation, when asked for.
    pub stiffness: Option<StiffnessAdaptation>,
    /// The model's `[base]`: the path is planned in its base frame and
    /// published in the tracker's (`docs/design.md` §2.4).
    pub base: crate::robot::BasePose,
    /// The least tension headroom along the path (warned about below
    /// [`TENSION_HEADROOM`]); `None` without feed-forward tensions.
    pub headroom: Option<crate::plan::Headroom>,
}

/// Work out `cfg`'s path (the planner process's set-up; `tendril-ros2
/// drive` plans the same way in-process).
pub fn plan(cfg: &PlannerConfig) -> Result<Planned, IpcError> {
    if !(cfg.rate_hz > 0.0 && cfg.rate_hz <= 20_000.0 && cfg.settle_s >= 0.0) {
        return Err(IpcError::Config(format!(
            "planner rate {} Hz / settle {} s: rate must be in (0, 20000], settle ≥ 0",
            cfg.rate_hz, cfg.settle_s
        )));
    }
    let robot = Robot::load(&cfg.robot).map_err(|e| IpcError::Other(e.to_string()))?;
    let statics = Statics::new(&robot, SolverSettings::default());
    let shaping = cfg
        .step_shaping
        .resolve(&robot, &cfg.shape)
        .map_err(|e| IpcError::Config(e.to_string()))?;
    if let Some(s) = shaping {
        log::info!(
            "planner: steps and the path's start shaped for the first mode at {:.3} Hz (ζ {:.3}): {:.0} ms",
            s.mode_hz,
            s.damping_ratio,
            s.length_s() * 1e3
        );
    }
    let traj = Trajectory::new(&cfg.shape, &statics)?.with_shaping(shaping);
    let headroom = traj.tension_headroom(&robot);
    if let Some(h) = headroom.filter(|h| h.fraction < TENSION_HEADROOM) {
        log::warn!(
            "planner: the path has tendon {} commanded at {:.3} N, {:.0} % of its range below its \
             {:.3} N limit (the built-in paths keep {:.0} %): little room there for the correction",
            h.tendon,
            h.tension_n,
            h.fraction * 1e2,
            robot.max_tensions()[h.tendon],
            TENSION_HEADROOM * 1e2
        );
    }
    let rest = match shaping {
        Some(s) if cfg.start_from_rest => {
            if s.length_s() > cfg.settle_s {
                log::warn!(
                    "planner: the approach from rest takes {:.2} s, longer than the {:.2} s settle",
                    s.length_s(),
                    cfg.settle_s
                );
            }
            let at_rest = statics
                .solve(&robot.min_tensions(), None)
                .map_err(|e| IpcError::Other(format!("planner: the robot at rest: {e}")))?;
            Some(at_rest.pose())
        }
        _ => None,
    };
    // Only where the path has an acceleration everywhere: at a corner the
    // inverse asks for a kick (a helix whose height turned back at a corner
    // went from 3.4 to 8 mm RMS with it on the three-segment robot; its
    // height now turns back on a parabola, `plan::path::helix_height`).
    let inverse = shaping
        .filter(|_| cfg.dynamic_offset && cfg.shape.is_smooth())
        .map(|s| s.modal_inverse());
    let stiffness = match cfg.adapt_stiffness {
        true => Some(StiffnessAdaptation::new(
            &traj,
            &robot,
            cfg.controller_gains
                .unwrap_or_else(|| controller_gains(&robot)),
            crate::ipc::controller::correction::QUIET_AFTER_MOVE_S,
            shaping.map(|s| s.mode_hz),
            cfg.loop_delay_s
                .unwrap_or_else(|| crate::ipc::controller::loop_delay_s(false)),
        )?),
        false => None,
    };
    let net_error = match (cfg.net_error_offset, &cfg.model) {
        (false, _) => None,
        (true, None) => {
            return Err(IpcError::Config(
                "planner: the net's error offset needs the controller's net (its model file)"
                    .into(),
            ))
        }
        (true, Some(model)) => Some(net_error_offset(model, &statics, &robot, &traj)?),
    };
    let mut motion = Motion::new(traj, cfg.settle_s, rest, inverse);
    if let Some(n) = net_error {
        motion = motion.with_net_error(n);
    }
    if let Some(turning) = &cfg.turning_offset {
        check_turning_offset(turning, &cfg.shape, &robot)?;
        motion = motion.with_turning_offset(turning.clone());
    }
    Ok(Planned {
        motion,
        learner: learner(cfg, &robot, shaping)?,
        stiffness,
        base: robot.base,
        headroom,
    })
}

/// The largest turning offset a planner sends, per coefficient, m: what
/// the model's learning may put there (it stops well below: the soft
/// three-segment robot's circle needed 0.32 mm).
pub const MAX_TURNING_OFFSET_M: f64 = 2e-3;

/// A turning offset is learned for one robot file and one circle.
pub fn check_turning_offset(
    turning: &crate::plan::TurningOffset,
    shape: &crate::plan::PathShape,
    robot: &Robot,
) -> Result<(), IpcError> {
    let bad = |why: String| IpcError::Config(format!("planner: turning offset: {why}"));
    turning.check(MAX_TURNING_OFFSET_M).map_err(bad)?;
    match &turning.learned_for {
        None => return Err(bad("it does not say what it was learned for".into())),
        Some(f) if f.robot != robot.fingerprint() => {
            return Err(bad(format!(
                "learned for another robot file, not {}",
                robot.name
            )))
        }
        Some(f) if f.shape != *shape => {
            return Err(bad(format!(
                "learned for another path ({:?}), not this {}",
                f.shape,
                shape.name()
            )))
        }
        Some(_) => {}
    }
    match shape {
        crate::plan::PathShape::Circle {
            center_m, freq_hz, ..
        } if *center_m == turning.center_m
            && (1.0 / freq_hz - turning.period_s).abs() <= 1e-9 * turning.period_s =>
        {
            Ok(())
        }
        _ => Err(bad(format!(
            "learned for a circle about ({:.4}, {:.4}) m with a {:.3} s period, not for this {}",
            turning.center_m[0],
            turning.center_m[1],
            turning.period_s,
            shape.name()
        ))),
    }
}

/// The offset that cancels the net in `model`'s quasi-static error along
/// `traj` (`plan::net_error`): the net run as the chip runs it, its output
/// through the period's command stage (the co-contraction shift, the clip
/// to the limits) as in a steady state.
fn net_error_offset(
    model: &std::path::Path,
    statics: &Statics,
    robot: &Robot,
    traj: &Trajectory,
) -> Result<NetErrorOffset, IpcError> {
    let net =
        crate::net::read_tnet(model).map_err(|e| IpcError::Config(format!("planner: {e}")))?;
    // The slew rate plays no part in a steady state's command.
    let limits = crate::command_stage::limits_for(robot, 1.0)
        .map_err(|e| IpcError::Config(format!("planner: the robot's tension limits: {e:?}")))?;
    let offset = NetErrorOffset::along(traj, statics, |pose| {
        crate::net::steady_command(&net, &limits, pose)
    });
    if offset.unsolved() > 0 {
        log::warn!(
            "planner: the statics of the net's command did not solve at {} of the path's poses: no net's error offset there",
            offset.unsolved()
        );
    }
    log::info!(
        "planner: the net is up to {:.3} mm off the path; its error is sent as an offset",
        offset.worst_m() * 1e3
    );
    Ok(offset)
}

/// The setpoint the planner sends at `t` (s since its start) for `desired`
/// (`motion.at(t)`), with `learned` (the learning's and the stiffness
/// adaptation's offsets, m along the tangent axes) if any: pose,
/// velocity, tangent, flags and dynamic offset in the model's base frame,
/// the header left empty. The planner process sends it (after any injected
/// fault, in the tracker's frame); `tendril-ros2 drive` runs it in-process.
pub fn setpoint_for(
    motion: &Motion,
    t: f64,
    desired: &crate::plan::Desired,
    learned: Option<[f64; 3]>,
) -> Setpoint {
    let point = &desired.point;
    let mut flags = 0;
    for (on, bit) in [
        (desired.holding, setpoint_flags::HOLD),
        (desired.moving, setpoint_flags::MOVING),
        (desired.has_velocity, setpoint_flags::HAS_VELOCITY),
    ] {
        if on {
            flags |= bit;
        }
    }
    let offsets = [
        motion.dynamic_offset(t, desired),
        motion.net_error_offset(desired),
        motion.turning_offset(desired),
        learned,
    ];
    let mut dynamic_offset = [0.0f32; 3];
    for offset in offsets.iter().flatten() {
        flags |= setpoint_flags::HAS_DYNAMIC_OFFSET;
        for (sum, v) in dynamic_offset.iter_mut().zip(offset) {
            *sum += *v as f32;
        }
    }
    let (tangent, tangent_axes, tangent_dim) = match point.tangent {
        Some(d) => {
            flags |= setpoint_flags::HAS_TANGENT;
            (
                d.columns.map(|column| column.map(|v| v as f32)),
                d.family.axes_padded().map(|axis| axis.map(|v| v as f32)),
                d.family.dim() as u32,
            )
        }
        None => ([[0.0; 7]; 3], [[0.0; 3]; 3], 0),
    };
    Setpoint {
        header: Header::default(),
        pose: point.pose.map(|v| v as f32),
        velocity: point.velocity.map(|v| v as f32),
        tangent,
        tangent_axes,
        tangent_dim,
        flags,
        dynamic_offset,
        reserved: 0,
    }
}

/// The learning `cfg` asks for, designed and checked (`None`: off). A
/// learning the convergence check refuses stays off and says why; the run
/// goes on without it.
fn learner(
    cfg: &PlannerConfig,
    robot: &Robot,
    shaping: Option<crate::plan::StepShaping>,
) -> Result<Option<Learner>, IpcError> {
    match cfg
        .learning
        .resolve(shaping, cfg.shape.period_s(), controller_gains(robot))
    {
        Ok(Some(design)) => {
            log::info!(
                "planner: learning the {:.2} s path's harmonics up to {:.2} Hz (worst contraction {:.2} a pass)",
                design.period_s,
                design.harmonics() as f64 / design.period_s,
                design.contraction
            );
            Ok(Some(Learner::new(design)))
        }
        Ok(None) => Ok(None),
        Err(e) if matches!(cfg.learning, LearningChoice::Designed(_)) => {
            Err(IpcError::Config(e.to_string()))
        }
        Err(e) => {
            log::warn!("planner: learning off: {e}");
            Ok(None)
        }
    }
}

/// The integral correction's gains of a controller at its defaults for
/// `robot`: a launcher that knows the controller's own gains designs the
/// learning with them and passes the design.
fn controller_gains(robot: &Robot) -> crate::plan::IntegralGains {
    crate::ipc::controller::correction::applied(
        robot,
        crate::ipc::controller::correction::KI_PER_S,
        crate::ipc::controller::correction::FILTER_TAU_S,
        crate::ipc::controller::correction::MAP_GAIN_PER_S,
        true,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plan::{LearnedFor, PathShape, TurningOffset};

    /// A table is sent only for the robot file and the circle it was
    /// learned for; anything else is refused with what differs.
    #[test]
    fn a_turning_offset_is_refused_off_its_robot_and_its_circle() {
        let robot = crate::robot::repo_robot("seed-4t.toml");
        let circle = PathShape::default_circle();
        let mut table = TurningOffset::zero([0.0, 0.0], circle.period_s().unwrap(), 2);
        let refused = |t: &TurningOffset, s: &PathShape, r: &Robot| {
            check_turning_offset(t, s, r).unwrap_err().to_string()
        };
        assert!(refused(&table, &circle, &robot).contains("does not say"));
        table.learned_for = Some(LearnedFor {
            robot: robot.fingerprint(),
            shape: circle.clone(),
        });
        check_turning_offset(&table, &circle, &robot).unwrap();
        let other = crate::robot::repo_robot("tdcr-3seg.toml");
        assert!(refused(&table, &circle, &other).contains("another robot"));
        let PathShape::Circle {
            center_m, freq_hz, ..
        } = circle.clone()
        else {
            unreachable!()
        };
        let wider = PathShape::Circle {
            center_m,
            radius_m: 0.02,
            freq_hz,
            height_m: None,
        };
        assert!(refused(&table, &wider, &robot).contains("another path"));
        table.harmonics[1][0][0] = 1.0;
        assert!(refused(&table, &circle, &robot).contains("over"));
    }
}

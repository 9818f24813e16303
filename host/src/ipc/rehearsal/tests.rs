use std::path::{Path, PathBuf};

use super::start;
use super::*;
use crate::ipc::controller::ControllerConfig;
use crate::ipc::planner::{plan, PlannerConfig};
use crate::plan::PathShape;
use crate::plant::{PlantParams, RobotModel};

fn repo(file: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(file)
}

/// The default robot's 1 Hz circle (a fast one: the motors' lag and the
/// integral leave an error that turns with it) on the quasi-static plant,
/// a few harmonics: small enough for a debug build.
struct Case {
    robot: crate::robot::Robot,
    net: Vec<u8>,
    controller: ControllerConfig,
    plant: PlantParams,
    motion: crate::plan::Motion,
}

const SETTLE_S: f64 = 1.0;
const PERIOD_S: f64 = 1.0;

fn case() -> Case {
    case_adapting(false).0
}

/// The case, and the planner's stiffness adaptation when asked for.
fn case_adapting(adapt_stiffness: bool) -> (Case, Option<crate::plan::StiffnessAdaptation>) {
    let robot_path = repo("robots/seed-4t.toml");
    let net_path = repo("firmware/vectors/default.tnet");
    let shape = PathShape::Circle {
        center_m: [0.0, 0.0],
        radius_m: 0.015,
        freq_hz: 1.0 / PERIOD_S,
        height_m: None,
    };
    let planner = PlannerConfig {
        start_from_rest: true,
        dynamic_offset: true,
        net_error_offset: true,
        model: Some(net_path.clone()),
        settle_s: SETTLE_S,
        adapt_stiffness,
        ..PlannerConfig::new(robot_path.clone(), shape)
    };
    let planned = plan(&planner).unwrap();
    let mut controller = ControllerConfig::new(robot_path.clone(), net_path.clone());
    controller.ki_per_s = crate::ipc::sim::DEFAULT_KI_PER_S;
    let case = Case {
        robot: crate::robot::Robot::load(&robot_path).unwrap(),
        net: std::fs::read(net_path).unwrap(),
        controller,
        plant: PlantParams {
            model: RobotModel::QuasiStatic,
            ..PlantParams::default()
        },
        motion: planned.motion,
    };
    (case, planned.stiffness)
}

impl Case {
    fn rehearsed(&self) -> VirtualLoop<'_> {
        VirtualLoop {
            robot: &self.robot,
            net: &self.net,
            controller: &self.controller,
            plant: &self.plant,
            motion: &self.motion,
            period_s: PERIOD_S,
            settle_s: SETTLE_S,
        }
    }
}

fn settings() -> Settings {
    Settings {
        harmonics: 4,
        lifted: 2,
        passes: 2,
        iterations: 3,
        ..Settings::default()
    }
}

#[test]
fn the_identified_map_predicts_an_offsets_error_and_the_learning_lowers_the_pass() {
    let case = case();
    let rehearsed = case.rehearsed();
    let s = settings();
    let zero = TurningOffset::zero([0.0, 0.0], PERIOD_S, s.harmonics);
    let rehearse =
        |o: &TurningOffset| rehearsed.run(o, s.passes, s.harmonics, StartWindow::default());
    let unaided = rehearse(&zero).unwrap();
    let e0 = flatten(&unaided.harmonics[1], s.harmonics);
    let identified = identify(&e0, &s, zero.center_m, PERIOD_S, &rehearse).unwrap();
    assert_eq!(identified.rehearsals, 9 + 3);
    assert_eq!(s.most_rehearsals(), 1 + 9 + 3 + s.iterations);

    // Superposition in the turning frame, the fact the design rests on:
    // an offset the identification never ran (four harmonics on three
    // axes at once, five times its amplitude) moves the error as the map
    // says, to a fifth of the move.
    let mut probe = zero.clone();
    probe.harmonics[0][1] = [6e-5, 0.0];
    probe.harmonics[1][0] = [-4e-5, 7e-5];
    probe.harmonics[1][2] = [5e-5, 2e-5];
    probe.harmonics[3][1] = [3e-5, -6e-5];
    let mut u = nalgebra::DVector::zeros(6 * s.harmonics);
    for (m, axes) in probe.harmonics.iter().enumerate() {
        for (axis, [re, im]) in axes.iter().enumerate() {
            u[index(axis, m, 0)] = *re;
            u[index(axis, m, 1)] = *im;
        }
    }
    let measured = flatten(&rehearse(&probe).unwrap().harmonics[1], s.harmonics) - &e0;
    let predicted = &identified.map * &u;
    let miss = (&measured - &predicted).norm() / measured.norm();
    eprintln!(
        "unaided pass {:.4} mm; the probe moved the error {:.4} mm, the map missed by {:.1} %",
        unaided.rms_m[1] * 1e3,
        measured.norm() * 1e3,
        miss * 1e2
    );
    assert!(
        measured.norm() > 1e-5,
        "the probe moved nothing: {measured}"
    );
    assert!(
        miss < 0.2,
        "the map missed the probe's effect by {:.1} %",
        miss * 1e2
    );

    // The iterations on that map: the measured pass falls to under half.
    let learned = iterate(
        (&e0, unaided.rms_m[1]),
        &identified.map,
        &s,
        &zero,
        &rehearse,
    )
    .unwrap();
    eprintln!(
        "learning: {:.4} → {:?} mm",
        learned.unaided_rms_m * 1e3,
        learned
            .iteration_rms_m
            .iter()
            .map(|v| v * 1e3)
            .collect::<Vec<_>>()
    );
    assert!(learned.stopped.is_none(), "{:?}", learned.stopped);
    assert!(
        learned.learned_rms_m() < 0.5 * learned.unaided_rms_m,
        "{:.4} → {:.4} mm",
        learned.unaided_rms_m * 1e3,
        learned.learned_rms_m() * 1e3
    );
    assert!(learned.offset.largest_m() > 0.0);

    // A deliberately wrong map (the sign turned): the first iteration's
    // error grows, the learning stops and keeps no offset.
    let wrong = iterate(
        (&e0, unaided.rms_m[1]),
        &(-identified.map.clone()),
        &s,
        &zero,
        &rehearse,
    )
    .unwrap();
    let why = wrong.stopped.as_deref().unwrap_or("");
    assert!(why.contains("grew"), "{why:?}: {:?}", wrong.iteration_rms_m);
    assert_eq!(wrong.iteration_rms_m.len(), 1);
    assert_eq!(wrong.offset.largest_m(), 0.0);
    assert_eq!(wrong.learned_rms_m(), wrong.unaided_rms_m);
}

/// The measured pass starts where the ring of the path's start is down to
/// e⁻⁴ of its size, and no later by a whole pass: the closed form
/// e^{−ζω t} of a second-order mode at the pass's start.
#[test]
fn the_measured_pass_starts_after_the_modes_ring_has_decayed() {
    let ring_left = |passes: usize, period_s: f64, hz: f64, zeta: f64| {
        (-zeta * std::f64::consts::TAU * hz * period_s * (passes - 1) as f64).exp()
    };
    for (period_s, hz, zeta) in [(2.5, 1.07, 0.05), (5.0, 1.07, 0.05), (1.0, 3.6, 0.02)] {
        let s = Settings::default().passes_to_settle(period_s, hz, zeta);
        assert!(s.passes >= Settings::default().passes);
        assert!(ring_left(s.passes, period_s, hz, zeta) <= (-4.0f64).exp() + 1e-12);
        if s.passes > Settings::default().passes {
            assert!(ring_left(s.passes - 1, period_s, hz, zeta) > (-4.0f64).exp());
        }
    }
    // The three-segment robot's 0.4 Hz circle: six passes, not three.
    assert_eq!(
        Settings::default().passes_to_settle(2.5, 1.07, 0.05).passes,
        6
    );
    // A mode with no damping to speak of is capped, a bad one changes nothing.
    assert_eq!(
        Settings::default().passes_to_settle(1.0, 1.0, 1e-6).passes,
        MOST_PASSES
    );
    assert_eq!(
        Settings::default()
            .passes_to_settle(1.0, f64::NAN, 0.05)
            .passes,
        Settings::default().passes
    );
}

/// The path's start learned after the periodic offset, on the same
/// rehearsed loop: the window's error falls, and the error the table then
/// expects there is the one a run with it shows (what the stiffness
/// adaptation is told not to read as the robot's).
#[test]
fn the_start_is_learned_and_the_table_expects_the_error_its_run_shows() {
    let case = case();
    let rehearsed = case.rehearsed();
    let start = StartSettings {
        step_s: 0.1,
        bumps: 4,
        window: StartWindow {
            bin_s: 0.05,
            bins: 12,
        },
        iterations: 3,
        ..StartSettings::for_mode(3.6, 0.05, 0.3).unwrap()
    };
    let mut periodic = TurningOffset::zero([0.0, 0.0], PERIOD_S, 2);
    periodic.expected = Some(crate::plan::ExpectedError {
        bin_s: 0.0,
        start: vec![],
        harmonics: vec![],
    });
    let rehearse = |o: &TurningOffset| rehearsed.run(o, 0, 0, start.window);
    let learned = start::learn_start(&periodic, &start, &rehearse).unwrap();
    eprintln!(
        "the start's window: {:.4} → {:?} mm",
        learned.unaided_rms_m * 1e3,
        learned
            .iteration_rms_m
            .iter()
            .map(|v| v * 1e3)
            .collect::<Vec<_>>()
    );
    assert_eq!(learned.rehearsals, 1 + 12 + learned.iteration_rms_m.len());
    assert!(
        learned.learned_rms_m() < 0.7 * learned.unaided_rms_m,
        "{:.4} → {:.4} mm",
        learned.unaided_rms_m * 1e3,
        learned.learned_rms_m() * 1e3
    );
    let table = &learned.offset;
    assert!(table.start.as_ref().is_some_and(|s| s.bumps.len() == 4));
    let again = rehearse(table).unwrap();
    let expected = table.expected.as_ref().unwrap();
    assert_eq!(expected.start, again.start);
    assert_eq!(expected.bin_s, 0.05);
}

/// A robot that does what the model's loop did is not read as stiffer or
/// softer than its file: frames that are the path less the table's
/// expected error (here 0.8 mm inwards all along the circle) leave κ̂ at
/// 0; the same frames read against the path alone do not.
#[test]
fn the_error_the_model_expects_is_not_read_as_stiffness() {
    let (case, adaptation) = case_adapting(true);
    let mut table = TurningOffset::zero([0.0, 0.0], PERIOD_S, 1);
    table.expected = Some(crate::plan::ExpectedError {
        bin_s: 0.05,
        start: vec![],
        harmonics: vec![[[8e-4, 0.0], [0.0; 2], [0.0; 2]]],
    });
    let kappa = |expected_known: bool| {
        let motion = case.motion.clone().with_turning_offset(table.clone());
        let mut adaptation = adaptation.clone().unwrap();
        for k in 0..((SETTLE_S + 4.0 * PERIOD_S) * 1e3) as usize {
            let t = k as f64 * 1e-3;
            let now = motion.at(t);
            let p = now.point.pose;
            let e = motion.expected_error(t, &now);
            let tip = [p[0] - e[0], p[1] - e[1], p[2] - e[2]];
            let told = if expected_known {
                &motion
            } else {
                &case.motion
            };
            adaptation.frame(told, t, tip);
            adaptation.step(motion.trajectory(), t, &now, true);
        }
        adaptation.applied()
    };
    let (known, unknown) = (kappa(true), kappa(false));
    eprintln!("κ̂ with the expected error known {known:.4}, unknown {unknown:.4}");
    assert_eq!(known, 0.0);
    assert!(unknown.abs() > 0.04, "{unknown}");
}

use std::path::{Path, PathBuf};

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
        ..PlannerConfig::new(robot_path.clone(), shape)
    };
    let planned = plan(&planner).unwrap();
    let mut controller = ControllerConfig::new(robot_path.clone(), net_path.clone());
    controller.ki_per_s = crate::ipc::sim::DEFAULT_KI_PER_S;
    Case {
        robot: crate::robot::Robot::load(&robot_path).unwrap(),
        net: std::fs::read(net_path).unwrap(),
        controller,
        plant: PlantParams {
            model: RobotModel::QuasiStatic,
            ..PlantParams::default()
        },
        motion: planned.motion,
    }
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
    let rehearse = |o: &TurningOffset| rehearsed.run(o, s.passes, s.harmonics);
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

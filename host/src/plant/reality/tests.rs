use std::path::Path;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::*;
use crate::robot::first_bending_mode_rad_s;

fn default_robot() -> Robot {
    Robot::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../robots/seed-4t.toml")).unwrap()
}

#[test]
fn every_builtin_parses_and_applies_to_both_robots() {
    let two = Robot::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../robots/tdcr-2seg.toml"))
        .unwrap();
    for (name, text) in BUILTIN {
        let r = Reality::from_toml(text, Path::new(name)).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(&r.name, name, "a built-in's name is its file stem");
        for robot in [default_robot(), two.clone()] {
            r.real_robot(&robot)
                .unwrap_or_else(|e| panic!("{name}: {e}"));
        }
        assert!(Reality::builtin(name).is_some());
        // A built-in's name finds it when no such file exists.
        assert_eq!(Reality::load(Path::new(name)).unwrap(), r);
    }
}

#[test]
fn errors_name_the_file_the_field_and_the_problem() {
    let bad = |text: &str, field: &str, problem: &str| {
        let e = Reality::from_toml(text, Path::new("bad.toml")).unwrap_err();
        assert_eq!(e.file, Path::new("bad.toml"));
        assert_eq!(e.field, field, "{e}");
        assert!(e.problem.contains(problem), "{e}");
    };
    bad(
        "name = \"x\"\n[tracker]\nrate_hz = 0.0\n",
        "tracker.rate_hz",
        "must be in [1, 10000] Hz",
    );
    bad(
        "name = \"x\"\n[tracker]\nrate_hz = 40.0\ndropout = 1.5\n",
        "tracker.dropout",
        "1.5",
    );
    bad(
        "name = \"x\"\n[robot]\nyoungs_modulus_scale = -1.0\n",
        "robot.youngs_modulus_scale",
        "factor",
    );
    bad("name = \"x\"\n[friction]\nmu = nan\n", "friction.mu", "NaN");
    bad(
        "name = \"x\"\n[robot]\nstiffness = 2.0\n",
        "robot.stiffness",
        "unknown field `stiffness`",
    );
    bad("name = \"\"\n", "name", "empty");
    // The name is a directory of `robustness --out`: never a path out of it.
    bad("name = \"../escaped\"\n", "name", "'/'");
    bad("name = \"/tmp/abs\"\n", "name", "'/'");
    bad("name = \"..\"\n", "name", "starts with '.'");
    bad(
        "name = \"x\"\n[robot]\ntendon_angle_delta_deg = [1.0, 40.0]\n",
        "robot.tendon_angle_delta_deg[1]",
        "±30",
    );
    bad(
        "name = \"x\"\n[dynamics]\nmodel = \"wobbly\"\n",
        "dynamics.model",
        "unknown variant",
    );
    let e = Reality::load(Path::new("no/such/reality.toml")).unwrap_err();
    assert!(e.problem.contains("em-tracker"), "names the built-ins: {e}");
}

#[test]
fn robot_changes_scale_and_shift_what_they_say() {
    let nominal = default_robot();
    let r = Reality::from_toml(
        "name = \"x\"\n[robot]\nyoungs_modulus_scale = 1.1\nlength_scale = 0.5\n\
         tendon_offset_delta_mm = [0.5, -0.5, 0.0, 0.1]\ntendon_angle_delta_deg = [3.0, 0.0, 0.0, 0.0]\n",
        Path::new("x"),
    )
    .unwrap();
    let real = r.real_robot(&nominal).unwrap();
    assert_eq!(real.youngs_modulus, nominal.youngs_modulus * 1.1);
    assert_eq!(real.shear_modulus, nominal.shear_modulus);
    assert_eq!(real.length, nominal.length * 0.5);
    assert_eq!(real.tendons[0].end, nominal.tendons[0].end * 0.5);
    assert!((real.tendons[1].offset - (nominal.tendons[1].offset - 0.5e-3)).abs() < 1e-15);
    assert!((real.tendons[0].angle - (nominal.tendons[0].angle + 3f64.to_radians())).abs() < 1e-15);
    // A list that does not match the robot is refused, naming both counts.
    let short = Reality::from_toml(
        "name = \"x\"\n[robot]\ntendon_offset_delta_mm = [0.5]\n",
        Path::new("x"),
    )
    .unwrap();
    let e = short.real_robot(&nominal).unwrap_err();
    assert!(e.contains("1 entries") && e.contains("4 tendons"), "{e}");
    // Drawn errors stay within their bounds and differ between tendons.
    let g = Reality::builtin("geometry")
        .unwrap()
        .real_robot(&nominal)
        .unwrap();
    let mut deltas = Vec::new();
    for (a, b) in g.tendons.iter().zip(&nominal.tendons) {
        assert!((a.offset - b.offset).abs() <= 0.5e-3 + 1e-15);
        assert!((a.angle - b.angle).abs() <= 3f64.to_radians() + 1e-15);
        deltas.push(a.offset - b.offset);
    }
    assert!(deltas.windows(2).any(|w| w[0] != w[1]));
}

#[test]
fn first_bending_mode_of_the_default_robot_is_3_6_hz() {
    // The dynamic rod's own ring-down measures 3.6 Hz (docs/design.md §4.2).
    let f = first_bending_mode_rad_s(&default_robot()) / std::f64::consts::TAU;
    assert!((f - 3.6).abs() < 0.05, "{f} Hz");
}

/// Run a tracker for `secs` at a 1 kHz plant on a still tip; returns the
/// delivered frames (at the step they were delivered).
fn run_tracker(spec: TrackerSpec, secs: f64) -> (Tracker, Vec<(u64, Frame)>) {
    let mut t = Tracker::new(spec);
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let truth = [0.01, -0.02, 0.39, 1.0, 0.0, 0.0, 0.0];
    let mut out = Vec::new();
    for k in 0..(secs * 1000.0) as u64 {
        let now = 1_000_000_000 + k * 1_000_000;
        if t.step(now, &truth, &mut rng) {
            out.push((now, *t.latest().unwrap()));
        }
    }
    (t, out)
}

#[test]
fn tracker_has_its_rate_delay_jitter_and_dropouts() {
    let spec = TrackerSpec {
        rate_hz: 40.0,
        latency_ms: 20.0,
        latency_jitter_ms: 0.0,
        position_jitter_mm: 0.14,
        orientation_jitter_deg: 0.1,
        dropout: 0.05,
    };
    let (t, frames) = run_tracker(spec, 60.0);
    // Rate: 40 frames a second are taken.
    assert!((t.taken as f64 - 2400.0).abs() <= 1.0, "taken {}", t.taken);
    // Dropouts: 5 % ± 3σ of a binomial over 2400 frames.
    let lost = t.lost as f64 / t.taken as f64;
    assert!(
        (lost - 0.05).abs() < 3.0 * (0.05f64 * 0.95 / 2400.0).sqrt(),
        "lost {lost}"
    );
    // Delay: each frame arrives 20 ms after it was taken (on a 1 ms plant grid).
    for (now, f) in &frames {
        assert_eq!(now - f.stamp_ns, 20_000_000);
    }
    // Frame numbers count every frame taken: gaps are the lost ones.
    let gaps: u64 = frames
        .windows(2)
        .map(|w| u64::from(w[1].1.seq - w[0].1.seq - 1))
        .sum();
    assert_eq!(
        gaps + frames.len() as u64,
        u64::from(frames.last().unwrap().1.seq) - u64::from(frames[0].1.seq) + 1
    );
    // Jitter: the per-axis standard deviation is 0.14 mm (±5 % at ~2300 frames).
    for axis in 0..3 {
        let xs: Vec<f64> = frames.iter().map(|(_, f)| f.pose[axis]).collect();
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        let sd = (xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / xs.len() as f64).sqrt();
        assert!(
            (sd - 0.14e-3).abs() < 0.07 * 0.14e-3,
            "axis {axis}: sd {sd}"
        );
    }
    // Orientation jitter: the angle about x is 2 qx to first order, sd 0.1°.
    let ax: Vec<f64> = frames.iter().map(|(_, f)| 2.0 * f.pose[4]).collect();
    let sd = (ax.iter().map(|a| a * a).sum::<f64>() / ax.len() as f64).sqrt();
    assert!((sd.to_degrees() - 0.1).abs() < 0.01, "{}", sd.to_degrees());
}

#[test]
fn jittered_latency_keeps_frames_in_order() {
    let spec = TrackerSpec {
        rate_hz: 200.0,
        latency_ms: 10.0,
        latency_jitter_ms: 5.0,
        ..TrackerSpec::IDEAL
    };
    let (_, frames) = run_tracker(spec, 5.0);
    assert!(frames.windows(2).all(|w| w[1].1.seq > w[0].1.seq));
    let mean_delay = frames
        .iter()
        .map(|(now, f)| (now - f.stamp_ns) as f64 * 1e-6)
        .sum::<f64>()
        / frames.len() as f64;
    // Mean ≥ the nominal 10 ms (order is kept by holding early frames back).
    assert!((10.0..14.0).contains(&mean_delay), "{mean_delay} ms");
}

/// The calibration benchmark's "real" robot file, made from seed-4t.toml by
/// the text edits of scripts/calibration-benchmark and scripts/calibration-loop
/// (E 227.7e9, ρ 45214.55, offsets 19.5, 18.5, 19.4, 18.7 mm), with the
/// `[base]` of its measured rows' tracker (1.5, −1, 0.8 mm).
fn calibration_real_robot() -> Robot {
    let text = crate::robot::BUILTIN_DEFAULT_TOML;
    let real = text
        .replace("youngs_modulus = 207e9", "youngs_modulus = 227.7e9")
        .replace("density = 39317.0 ", "density = 45214.55 ");
    let mut parts = real.split("offset = 0.019\n");
    let mut out = parts.next().unwrap().to_string();
    for (o, p) in ["0.0195", "0.0185", "0.0194", "0.0187"].iter().zip(parts) {
        out.push_str(&format!("offset = {o}\n{p}"));
    }
    // The edits must all have applied: a changed seed-4t.toml would make
    // the scripts' real robot silently the nominal one.
    assert!(out.contains("227.7e9") && out.contains("45214.55") && !out.contains("= 0.019\n"));
    out.push_str("\n[base]\ntranslation = [0.0015, -0.001, 0.0008]\n");
    Robot::from_toml(&out, Path::new("real.toml")).unwrap()
}

#[test]
fn calibration_truth_is_the_calibration_benchmarks_real_robot() {
    use crate::ipc::plant::{PlantModel, PlantParams};
    use crate::statics::{SolverSettings, Statics};
    // The reality file (a file, not a built-in: the robustness table runs
    // every built-in) applied to the nominal robot by the plant itself.
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../robots/realities/calibration-truth.toml");
    let reality = Reality::load(&path).unwrap_or_else(|e| panic!("{e}"));
    let nominal = default_robot();
    let params = PlantParams {
        noise_m: 0.0,
        noise_quat: 0.0,
        reality: Some(reality),
        ..PlantParams::default()
    };
    let steps = params.statics_steps;
    let mut plant = PlantModel::new(&nominal, params).unwrap();
    let file = Statics::new(
        &calibration_real_robot(),
        SolverSettings {
            steps,
            ..SolverSettings::default()
        },
    );
    let nominal_statics = Statics::new(&nominal, SolverSettings::default());
    let tensions = crate::dataset::Sampler::Adjacent.draw(8, &nominal.max_tensions(), 3);
    for tau in tensions {
        plant.command(&tau);
        // Past the motors' lag: five time constants a step.
        for _ in 0..10 {
            assert!(plant.step(0.1));
        }
        let p = nalgebra::Vector3::from_row_slice(&plant.pose()[..3]);
        // The plant reports in the tracker's frame: the file's `[base]`.
        let at = file.solve(plant.tensions(), None).unwrap().position;
        let want = nalgebra::Vector3::from(file.robot().base.to_tracker().point(at.into()));
        // Same robot up to the last bits of E, ρ and the offsets; the rest
        // is the solver's convergence (warm in the plant, cold here).
        assert!(
            (p - want).norm() < 1e-8,
            "{tau:?}: {} m off",
            (p - want).norm()
        );
        // In its own base frame (`/tf`'s base_link → tip): the statics' tip.
        let in_base = nalgebra::Vector3::from_row_slice(&plant.pose_in_base()[..3]);
        assert!(
            (in_base - at).norm() < 1e-8,
            "{tau:?}: in base {in_base:?}, statics {at:?}"
        );
        // And it is not the nominal robot (so the check can tell them apart).
        let off = (nominal_statics
            .solve(plant.tensions(), None)
            .unwrap()
            .position
            - p)
            .norm();
        assert!(off > 1e-3, "{tau:?}: only {off} m from the nominal robot");
    }
}

//! `tendril calibrate` end to end on a tiny case (docs/design.md §11):
//! synthetic measurements of a heavier robot seen from an offset tracker,
//! the fit, the robot file other commands take, the planner, a bad input.

use std::path::Path;

use tendril_tests::{tendril, workspace_root as root};

fn ok(out: &std::process::Output) {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn calibrate_recovers_a_heavier_robot_and_writes_a_robot_file_fk_takes() {
    let dir = tempfile::tempdir().unwrap();
    let d = |f: &str| dir.path().join(f).to_str().unwrap().to_string();
    let nominal = root().join("robots/seed-4t.toml");
    let text = std::fs::read_to_string(&nominal).unwrap();
    // The "real" robot: 15 % heavier.
    let real = text.replace("density = 39317.0", "density = 45214.55");
    assert_ne!(real, text);
    std::fs::write(d("real.toml"), real).unwrap();
    ok(&tendril(&[
        "generate",
        "--robot",
        &d("real.toml"),
        "--samples",
        "60",
        "--noise-mm",
        "0.05",
        "--frame-offset-mm",
        "2,0,-1",
        "--out",
        &d("measured.csv"),
        "--quiet",
    ]));
    ok(&tendril(&[
        "calibrate",
        "--robot",
        nominal.to_str().unwrap(),
        "--data",
        &d("measured.csv"),
        "--fit",
        "density,base_t",
        "--positions-only",
        "--out",
        &d("cal.toml"),
    ]));
    for f in ["cal.toml", "cal.report.json", "cal.report.md", "cal.png"] {
        assert!(Path::new(&d(f)).exists(), "{f} missing");
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d("cal.report.json")).unwrap()).unwrap();
    let density = report["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["name"] == "density")
        .unwrap();
    let fitted = density["fitted"].as_f64().unwrap();
    let hw = density["half_width_95"].as_f64().unwrap();
    assert!((fitted - 45214.55).abs() < 2.0 * hw, "{density}");
    let before = report["held_out_before"]["rms_m"].as_f64().unwrap();
    let after = report["held_out_after"]["rms_m"].as_f64().unwrap();
    // Jitter 0.05 mm per axis is 0.087 mm as a 3-D norm.
    assert!(
        before > 1e-3 && after < 1.5 * 0.087e-3,
        "{before} -> {after}"
    );
    // The calibrated file is a robot file every command takes.
    ok(&tendril(&[
        "fk",
        "--robot",
        &d("cal.toml"),
        "--tensions",
        "2,0,0,0",
        "--json",
    ]));
    // The planner proposes tension sets within the limits.
    ok(&tendril(&[
        "calibrate",
        "--plan",
        "5",
        "--robot",
        nominal.to_str().unwrap(),
        "--fit",
        "density,offsets",
        "--out",
        &d("plan.csv"),
    ]));
    let plan = std::fs::read_to_string(d("plan.csv")).unwrap();
    assert_eq!(plan.lines().count(), 6, "{plan}");
    assert!(plan.starts_with("t0,t1,t2,t3\n"));
}

#[test]
fn calibrate_names_a_missing_column() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("m.csv");
    std::fs::write(&csv, "t0,t1,t2,t3,px,py\n1,0,0,0,0,0\n").unwrap();
    let out = tendril(&[
        "calibrate",
        "--data",
        csv.to_str().unwrap(),
        "--out",
        dir.path().join("c.toml").to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("m.csv") && err.contains("missing column pz"),
        "{err}"
    );
    assert!(!dir.path().join("c.toml").exists());
}

/// `rows` synthetic measurements of `robot` (default the seed robot) in
/// `dir/name`, with `extra` generate flags.
fn measured(dir: &Path, name: &str, rows: usize, extra: &[&str]) -> String {
    let path = dir.join(name).to_str().unwrap().to_string();
    let mut args = vec![
        "generate",
        "--quiet",
        "--robot",
        "robots/seed-4t.toml",
        "--out",
        &path,
    ];
    let rows = rows.to_string();
    args.extend(["--samples", rows.as_str()]);
    args.extend(extra);
    ok(&tendril(&args));
    path
}

fn calibrate_to(data: &str, out: &Path, extra: &[&str]) -> std::process::Output {
    let mut args = vec!["calibrate", "--data", data, "--out", out.to_str().unwrap()];
    args.extend(extra);
    tendril(&args)
}

fn report(out: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(out.with_extension("report.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

fn fitted(report: &serde_json::Value, name: &str) -> f64 {
    let p = (report["parameters"].as_array().unwrap().iter())
        .find(|p| p["name"] == name)
        .unwrap_or_else(|| panic!("no {name} in {report}"));
    p["fitted"].as_f64().unwrap()
}

#[test]
fn a_tracker_far_from_the_base_is_fitted_as_a_frame_not_as_a_bent_rod() {
    let dir = tempfile::tempdir().unwrap();
    let data = measured(
        dir.path(),
        "far.csv",
        100,
        &["--noise-mm", "0.05", "--frame-offset-mm", "200,-100,50"],
    );
    let out = dir.path().join("cal.toml");
    let o = calibrate_to(
        &data,
        &out,
        &["--fit", "density,length,base_t", "--positions-only"],
    );
    ok(&o);
    let r = report(&out);
    for (name, truth) in [("base_tx", 0.2), ("base_ty", -0.1), ("base_tz", 0.05)] {
        let x = fitted(&r, name);
        assert!((x - truth).abs() < 1e-3, "{name} {x} (truth {truth})");
    }
    assert!((fitted(&r, "length") - 0.4).abs() < 1e-3, "{r}");
    assert_eq!(r["verdict"]["calibrated"], true, "{}", r["verdict"]);
    assert!(r["held_out_after"]["rms_m"].as_f64().unwrap() < 0.3e-3);
}

#[test]
fn rows_no_fit_can_use_are_refused_and_nothing_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let data = measured(dir.path(), "m.csv", 40, &["--noise-mm", "0.1"]);
    let text = std::fs::read_to_string(&data).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (px, t0) = (col("px"), col("t0"));
    let rewrite = |f: &dyn Fn(usize, &str) -> String| {
        let mut out = header.join(",") + "\n";
        for l in text.lines().skip(1) {
            let cells: Vec<String> = l.split(',').enumerate().map(|(k, c)| f(k, c)).collect();
            out += &(cells.join(",") + "\n");
        }
        out
    };
    // Positions in millimetres.
    let mm = rewrite(&|k, c| {
        if (px..px + 3).contains(&k) {
            (c.parse::<f64>().unwrap() * 1e3).to_string()
        } else {
            c.to_string()
        }
    });
    // Every row at zero tension.
    let zero = rewrite(&|k, c| {
        if (t0..t0 + 4).contains(&k) {
            "0".into()
        } else {
            c.into()
        }
    });
    std::fs::write(dir.path().join("old.toml"), "mine").unwrap();
    for (name, rows, needle) in [
        ("mm.csv", mm, "metres"),
        ("zero.csv", zero, "same tensions"),
    ] {
        let path = dir.path().join(name);
        std::fs::write(&path, rows).unwrap();
        let o = calibrate_to(path.to_str().unwrap(), &dir.path().join("old.toml"), &[]);
        assert_eq!(o.status.code(), Some(1), "{name}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(needle), "{name}: {err}");
        assert_eq!(
            std::fs::read_to_string(dir.path().join("old.toml")).unwrap(),
            "mine"
        );
        assert!(!dir.path().join("old.report.json").exists());
    }
}

#[test]
fn a_fit_to_mostly_outliers_is_reported_as_no_calibration_and_writes_no_robot_file() {
    let dir = tempfile::tempdir().unwrap();
    let data = measured(
        dir.path(),
        "o.csv",
        60,
        &["--noise-mm", "0.1", "--outlier-fraction", "0.9"],
    );
    let out = dir.path().join("cal.toml");
    std::fs::write(&out, "previous").unwrap();
    let o = calibrate_to(
        &data,
        &out,
        &["--fit", "density,base_t", "--positions-only"],
    );
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("not a calibration"), "{err}");
    assert_eq!(std::fs::read_to_string(&out).unwrap(), "previous");
    let r = report(&out);
    assert_eq!(r["verdict"]["calibrated"], false);
    let md = std::fs::read_to_string(out.with_extension("report.md")).unwrap();
    assert!(md.contains("Not a calibration"), "{md}");
}

#[test]
fn g_is_fixed_as_unseen_without_torsion_and_no_held_out_rows_show_no_figures() {
    let dir = tempfile::tempdir().unwrap();
    let data = measured(dir.path(), "m.csv", 40, &["--noise-mm", "0.05"]);
    let out = dir.path().join("cal.toml");
    let o = calibrate_to(
        &data,
        &out,
        &["--fit", "G,base_t", "--positions-only", "--holdout", "0"],
    );
    ok(&o);
    let r = report(&out);
    let g = (r["parameters"].as_array().unwrap().iter())
        .find(|p| p["name"] == "G")
        .unwrap();
    assert_eq!(g["fixed"], true, "{g}");
    let why = &r["unidentifiable"][0]["separate_with"];
    assert!(why.as_str().unwrap().contains("torsion"), "{why}");
    assert_eq!(r["rows_held_out"], 0);
    let md = std::fs::read_to_string(out.with_extension("report.md")).unwrap();
    assert!(md.contains("| held out (0) | calibrated | — |"), "{md}");
    assert!(!String::from_utf8_lossy(&o.stderr).contains("held-out tip error"));
}

#[test]
fn a_plan_too_large_to_measure_and_a_plan_beside_data_are_refused_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let plan = dir.path().join("p.csv");
    let started = std::time::Instant::now();
    let o = tendril(&[
        "calibrate",
        "--plan",
        "99999999999",
        "--out",
        plan.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("at most 5000 rows"));
    assert!(started.elapsed() < std::time::Duration::from_secs(10));
    let o = tendril(&[
        "calibrate",
        "--plan",
        "5",
        "--data",
        "x.csv",
        "--out",
        plan.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2), "--plan with --data");
    let data = measured(dir.path(), "m.csv", 20, &[]);
    let o = calibrate_to(&data, Path::new("-"), &[]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--out -"));
    assert!(!plan.exists());
}

/// A plan with a hung mass (issue 45, item 2): the CSV carries the known
/// tip force (the mass's weight along the robot file's gravity) on some of
/// its rows, zero on the others; a robot file without gravity cannot say
/// where a hung mass pulls, and a bad load is refused, naming the flag.
#[test]
fn a_plan_with_a_hung_mass_writes_its_tip_force_on_some_rows() {
    let dir = tempfile::tempdir().unwrap();
    let plan = dir.path().join("p.csv");
    let seed = root().join("robots/seed-4t.toml");
    ok(&tendril(&[
        "calibrate",
        "--plan",
        "12",
        "--plan-tip-mass-g",
        "50",
        "--robot",
        seed.to_str().unwrap(),
        "--fit",
        "E,density,offsets",
        "--out",
        plan.to_str().unwrap(),
    ]));
    let text = std::fs::read_to_string(&plan).unwrap();
    assert!(text.starts_with("t0,t1,t2,t3,fx,fy,fz\n"), "{text}");
    // seed-4t's gravity is 9.81 m/s² along +x of its base: 50 g weighs 0.4905 N.
    let forces: Vec<Vec<f64>> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').skip(4).map(|x| x.parse().unwrap()).collect())
        .collect();
    assert_eq!(forces.len(), 12);
    let loaded = forces
        .iter()
        .filter(|f| (f[0] - 0.4905).abs() < 1e-9 && f[1] == 0.0 && f[2] == 0.0)
        .count();
    let unloaded = forces
        .iter()
        .filter(|f| f.iter().all(|&x| x == 0.0))
        .count();
    assert!(loaded > 0 && loaded + unloaded == 12, "{text}");
    let two_seg = root().join("robots/tdcr-2seg.toml");
    let o = tendril(&[
        "calibrate",
        "--plan",
        "5",
        "--plan-tip-mass-g",
        "50",
        "--robot",
        two_seg.to_str().unwrap(),
        "--out",
        dir.path().join("q.csv").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--plan-tip-load"));
    let o = tendril(&[
        "calibrate",
        "--plan",
        "5",
        "--plan-tip-load",
        "0,0",
        "--out",
        dir.path().join("q.csv").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--plan-tip-load \"0,0\""));
    // A mass the rod cannot hold is refused before any candidate is solved;
    // a load without a plan is refused (a fit reads fx,fy,fz instead).
    let o = tendril(&[
        "calibrate",
        "--plan",
        "5",
        "--plan-tip-mass-g",
        "1e9",
        "--out",
        dir.path().join("q.csv").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("more than the robot holds"));
    let o = tendril(&[
        "calibrate",
        "--plan-tip-mass-g",
        "50",
        "--data",
        seed.to_str().unwrap(),
        "--out",
        dir.path().join("q.toml").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("they need --plan N"));
    assert!(!dir.path().join("q.csv").exists() && !dir.path().join("q.toml").exists());
}

/// `calibrate --step` (issue 45, item 3) on traces of tendril's own dynamic
/// plant: the default robot with the dynamic rod at ζ₁ = 5 %
/// (`dynamic-light-damping`), one tendon stepped to a tenth of its range
/// through the motors, seen by each built-in reality's tracker (its rate,
/// latency and jitter, frames lost). The independent fact is the mode the
/// dynamic model's identification gives at the step's tensions
/// (`dynamics::modes`, checked against Euler–Bernoulli and the plant's own
/// ringing): the fitted 95 % intervals of f₁ and ζ₁ must cover it, ζ₁ to a
/// few per cent, and the retardation time must be t_r = 2ζ/ω. Each trace is
/// fitted twice: as a CSV of the delivered frames, and as the run log
/// (`.mcap`) a sim writes of the same plant steps.
#[test]
fn a_step_trace_through_each_trackers_gives_the_rods_first_mode_with_intervals() {
    use tendril::dynamics::modes::{identify, ModeSearch};
    use tendril::plant::reality::Reality;
    use tendril::plant::{PlantModel, PlantParams};
    let robot = tendril::robot::repo_robot("seed-4t.toml");
    let rod = Reality::builtin("dynamic-light-damping").unwrap();
    let i = *tendril::robot::groups::anchor_groups(&robot)[0]
        .first()
        .unwrap();
    let mut command = vec![0.0; robot.n_tendons()];
    command[i] = 0.1 * robot.max_tensions()[i];
    let real = rod.real_robot(&robot).unwrap();
    let truth = identify(&real, rod.damping(&real), &command, &ModeSearch::default()).unwrap()[0];
    let dir = tempfile::tempdir().unwrap();
    for name in ["em-tracker", "optical-tracker", "everything"] {
        let mut reality = rod.clone();
        reality.tracker = Reality::builtin(name).unwrap().tracker;
        assert!(reality.tracker.is_some(), "{name} has a tracker");
        let mut plant = PlantModel::new(
            &robot,
            PlantParams {
                reality: Some(reality),
                ..PlantParams::default()
            },
        )
        .unwrap();
        // 4 s after the step: the frames as the tracker delivers them, and
        // every plant step in a run log as a sim writes it (its /tracking
        // repeats the newest frame at each 1 ms step).
        let mcap = dir.path().join(format!("{name}.mcap"));
        let log = tendril::runlog::RunLog::start(&tendril::runlog::RunLogConfig {
            mcap: Some(mcap.clone()),
            lossless: true,
            ..Default::default()
        })
        .unwrap();
        let mut csv = String::from("t_s,x_m,y_m,z_m\n");
        let mut last_seq = 0;
        for k in 1..=4000u64 {
            plant.command(&command);
            assert!(plant.step(1e-3));
            plant.sense(k * 1_000_000);
            let frame = plant.frame();
            log.step(tendril::runlog::StepRecord {
                t_ns: k * 1_000_000,
                command_seq: 1,
                controller_status: 0,
                plant_status: 0,
                commanded: command.clone(),
                measured: command.clone(),
                tip: plant.pose(),
                frame: frame.map(|f| f.pose),
                desired: None,
            });
            if let Some(f) = frame.filter(|f| f.seq != last_seq) {
                last_seq = f.seq;
                csv += &format!(
                    "{},{},{},{}\n",
                    f.stamp_ns as f64 * 1e-9,
                    f.pose[0],
                    f.pose[1],
                    f.pose[2]
                );
            }
        }
        log.finish().unwrap();
        let trace = dir.path().join(format!("{name}.csv"));
        std::fs::write(&trace, csv).unwrap();
        for trace in [trace, mcap] {
            let name = trace.file_name().unwrap().to_str().unwrap();
            let out = tendril(&["calibrate", "--step", trace.to_str().unwrap(), "--out", "-"]);
            ok(&out);
            let r: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
            let fit = &r["fit"];
            let value = |key: &str| {
                let e = &fit[key];
                (
                    e["value"].as_f64().unwrap(),
                    [
                        e["interval_95"][0].as_f64().unwrap(),
                        e["interval_95"][1].as_f64().unwrap(),
                    ],
                )
            };
            let (f, f_ci) = value("freq_hz");
            let (zeta, zeta_ci) = value("damping_ratio");
            let (tr, _) = value("retardation_s");
            eprintln!(
                "{name}: f1 {f:.4} Hz {f_ci:?}, ζ {zeta:.4} {zeta_ci:?} (model: {:.4} Hz, ζ {:.4})",
                truth.freq_hz, truth.damping_ratio
            );
            assert!(
                f_ci[0] <= truth.freq_hz && truth.freq_hz <= f_ci[1],
                "{name}: f1 {f_ci:?} misses {}",
                truth.freq_hz
            );
            assert!(
                zeta_ci[0] <= truth.damping_ratio && truth.damping_ratio <= zeta_ci[1],
                "{name}: ζ {zeta_ci:?} misses {}",
                truth.damping_ratio
            );
            assert!(
                zeta_ci[1] - zeta_ci[0] < 0.2 * truth.damping_ratio,
                "{name}: ζ {zeta_ci:?}"
            );
            let wn = std::f64::consts::TAU * f;
            assert!((tr - 2.0 * zeta / wn).abs() < 1e-9, "{name}: t_r {tr}");
        }
    }
}

/// `tendril modes --along` (issue 43, item 1): the modes at evenly spaced
/// rows of a run's tensions. The independent facts: each row's modes are
/// the ones `--at` gives at that row's tensions (the same identification,
/// a different way in), and a file without the robot's tension columns is
/// refused naming the columns it needs.
#[test]
fn modes_along_a_plant_log_are_the_modes_at_its_rows() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("plant-0.csv");
    std::fs::write(
        &log,
        "t_ns,tau0,tau1,tau2,tau3,px\n0,0,0,0,0,0.03\n1,0.5,0,0,0,0.03\n2,1.5,0,0.2,0,0.04\n",
    )
    .unwrap();
    let log_s = log.to_str().unwrap();
    let json = |args: &[&str]| -> serde_json::Value {
        let o = tendril(args);
        ok(&o);
        serde_json::from_slice(&o.stdout).unwrap()
    };
    let along = json(&[
        "modes",
        "--robot",
        "robots/seed-4t.toml",
        "--along",
        log_s,
        "--rows",
        "2",
        "--json",
    ]);
    let rows = along["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 2, "{along}");
    assert_eq!(rows[0]["pose"], "line 2");
    assert_eq!(rows[1]["pose"], "line 4");
    let at = json(&[
        "modes",
        "--robot",
        "robots/seed-4t.toml",
        "--at",
        "1.5,0,0.2,0",
        "--json",
    ]);
    assert_eq!(
        rows[1]["modes"], at["rows"][0]["modes"],
        "{along} against {at}"
    );
    let f1 = rows[0]["modes"][0]["freq_hz"].as_f64().unwrap();
    assert!(
        (3.4..3.8).contains(&f1),
        "the seed robot's first mode at rest: {f1} Hz"
    );

    let bad = dir.path().join("bad.csv");
    std::fs::write(&bad, "t0,t1\n1,0\n").unwrap();
    let o = tendril(&[
        "modes",
        "--robot",
        "robots/seed-4t.toml",
        "--along",
        bad.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("tau0..tau3") && e.contains("bad.csv"), "{e}");
    // A row above the robot's maxima is refused as --at refuses it, naming
    // its line.
    let high = dir.path().join("high.csv");
    std::fs::write(&high, "tau0,tau1,tau2,tau3\n0,0,0,0\n50,0,0,0\n").unwrap();
    let o = tendril(&[
        "modes",
        "--robot",
        "robots/seed-4t.toml",
        "--along",
        high.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("high.csv, line 3"), "{e}");
}

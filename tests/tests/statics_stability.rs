//! `tendril fk` under tip loads: the equilibrium a rod loaded from rest
//! reaches, and refusal of unstable or non-unique ones (issue 31). Checked
//! against closed forms: Euler's clamped–free column P_cr = π² E I / (4 L²),
//! the elastica's buckled branch, and that a dead lateral force can never
//! turn the tip past a right angle.

use std::path::Path;

use tendril_tests::tendril;

/// tdcr-2seg's backbone (no gravity): E = 54 GPa, r = 0.7 mm, L = 0.4 m.
fn tdcr_ei() -> f64 {
    54e9 * std::f64::consts::PI * 0.0007_f64.powi(4) / 4.0
}

const TDCR_L: f64 = 0.4;

/// Euler's critical load of the clamped–free column, N.
fn euler_load() -> f64 {
    std::f64::consts::PI.powi(2) * tdcr_ei() / (4.0 * TDCR_L * TDCR_L)
}

fn json(out: &std::process::Output) -> serde_json::Value {
    assert!(
        out.status.success(),
        "fk failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("fk --json prints JSON")
}

fn position(v: &serde_json::Value) -> [f64; 3] {
    let p = v["position"].as_array().unwrap();
    [0, 1, 2].map(|k| p[k].as_f64().unwrap())
}

/// Rotation angle of the tip from the base frame, degrees.
fn tip_angle_deg(v: &serde_json::Value) -> f64 {
    let w = v["quaternion"][0].as_f64().unwrap().abs().min(1.0);
    2.0 * w.acos().to_degrees()
}

fn fk_2seg(force: &str) -> std::process::Output {
    tendril(&[
        "fk",
        "--robot",
        "robots/tdcr-2seg.toml",
        "--tensions",
        "0,0,0,0,0,0",
        "--tip-force",
        force,
        "--json",
    ])
}

#[test]
fn a_lateral_ten_newton_tip_force_bends_the_rod_toward_it() {
    // seed-4t: gravity +x, the force +x. A dead lateral force cannot turn a
    // clamped rod's tip past 90° (the moment at the tip is zero and the
    // tangent turns toward the force); the shooting solve alone landed on
    // an equilibrium turned 178° with the tip at −x, and 7–9 N did not
    // converge.
    let mut last_x = 0.0;
    for f in ["7", "8", "9", "10"] {
        let v = json(&tendril(&[
            "fk",
            "--tensions",
            "0,0,0,0",
            "--tip-force",
            &format!("{f},0,0"),
            "--json",
        ]));
        let p = position(&v);
        let angle = tip_angle_deg(&v);
        assert!(p[0] > last_x, "{f} N: tip x {} not past {last_x}", p[0]);
        assert!(angle < 90.0, "{f} N: tip turned {angle:.1}°");
        last_x = p[0];
    }
}

#[test]
fn a_column_below_the_euler_load_stays_straight_and_is_accepted() {
    let p = position(&json(&fk_2seg(&format!("0,0,{}", -0.9 * euler_load()))));
    assert!(p[0].abs() < 1e-9 && p[1].abs() < 1e-9, "{p:?}");
    assert!(p[2] < TDCR_L, "{p:?}");
}

#[test]
fn a_perfect_column_above_the_euler_load_is_refused_as_not_unique() {
    // Straight is an equilibrium above P_cr, but an unstable one: the rod
    // buckles either way. The old solve printed the straight column, exit 0.
    let out = fk_2seg(&format!("0,0,{}", -1.3 * euler_load()));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success(),
        "accepted: {}",
        String::from_utf8_lossy(&out.stdout)
    );
    assert!(
        out.stdout.is_empty(),
        "printed an answer: {}",
        String::from_utf8_lossy(&out.stdout)
    );
    assert!(stderr.contains("not unique"), "{stderr}");
    // Where: at P_cr / P of the load, to the step halving's resolution.
    let percent = 100.0 / 1.3;
    assert!(
        stderr.contains(&format!("{percent:.1} %")) || {
            let got: f64 = stderr
                .split(" at ")
                .last()
                .and_then(|t| t.split_whitespace().next())
                .and_then(|t| t.parse().ok())
                .unwrap_or(f64::NAN);
            (got - percent).abs() < 0.5
        },
        "{stderr}"
    );
}

#[test]
fn a_buckled_column_follows_its_imperfection_and_matches_the_elastica() {
    // 1.5 P_cr with a lateral force of 0.1 % of it: the rod buckles toward
    // the small force, to the elastica's deflection δ/L = 2k/K(k), where
    // K(k) = (π/2)·√(P/P_cr) (complete elliptic integral, k = sin(α/2)).
    let ratio: f64 = 1.5;
    let p_axial = ratio * euler_load();
    let target = std::f64::consts::FRAC_PI_2 * ratio.sqrt();
    let k_of = |k: f64| {
        // K(k) = π / (2 AGM(1, √(1 − k²))).
        let (mut a, mut b) = (1.0_f64, (1.0 - k * k).sqrt());
        for _ in 0..30 {
            (a, b) = ((a + b) / 2.0, (a * b).sqrt());
        }
        std::f64::consts::PI / (2.0 * a)
    };
    let (mut lo, mut hi) = (0.0, 0.999_999);
    for _ in 0..80 {
        let mid = 0.5 * (lo + hi);
        if k_of(mid) < target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let elastica = 2.0 * lo / target * TDCR_L;
    for sign in [1.0, -1.0] {
        let force = format!("0,{},{}", sign * 1e-3 * p_axial, -p_axial);
        let p = position(&json(&fk_2seg(&force)));
        assert!(
            sign * p[1] > 0.0,
            "{force}: tip {p:?} did not follow the imperfection"
        );
        let rel = (p[1].abs() - elastica).abs() / elastica;
        assert!(
            rel < 0.03,
            "{force}: lateral {} vs elastica {elastica} (rel {rel})",
            p[1]
        );
    }
}

#[test]
fn a_batch_marks_the_row_without_a_stable_equilibrium_and_exits_non_zero() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("rows.csv");
    let output = dir.path().join("out.csv");
    let pcr = euler_load();
    std::fs::write(
        &input,
        format!(
            "t0,t1,t2,t3,t4,t5,fz\n0,0,0,0,0,0,{}\n0,0,0,0,0,0,{}\n",
            -0.5 * pcr,
            -1.3 * pcr
        ),
    )
    .unwrap();
    let out = tendril(&[
        "fk",
        "--robot",
        "robots/tdcr-2seg.toml",
        "--input",
        input.to_str().unwrap(),
        "--output",
        output.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success(),
        "exit 0 with an unstable row: {stderr}"
    );
    assert!(stderr.contains("1 of 2 rows"), "{stderr}");
    assert!(stderr.contains("stable"), "{stderr}");
    let text = std::fs::read_to_string(Path::new(&output)).unwrap();
    let flags: Vec<&str> = text
        .lines()
        .skip(1)
        .map(|l| l.rsplit(',').next().unwrap())
        .collect();
    assert_eq!(flags, ["true", "false"], "{text}");
    // The stable row has its pose (straight: px = 0), the other none.
    let px: Vec<&str> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(7).unwrap())
        .collect();
    assert_eq!(
        px[0]
            .parse::<f64>()
            .map(f64::abs)
            .ok()
            .filter(|x| *x < 1e-9),
        Some(0.0),
        "{text}"
    );
    assert_eq!(px[1], "", "{text}");
}

//! The polish phase through the CLI (docs/design.md §4, "Polish"): on the
//! two-segment robot's rows, a small net polished on the tip loss lands the tip
//! closer on held-out rows — judged by the statics, not by the loss it
//! minimised — and its report says what the polish did.

use std::path::Path;

use tendril_tests::{assert_ok, held_out_tip_mean_mm, json, robot, tendril_in};

/// Train `name.tnet` with `extra` flags and return its held-out tip mean, mm.
fn train_and_judge(dir: &Path, name: &str, extra: &[&str]) -> f64 {
    let model = format!("{name}.tnet");
    let base = [
        "train",
        "--data",
        "d.csv",
        "--out",
        &model,
        "--max-hidden",
        "3",
        "--threads",
        "2",
    ];
    let o = tendril_in(dir, &[&base[..], extra].concat());
    assert_ok(&o, name);
    held_out_tip_mean_mm(dir, &model, "d.csv", &robot("tdcr-2seg.toml"))
}

#[test]
fn a_polished_net_lands_the_tip_closer_on_held_out_rows() {
    let dir = tempfile::tempdir().unwrap();
    let two = robot("tdcr-2seg.toml");
    let o = tendril_in(
        dir.path(),
        &[
            "generate",
            "--robot",
            two.to_str().unwrap(),
            "--samples",
            "1500",
            "--out",
            "d.csv",
            "--quiet",
        ],
    );
    assert_ok(&o, "generate");
    let greedy = train_and_judge(dir.path(), "greedy", &["--polish", "0"]);
    let polished = train_and_judge(dir.path(), "polished", &["--polish", "800"]);
    eprintln!("held-out tip mean: greedy {greedy} mm, polished {polished} mm");
    assert!(
        polished < 0.7 * greedy,
        "held-out tip error: greedy {greedy} mm, polished {polished} mm"
    );
    let report = json(&dir.path().join("polished.train.json"));
    assert_eq!(report["options"]["polish"]["loss"], "tip", "{report}");
    let p = &report["report"]["polish"];
    assert!(p["iterations"].as_u64().unwrap() > 10, "{p}");
    assert!(
        p["valid_rmse"][1].as_f64().unwrap() < p["valid_rmse"][0].as_f64().unwrap(),
        "{p}"
    );
    let greedy_report = json(&dir.path().join("greedy.train.json"));
    assert!(greedy_report["report"]["polish"].is_null());
}

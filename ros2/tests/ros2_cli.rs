//! `tendril-ros2` as a user meets it: its help, and settings it cannot run
//! with refused before it joins a graph. (Its life on a graph is tested
//! from an independent Cyclone DDS peer: python/tests/test_ros2.py.)

use std::process::Command;

fn ros2(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_tendril-ros2"))
        .args(args)
        .env("ROS_DOMAIN_ID", "231")
        .output()
        .expect("tendril-ros2 runs")
}

#[test]
fn the_help_names_the_plant_and_bad_settings_are_refused_by_name() {
    let help = ros2(&["--help"]);
    assert!(help.status.success());
    assert!(String::from_utf8_lossy(&help.stdout).contains("plant"));
    // drive's rate is its own (200 Hz), not `tendril controller`'s 1 kHz.
    let drive = ros2(&["drive", "--help"]);
    assert!(String::from_utf8_lossy(&drive.stdout).contains("[default: 200"));
    for (args, named) in [
        (&["plant", "--rate", "5000"][..], "--rate"),
        (&["plant", "--scene-hz", "0"][..], "--scene-hz"),
        (&["plant", "--duration", "0"][..], "--duration"),
        (
            &["plant", "--robot", "robots/none.toml"][..],
            "robots/none.toml",
        ),
    ] {
        let out = ros2(args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?} ran");
        assert!(
            err.starts_with("tendril-ros2: error:") && err.contains(named),
            "{args:?}: {err}"
        );
    }
}

//! What a run will cost, checked before it starts (issue 31: `--duration
//! 100000` used to grow its logs by ≈ 2.5 GB an hour until the disk or the
//! analysis's memory gave out).
//!
//! The three processes stream their CSV logs into the run's work directory
//! as they go (nothing is held in their memory: the plant's and
//! controller's timing statistics are fixed-size histograms), and the
//! launcher reads them back once to build the report, holding about as
//! many bytes as the logs take on disk. Both are proportional to the run's
//! length, so the run's length is bounded instead: the estimated log size
//! must fit under a stated cap (`--max-log-gb`, default
//! [`DEFAULT_MAX_LOG_GB`]) and in the free space of the output's file system.

use std::path::Path;

use super::{SimConfig, SimError};

/// Bytes of one log row, apart from the tendon columns (times, sequence
/// numbers, pose, status), measured: 0.69 MB/s for the three logs of a
/// 4-tendon robot at 1 kHz (`tendril sim --duration 30`, 22.5 MB in 32.4 s).
const ROW_BASE_BYTES: f64 = 70.0;
/// Bytes per tendon in one log row (commanded and measured tensions).
const ROW_BYTES_PER_TENDON: f64 = 40.0;
/// Bytes per second of a run log (`run.mcap`) apart from its scenes: the
/// 1 kHz tensions, tracking and status channels, zstd-compressed,
/// measured: 511 kB for a 4.5 s run with one two-point scene a second.
const RUN_LOG_BASE_BYTES_PER_S: f64 = 115e3;
/// Bytes per scene point (the backbone and each tendon's line), measured
/// over 4.5 s runs of the default robot: 25.5 at 30 scenes/s of 41
/// points, 22.7 at 100 × 200, 21.5 at 1000 × 1000 (the largest that
/// `--scene-hz` and `--backbone-points` allow: 108 MB/s).
const RUN_LOG_BYTES_PER_SCENE_POINT: f64 = 26.0;
/// Default cap on a run's logs, GB (≈ 45 min at 1 kHz with 4 tendons).
pub const DEFAULT_MAX_LOG_GB: f64 = 2.0;

/// The estimated cost of one run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cost {
    /// Log bytes per second of run.
    pub bytes_per_s: f64,
    /// Log bytes of the whole run (settle + duration), also about the
    /// memory the report's analysis needs.
    pub log_bytes: f64,
}

/// The cost of `cfg` for a robot with `tendons` tendons: one row per
/// planner setpoint, per controller period and per plant step (the plant
/// steps at the command rate), and the run log with its scenes.
pub fn estimate(cfg: &SimConfig, tendons: usize) -> Cost {
    let rows_per_s = cfg.planner.rate_hz + 2.0 * cfg.controller.rate_hz;
    let mut bytes_per_s = rows_per_s * (ROW_BASE_BYTES + ROW_BYTES_PER_TENDON * tendons as f64);
    let runlog = &cfg.plant.runlog;
    if runlog.mcap.is_some() {
        let points = runlog.backbone_points as f64 * (1 + tendons) as f64;
        bytes_per_s +=
            RUN_LOG_BASE_BYTES_PER_S + RUN_LOG_BYTES_PER_SCENE_POINT * runlog.scene_hz * points;
    }
    Cost {
        bytes_per_s,
        log_bytes: bytes_per_s * (cfg.planner.settle_s + cfg.duration_s),
    }
}

/// Free bytes on the file system that holds `path` (or its nearest
/// existing ancestor); `None` when it cannot be asked.
pub fn free_bytes(path: &Path) -> Option<u64> {
    use std::os::unix::ffi::OsStrExt;
    let existing = path
        .ancestors()
        .find(|p| p.exists())
        .unwrap_or(Path::new("."));
    let existing = if existing.as_os_str().is_empty() {
        Path::new(".")
    } else {
        existing
    };
    let c = std::ffi::CString::new(existing.as_os_str().as_bytes()).ok()?;
    // SAFETY: a zeroed statvfs is a valid out-argument; `c` is a valid C string.
    let mut st: libc::statvfs = unsafe { std::mem::zeroed() };
    // SAFETY: as above; statvfs only writes `st`.
    let rc = unsafe { libc::statvfs(c.as_ptr(), &mut st) };
    (rc == 0).then(|| st.f_bavail as u64 * st.f_frsize as u64)
}

fn gb(bytes: f64) -> String {
    if bytes < 1e9 {
        format!("{:.1} MB", bytes / 1e6)
    } else {
        format!("{:.1} GB", bytes / 1e9)
    }
}

/// Seconds, readable also when absurd (`1e300`).
fn secs(s: f64) -> String {
    if s < 1e9 {
        format!("{s}")
    } else {
        format!("{s:e}")
    }
}

/// Refuse a run whose logs would exceed the cap or the free space.
pub fn check(cfg: &SimConfig, tendons: usize, free: Option<u64>) -> Result<Cost, SimError> {
    let cost = estimate(cfg, tendons);
    let cap = cfg.max_log_gb * 1e9;
    let what = || {
        format!(
            "--duration {} s (+ {} s settle): the logs would take ≈ {} ({:.2} MB/s) and about as \
             much memory to analyse",
            secs(cfg.duration_s),
            secs(cfg.planner.settle_s),
            gb(cost.log_bytes),
            cost.bytes_per_s / 1e6
        )
    };
    if cost.log_bytes > cap {
        return Err(SimError::Config(format!(
            "{}; the cap is {} (--max-log-gb to raise it, or a shorter --duration: at most \
             {:.0} s)",
            what(),
            gb(cap),
            (cap / cost.bytes_per_s - cfg.planner.settle_s).max(0.0)
        )));
    }
    if let Some(free) = free.filter(|&f| cost.log_bytes > f as f64) {
        return Err(SimError::Config(format!(
            "{}; only {} are free on the file system of {}",
            what(),
            gb(free as f64),
            cfg.out.display()
        )));
    }
    Ok(cost)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ipc::sim::ModelSource;

    fn cfg(duration_s: f64) -> SimConfig {
        let mut c = SimConfig::new(
            "tendril".into(),
            "robots/seed-4t.toml".into(),
            ModelSource::BuiltIn,
            "out".into(),
        );
        c.duration_s = duration_s;
        c
    }

    #[test]
    fn the_estimate_matches_the_measured_log_rate() {
        // 22.5 MB in 32.4 s measured (4 tendons, 1 kHz): 0.69 MB/s.
        let c = estimate(&cfg(30.0), 4);
        assert!((c.bytes_per_s - 0.69e6).abs() < 0.05e6, "{c:?}");
        assert!((c.log_bytes - 32.0 * c.bytes_per_s).abs() < 1.0);
    }

    #[test]
    fn a_hundred_thousand_seconds_is_refused_with_its_cost_and_the_flag_to_raise_the_cap() {
        let err = check(&cfg(100_000.0), 4, Some(u64::MAX))
            .unwrap_err()
            .to_string();
        assert!(err.contains("--duration 100000 s"), "{err}");
        assert!(err.contains("≈ 69.0 GB"), "{err}");
        assert!(err.contains("--max-log-gb"), "{err}");
        let mut raised = cfg(100_000.0);
        raised.max_log_gb = 100.0;
        assert!(check(&raised, 4, Some(u64::MAX)).is_ok());
        let err = check(&raised, 4, Some(1_000_000_000))
            .unwrap_err()
            .to_string();
        assert!(err.contains("only 1.0 GB are free"), "{err}");
        assert!(check(&cfg(10.0), 4, Some(1_000_000_000)).is_ok());
        let err = check(&cfg(1e300), 4, None).unwrap_err().to_string();
        assert!(err.contains("--duration 1e300 s"), "{err}");
        let mut tiny = cfg(10.0);
        tiny.max_log_gb = 1e-6;
        let err = check(&tiny, 4, None).unwrap_err().to_string();
        assert!(
            err.contains("≈ 8.3 MB") && err.contains("cap is 0.0 MB"),
            "{err}"
        );
    }

    #[test]
    fn the_run_log_and_its_scenes_are_costed_as_measured() {
        let mut c = cfg(4.0);
        c.planner.settle_s = 0.5;
        let csv_only = estimate(&c, 4).bytes_per_s;
        c.plant.runlog.mcap = Some("run.mcap".into());
        // Measured run.mcap sizes over 4.5 s (module constants' sources).
        for (scene_hz, points, measured_bytes) in [
            (30.0, 41, 1_217_636.0),
            (100.0, 200, 10_719_191.0),
            (1000.0, 1000, 484_949_520.0),
        ] {
            c.plant.runlog.scene_hz = scene_hz;
            c.plant.runlog.backbone_points = points;
            let log = (estimate(&c, 4).bytes_per_s - csv_only) * 4.5;
            let ratio = log / measured_bytes;
            assert!(
                (0.9..1.4).contains(&ratio),
                "{scene_hz} Hz × {points}: {ratio}"
            );
        }
        // The hostile case: every scene as dense as allowed, for 2000 s.
        c.duration_s = 2000.0;
        let err = check(&c, 4, Some(u64::MAX)).unwrap_err().to_string();
        assert!(err.contains("GB"), "{err}");
    }
}

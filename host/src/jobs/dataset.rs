//! Dataset generation as one library call: a typed request in, the CSV and its
//! sidecar on disk, the sidecar out (docs/design.md §3). `tendril generate`
//! and the pipeline both call [`generate`].
//!
//! Rows stream to a temporary file beside the output as blocks complete, so
//! memory stays bounded whatever the count; the file replaces the output only
//! when every row is in. An interrupted or failed run leaves any existing
//! dataset and sidecar as they were.

use std::fs::File;
use std::io::{BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use sha2::{Digest, Sha256};

use crate::dataset::disk::{free_bytes, parent_dir, same_file};
use crate::dataset::generate::{column_ranges, generate_rows, GenerateOptions, StreamError};
use crate::dataset::io::{RowWriter, MAX_VALUE_BYTES};
use crate::dataset::split::{test_mask, MinMax, Ranges, SPLIT_SEED, TEST_FRACTION};
use crate::dataset::{DatasetError, Resolve, Sampler, Sidecar};
use crate::robot::anchor_groups;
use crate::robot::{Robot, RobotError};
use crate::statics::{SolverSettings, Statics};

/// The largest `--samples` accepted: 1000× the default, about 5 GB of CSV
/// and 20 minutes on a 2-core machine. Memory stays bounded by one block of
/// solutions plus 5 bytes per row for the train/test split (100 MB here).
pub const MAX_SAMPLES: usize = 20_000_000;
/// The largest `--steps` accepted (RK4 steps over the length; 16 converge the
/// default robot's tip to 1e-7 m).
pub const MAX_STEPS: usize = 100_000;
/// Default sample count.
pub const DEFAULT_SAMPLES: usize = 20_000;
/// Default largest fraction of failed solves before the run counts as failed.
pub const DEFAULT_MAX_FAILURE_FRACTION: f64 = 0.001;

/// What to generate and where.
#[derive(Clone, Debug, PartialEq)]
pub struct GenerateRequest {
    /// Robot description (TOML).
    pub robot_path: PathBuf,
    /// Samples to draw, 1..=[`MAX_SAMPLES`].
    pub samples: usize,
    /// Random seed of the sampler.
    pub seed: u64,
    /// Tension sampler; `None` = [`Sampler::default_for`] the robot.
    pub sampler: Option<Sampler>,
    /// Which tensions each row keeps; `None` = [`Resolve::default_for`] the
    /// robot.
    pub resolve: Option<Resolve>,
    /// Output CSV; the sidecar goes beside it ([`Sidecar::path_for`]).
    pub out: PathBuf,
    /// Fail (after writing) if more than this fraction of solves fails, in [0, 1].
    pub max_failure_fraction: f64,
    /// Held-out test fraction recorded for the learners, in [0, 1).
    pub test_fraction: f64,
    /// RK4 steps over the length, 1..=[`MAX_STEPS`].
    pub steps: usize,
}

impl GenerateRequest {
    /// The defaults of `tendril generate` for `robot_path`, writing `out`.
    pub fn new(robot_path: &Path, out: &Path) -> GenerateRequest {
        GenerateRequest {
            robot_path: robot_path.to_path_buf(),
            samples: DEFAULT_SAMPLES,
            seed: 1,
            sampler: None,
            resolve: None,
            out: out.to_path_buf(),
            max_failure_fraction: DEFAULT_MAX_FAILURE_FRACTION,
            test_fraction: TEST_FRACTION,
            steps: SolverSettings::default().steps,
        }
    }

    /// The sidecar path.
    pub fn sidecar_path(&self) -> PathBuf {
        Sidecar::path_for(&self.out)
    }

    fn settings(&self) -> SolverSettings {
        SolverSettings {
            steps: self.steps,
            ..SolverSettings::default()
        }
    }

    /// An upper bound on the bytes the CSV and sidecar take.
    pub fn output_bytes_bound(&self, n_tendons: usize) -> u64 {
        const SIDECAR_BYTES: u64 = 16 * 1024;
        let per_row = (n_tendons as u64 + 7) * MAX_VALUE_BYTES;
        (self.samples as u64 + 1).saturating_mul(per_row) + SIDECAR_BYTES
    }

    fn validate(&self) -> Result<(), GenerateError> {
        let bad = |why: String| Err(GenerateError::Invalid(why));
        if !(1..=MAX_SAMPLES).contains(&self.samples) {
            return bad(format!(
                "--samples must be between 1 and {MAX_SAMPLES} (docs/design.md §3), got {}",
                self.samples
            ));
        }
        if !(1..=MAX_STEPS).contains(&self.steps) {
            return bad(format!(
                "--steps must be between 1 and {MAX_STEPS}, got {}",
                self.steps
            ));
        }
        crate::dataset::split::check_test_fraction(self.test_fraction)
            .map_err(GenerateError::Invalid)?;
        if !(0.0..=1.0).contains(&self.max_failure_fraction) {
            return bad(format!(
                "--max-failure-fraction must be in [0, 1], got {}",
                self.max_failure_fraction
            ));
        }
        Ok(())
    }

    /// Refuse an output that is a directory, not a regular file, an input
    /// or the other output, before anything is written.
    fn check_paths(&self) -> Result<(), GenerateError> {
        let sidecar = self.sidecar_path();
        for out in [&self.out, &sidecar] {
            if out.is_dir() {
                return Err(GenerateError::BadOutput {
                    path: out.clone(),
                    why: "is a directory; give a file name".into(),
                });
            }
        }
        // A dataset is two files, the CSV and the sidecar `train` needs
        // beside it: rows streamed into a device or FIFO would leave a stray
        // `/dev/full.json` (or no place at all) for their sidecar, and a
        // sidecar written through a FIFO is lost. Refused, as `-` is.
        for (out, what) in [(&self.out, "dataset"), (&sidecar, "sidecar")] {
            match crate::fsutil::is_regular_output(out) {
                Ok(true) => {}
                Ok(false) => {
                    return Err(GenerateError::BadOutput {
                        path: out.clone(),
                        why: format!(
                            "is a device, FIFO or descriptor, not a regular file: the {what} \
                             must be a file, as a dataset is a CSV with its sidecar (.json) \
                             beside it for `train`; give a file name"
                        ),
                    })
                }
                Err(e) => return Err(io_error(out, &e)),
            }
        }
        if same_file(&self.out, &sidecar) {
            return Err(GenerateError::BadOutput {
                path: self.out.clone(),
                why: "the dataset and its sidecar would be the same file; name the CSV \
                      something other than *.json"
                    .into(),
            });
        }
        for (out, what) in [(&self.out, "dataset"), (&sidecar, "sidecar")] {
            if same_file(out, &self.robot_path) {
                return Err(GenerateError::BadOutput {
                    path: out.clone(),
                    why: format!("the {what} would overwrite the robot file"),
                });
            }
        }
        Ok(())
    }
}

/// Why a dataset could not be generated.
#[derive(Debug, thiserror::Error)]
pub enum GenerateError {
    /// The robot file could not be loaded.
    #[error(transparent)]
    Robot(#[from] RobotError),
    /// A request field is out of range.
    #[error("{0}")]
    Invalid(String),
    /// An output path is an input, the other output, or a directory.
    #[error("{}: {why}", path.display())]
    BadOutput {
        /// The output path.
        path: PathBuf,
        /// Which paths collide.
        why: String,
    },
    /// The output would not fit in the free space of its directory.
    #[error(
        "{}: --samples {} needs up to {} MB but only {} MB are free there; ask for fewer samples or write elsewhere",
        dir.display(), samples, need / 1_000_000, free / 1_000_000
    )]
    NoSpace {
        /// The output directory.
        dir: PathBuf,
        /// Samples asked for.
        samples: usize,
        /// Upper bound of the bytes needed.
        need: u64,
        /// Bytes free for an unprivileged user.
        free: u64,
    },
    /// Ctrl-C or another stop request; nothing was written.
    #[error("interrupted; nothing was written")]
    Interrupted,
    /// Every solve failed, so there is nothing to write.
    #[error("every solve failed: nothing to write (first failure: {first})")]
    EverySolveFailed {
        /// The first failure, in words.
        first: String,
    },
    /// More solves failed than allowed. The dataset and sidecar were written.
    #[error(
        "{dropped} of {requested} solves failed ({:.2} %, above the maximum failure fraction {max}); see {}",
        100.0 * *dropped as f64 / *requested as f64, sidecar.display()
    )]
    TooManyFailures {
        /// Samples dropped.
        dropped: usize,
        /// Samples asked for.
        requested: usize,
        /// The allowed fraction.
        max: f64,
        /// The sidecar that was written.
        sidecar: PathBuf,
    },
    /// Reading or writing a file failed.
    #[error("{}: {message}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// What went wrong (the OS error, said once).
        message: String,
    },
    /// The sidecar could not be written.
    #[error(transparent)]
    Dataset(#[from] DatasetError),
}

fn io_error(path: &Path, e: &std::io::Error) -> GenerateError {
    // An io::Error wrapping another error (tempfile's path errors) displays
    // the inner message and also reports it as its source; keep the text only.
    let message = match e.get_ref() {
        Some(inner) => inner
            .source()
            .map_or_else(|| inner.to_string(), ToString::to_string),
        None => e.to_string(),
    };
    GenerateError::Io {
        path: path.to_path_buf(),
        message,
    }
}

/// Generate the dataset `req` asks for: validate, stream the rows to a
/// temporary file, compute the sidecar's ranges, then put both in place.
/// `stop` is polled between chunks of solves (set it from a Ctrl-C handler).
/// Returns the sidecar that was written. With more failed solves than
/// `req.max_failure_fraction` allows, the files are written and
/// [`GenerateError::TooManyFailures`] is returned.
pub fn generate(
    req: &GenerateRequest,
    progress: bool,
    stop: &AtomicBool,
) -> Result<Sidecar, GenerateError> {
    req.validate()?;
    req.check_paths()?;
    let (robot, source) = Robot::load_with_source(&req.robot_path)?;
    let dir = parent_dir(&req.out);
    std::fs::create_dir_all(&dir).map_err(|e| io_error(&dir, &e))?;
    check_space(&dir, req.samples, req.output_bytes_bound(robot.n_tendons()))?;

    let start = Instant::now();
    let settings = req.settings();
    let statics = Statics::new(&robot, settings);
    let sampler = req
        .sampler
        .unwrap_or(Sampler::default_for(robot.n_tendons()));
    let resolve = req.resolve.unwrap_or(Resolve::default_for(&robot));
    let opts = GenerateOptions {
        samples: req.samples,
        seed: req.seed,
        sampler,
        resolve,
        progress,
    };
    let temp = crate::fsutil::Temporary::for_output(&req.out).map_err(|e| io_error(&dir, &e))?;
    let tally = {
        let file = temp.as_file().try_clone().map_err(|e| io_error(&dir, &e))?;
        let mut rows = RowWriter::new(BufWriter::new(file), robot.n_tendons())
            .map_err(|e| io_error(&dir, &e))?;
        let tally = generate_rows(&statics, &opts, stop, |t, pose| {
            rows.write(t.iter().chain(pose).copied())
        })
        .map_err(|e| match e {
            StreamError::Interrupted => GenerateError::Interrupted,
            StreamError::Sink(e) => io_error(temp.path(), &e),
        })?;
        let mut out = rows.into_inner();
        out.flush().map_err(|e| io_error(temp.path(), &e))?;
        tally
    };
    for (t, e) in &tally.failures {
        log::warn!("dropped sample {t:?}: {e}");
    }
    if tally.kept == 0 {
        let first = tally.failures.first().map_or_else(
            || "none recorded".to_string(),
            |(t, e)| format!("{t:?}: {e}"),
        );
        return Err(GenerateError::EverySolveFailed { first });
    }
    let train_ranges = train_ranges(
        temp.path(),
        robot.n_tendons(),
        tally.kept,
        req.test_fraction,
    )
    .map_err(|e| io_error(temp.path(), &e))?;
    if stop.load(Ordering::Relaxed) {
        return Err(GenerateError::Interrupted);
    }
    let sidecar = Sidecar {
        robot_file: req.robot_path.display().to_string(),
        robot_sha256: hex(&Sha256::digest(source.as_bytes())),
        robot_fingerprint: hex(&robot.fingerprint()),
        robot_name: robot.name.clone(),
        sampler: sampler.name().into(),
        sampler_groups: sampler_groups(sampler, &robot),
        resolve,
        seed: req.seed,
        requested: req.samples,
        count: tally.kept,
        solver: settings,
        ranges: column_ranges(robot.n_tendons(), &tally.lo, &tally.hi),
        resolved_cold: tally.resolved_cold,
        dropped: tally.dropped,
        failure_policy: "a warm-started solve that misses the tolerance is re-solved cold; \
                         a sample whose cold solve fails too is dropped and counted here; \
                         with least-bending rows, so is a drawn tip position the exact IK \
                         does not reach again"
            .into(),
        test_fraction: req.test_fraction,
        train_ranges: Some(train_ranges),
        seconds: start.elapsed().as_secs_f64(),
        tendril_version: env!("CARGO_PKG_VERSION").into(),
        residual: None,
    };
    commit(temp, &req.out, &sidecar)?;
    let fraction = tally.dropped as f64 / req.samples as f64;
    if fraction > req.max_failure_fraction {
        return Err(GenerateError::TooManyFailures {
            dropped: tally.dropped,
            requested: req.samples,
            max: req.max_failure_fraction,
            sidecar: req.sidecar_path(),
        });
    }
    Ok(sidecar)
}

/// Put the finished CSV in place (by the output policy of
/// [`crate::fsutil`]: renamed over a regular file, copied through a device
/// or FIFO) and write its sidecar. The old sidecar goes first, so no crash
/// between the steps can pair a sidecar with a CSV it does not describe
/// ([`is_up_to_date`] would then reuse the wrong rows).
fn commit(
    temp: crate::fsutil::Temporary,
    out: &Path,
    sidecar: &Sidecar,
) -> Result<(), GenerateError> {
    let side_path = Sidecar::path_for(out);
    match std::fs::remove_file(&side_path) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
            return Err(io_error(&side_path, &e));
        }
        _ => {}
    }
    temp.persist(out).map_err(|e| io_error(out, &e))?;
    sidecar.write(&side_path)?;
    Ok(())
}

/// Min–max ranges of the training split of the `n` rows in the CSV at
/// `path`, the same as `prepare` computes from the whole dataset in memory,
/// found in one streamed pass.
fn train_ranges(
    path: &Path,
    n_tendons: usize,
    n: usize,
    test_fraction: f64,
) -> std::io::Result<Ranges> {
    let is_test = test_mask(n, test_fraction, SPLIT_SEED);
    let width = n_tendons + 7;
    let mut lo = vec![f64::INFINITY; width];
    let mut hi = vec![f64::NEG_INFINITY; width];
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(true)
        .from_reader(BufReader::new(File::open(path)?));
    let mut record = csv::StringRecord::new();
    let mut row = 0;
    while reader
        .read_record(&mut record)
        .map_err(std::io::Error::other)?
    {
        if !is_test.get(row).copied().unwrap_or(true) {
            for (k, field) in record.iter().enumerate().take(width) {
                let x: f64 = field.parse().map_err(std::io::Error::other)?;
                lo[k] = lo[k].min(x);
                hi[k] = hi[k].max(x);
            }
        }
        row += 1;
    }
    let split =
        |from: usize, to: usize| MinMax::from_bounds(lo[from..to].to_vec(), hi[from..to].to_vec());
    Ok(Ranges {
        poses: split(n_tendons, width),
        tensions: split(0, n_tendons),
    })
}

/// Whether `req.out` holds a dataset [`generate`] wrote for `req` (same robot
/// bytes, sampler, seed, count and steps), so a caller may reuse it.
pub fn is_up_to_date(req: &GenerateRequest) -> bool {
    let Ok(side) = Sidecar::read(&req.sidecar_path()) else {
        return false;
    };
    let Ok((robot, source)) = Robot::load_with_source(&req.robot_path) else {
        return false;
    };
    let sampler = req
        .sampler
        .unwrap_or(Sampler::default_for(robot.n_tendons()));
    req.out.exists()
        && side.robot_sha256 == hex(&Sha256::digest(source.as_bytes()))
        && side.sampler == sampler.name()
        && same_groups(&side.sampler_groups, &sampler_groups(sampler, &robot))
        && side.resolve == req.resolve.unwrap_or(Resolve::default_for(&robot))
        && side.seed == req.seed
        && side.requested == req.samples
        && side.solver.steps == req.steps
}

/// The groups the sidecar records for `sampler` on `robot`.
fn sampler_groups(sampler: Sampler, robot: &Robot) -> Vec<Vec<usize>> {
    match sampler {
        Sampler::Adjacent => anchor_groups(robot),
        Sampler::Uniform => Vec::new(),
    }
}

/// Whether a sidecar's recorded groups draw as `groups` do. Sidecars written
/// before the groups were recorded have none; they drew all tendons as one
/// ring in index order, which is what one group listed in index order draws.
fn same_groups(recorded: &[Vec<usize>], groups: &[Vec<usize>]) -> bool {
    recorded == groups
        || (recorded.is_empty()
            && match groups {
                [] => true,
                [one] => one.iter().copied().eq(0..one.len()),
                _ => false,
            })
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Refuse a run whose output bound exceeds the free space of `dir`.
fn check_space(dir: &Path, samples: usize, need: u64) -> Result<(), GenerateError> {
    match free_bytes(dir) {
        Some(free) if free < need => Err(GenerateError::NoSpace {
            dir: dir.to_path_buf(),
            samples,
            need,
            free,
        }),
        _ => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dataset::{prepare, Dataset};

    fn request(dir: &Path, samples: usize) -> GenerateRequest {
        let robot = Path::new(env!("CARGO_MANIFEST_DIR")).join("../robots/seed-4t.toml");
        GenerateRequest {
            samples,
            ..GenerateRequest::new(&robot, &dir.join("d.csv"))
        }
    }

    #[test]
    fn streamed_sidecar_ranges_match_the_in_memory_split() {
        let dir = tempfile::tempdir().unwrap();
        let req = GenerateRequest {
            test_fraction: 0.2,
            ..request(dir.path(), 300)
        };
        let side = generate(&req, false, &AtomicBool::new(false)).unwrap();
        let data = Dataset::read_csv(&req.out).unwrap();
        assert_eq!(data.len(), side.count);
        let prepared = prepare(&data, 0.2, 0.0, SPLIT_SEED);
        assert_eq!(side.train_ranges, Some(prepared.ranges()));
        let px = side.ranges.iter().find(|r| r.column == "px").unwrap();
        assert_eq!(px.min, data.poses.column(0).min());
        assert_eq!(px.max, data.poses.column(0).max());
        assert!(is_up_to_date(&req));
        assert!(!is_up_to_date(&GenerateRequest { seed: 2, ..req }));
    }

    #[test]
    fn three_segment_rows_keep_the_least_bending_tensions_of_the_drawn_tip() {
        // The independent facts: every kept row's pose is the statics of its
        // tensions; its tip is the drawn row's tip to the µm of axial strain
        // (the sampler redrawn with the same seed); the drawn tensions reach
        // that tip too, so they
        // cannot bend the robot with less effort (Σ over each segment's
        // three tendons of (τ − their mean)²); and each segment has a slack
        // tendon, as the command stage leaves it.
        let dir = tempfile::tempdir().unwrap();
        let robot_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../robots/tdcr-3seg.toml");
        let req = GenerateRequest {
            samples: 24,
            seed: 5,
            ..GenerateRequest::new(&robot_path, &dir.path().join("d.csv"))
        };
        let side = generate(&req, false, &AtomicBool::new(false)).unwrap();
        assert_eq!(side.resolve, Resolve::LeastBending);
        assert_eq!((side.count, side.dropped), (24, 0));
        let data = Dataset::read_csv(&req.out).unwrap();
        let robot = Robot::load(&robot_path).unwrap();
        let statics = Statics::new(&robot, SolverSettings::default());
        let groups = anchor_groups(&robot);
        let drawn = Sampler::Adjacent.draw_grouped(
            24,
            &robot.min_tensions(),
            &robot.max_tensions(),
            &groups,
            5,
        );
        let effort = |t: &[f64]| -> f64 {
            groups
                .iter()
                .map(|g| {
                    let mean = g.iter().map(|&i| t[i]).sum::<f64>() / g.len() as f64;
                    g.iter().map(|&i| (t[i] - mean).powi(2)).sum::<f64>()
                })
                .sum()
        };
        let mut lighter = 0;
        for (r, d) in drawn.iter().enumerate() {
            let kept: Vec<f64> = data.tensions.row(r).iter().copied().collect();
            let pose = statics.solve(&kept, None).unwrap().pose();
            let drawn_tip = statics.solve(d, None).unwrap().position;
            for (c, v) in pose.iter().enumerate() {
                assert!((v - data.poses[(r, c)]).abs() < 1e-9, "row {r}");
            }
            // Slackening moves the tip by the axial strain only: µm.
            for (c, v) in pose.iter().take(3).enumerate() {
                assert!((drawn_tip[c] - v).abs() < 1e-4, "row {r}: {d:?}");
            }
            assert!(
                effort(&kept) <= effort(d) + 1e-9,
                "row {r}: {kept:?} vs {d:?}"
            );
            lighter += usize::from(effort(&kept) < 0.9 * effort(d));
            for g in &groups {
                let slack = g.iter().map(|&i| kept[i]).fold(f64::INFINITY, f64::min);
                assert!(slack.abs() <= 1e-9, "row {r}: {kept:?}");
            }
        }
        // Not a copy of the draws: most rows spread the bending over more tendons.
        assert!(lighter >= 12, "{lighter} of 24 rows lighter than drawn");
        // A dataset resolved otherwise is not reused for this request.
        assert!(is_up_to_date(&req));
        std::fs::write(
            req.sidecar_path(),
            std::fs::read_to_string(req.sidecar_path())
                .unwrap()
                .replace("\"least-bending\"", "\"drawn\""),
        )
        .unwrap();
        assert!(!is_up_to_date(&req));
        assert!(is_up_to_date(&GenerateRequest {
            resolve: Some(Resolve::Drawn),
            ..req
        }));
    }

    #[test]
    fn robots_up_to_two_segments_keep_the_drawn_tensions() {
        for (file, dof, resolve) in [
            ("seed-4t.toml", 2, Resolve::Drawn),
            ("seed-1t.toml", 1, Resolve::Drawn),
            ("tdcr-2seg.toml", 4, Resolve::Drawn),
            ("tdcr-3seg.toml", 6, Resolve::LeastBending),
        ] {
            let robot = crate::robot::repo_robot(file);
            assert_eq!(crate::robot::bending_dof(&robot), dof, "{file}");
            assert_eq!(Resolve::default_for(&robot), resolve, "{file}");
        }
    }

    #[test]
    fn a_set_stop_flag_writes_nothing_and_keeps_the_old_files() {
        let dir = tempfile::tempdir().unwrap();
        let req = request(dir.path(), 50);
        std::fs::write(&req.out, "old csv").unwrap();
        std::fs::write(req.sidecar_path(), "old sidecar").unwrap();
        let err = generate(&req, false, &AtomicBool::new(true)).unwrap_err();
        assert!(matches!(err, GenerateError::Interrupted), "{err}");
        assert_eq!(std::fs::read_to_string(&req.out).unwrap(), "old csv");
        assert_eq!(
            std::fs::read_to_string(req.sidecar_path()).unwrap(),
            "old sidecar"
        );
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2);
    }

    #[test]
    fn colliding_paths_are_refused_before_writing() {
        let dir = tempfile::tempdir().unwrap();
        let mut req = request(dir.path(), 10);
        req.out = dir.path().join("x.json");
        let err = generate(&req, false, &AtomicBool::new(false)).unwrap_err();
        assert!(matches!(err, GenerateError::BadOutput { .. }), "{err}");
        assert!(err.to_string().contains("same file"), "{err}");
        // The robot file named through a different spelling of its directory.
        let robot_copy = dir.path().join("bot.csv");
        std::fs::copy(&req.robot_path, &robot_copy).unwrap();
        req.robot_path = robot_copy.clone();
        req.out = dir.path().join("sub/../bot.csv");
        std::fs::create_dir(dir.path().join("sub")).unwrap();
        let err = generate(&req, false, &AtomicBool::new(false)).unwrap_err();
        assert!(err.to_string().contains("robot file"), "{err}");
        assert!(std::fs::read_to_string(&robot_copy)
            .unwrap()
            .contains("[backbone]"));
        // A directory where the sidecar would go.
        std::fs::create_dir(dir.path().join("side.json")).unwrap();
        let req = GenerateRequest {
            out: dir.path().join("side.csv"),
            ..request(dir.path(), 10)
        };
        let err = generate(&req, false, &AtomicBool::new(false)).unwrap_err();
        assert!(err.to_string().contains("is a directory"), "{err}");
    }

    /// A FIFO at `path`, held open for reading and writing so that a
    /// writer never blocks (rows into it would sit in the pipe's buffer).
    #[cfg(unix)]
    fn open_fifo(path: &Path) -> std::fs::File {
        let made = std::process::Command::new("mkfifo")
            .arg(path)
            .status()
            .unwrap();
        assert!(made.success());
        std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(path)
            .unwrap()
    }

    #[cfg(unix)]
    #[test]
    fn a_fifo_for_the_dataset_or_its_sidecar_is_refused_before_writing() {
        use std::os::unix::fs::FileTypeExt;
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("rows");
        let _held = open_fifo(&fifo);
        let req = GenerateRequest {
            out: fifo.clone(),
            ..request(dir.path(), 3)
        };
        let err = generate(&req, false, &AtomicBool::new(false)).unwrap_err();
        assert!(matches!(err, GenerateError::BadOutput { .. }), "{err}");
        assert!(err.to_string().contains("not a regular file"), "{err}");
        assert!(
            !dir.path().join("rows.json").exists(),
            "a sidecar was written"
        );
        // The sidecar's path a FIFO: the rows would go to d.csv, the sidecar lost.
        let side = dir.path().join("d.json");
        let _held_side = open_fifo(&side);
        let err = generate(&request(dir.path(), 3), false, &AtomicBool::new(false)).unwrap_err();
        assert!(
            err.to_string().contains("the sidecar must be a file"),
            "{err}"
        );
        assert!(
            !dir.path().join("d.csv").exists(),
            "the dataset was written"
        );
        for f in [&fifo, &side] {
            assert!(std::fs::symlink_metadata(f).unwrap().file_type().is_fifo());
        }
    }

    #[test]
    fn absurd_counts_and_fractions_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        for req in [
            request(dir.path(), 0),
            request(dir.path(), MAX_SAMPLES + 1),
            GenerateRequest {
                steps: 0,
                ..request(dir.path(), 10)
            },
            GenerateRequest {
                test_fraction: 1.0,
                ..request(dir.path(), 10)
            },
            GenerateRequest {
                max_failure_fraction: f64::NAN,
                ..request(dir.path(), 10)
            },
        ] {
            let err = generate(&req, false, &AtomicBool::new(false)).unwrap_err();
            assert!(matches!(err, GenerateError::Invalid(_)), "{err}");
        }
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    #[test]
    fn generate_refuses_the_test_fractions_train_refuses() {
        let dir = tempfile::tempdir().unwrap();
        for t in [0.0, 0.9, -0.1, f64::NAN] {
            let req = GenerateRequest {
                test_fraction: t,
                ..request(dir.path(), 10)
            };
            let err = generate(&req, false, &AtomicBool::new(false)).unwrap_err();
            assert!(err.to_string().contains("(0, 0.5]"), "{t}: {err}");
            let split = crate::jobs::train::SplitSpec {
                test_fraction: t,
                ..Default::default()
            };
            assert!(split.validate().is_err(), "train accepts {t}");
        }
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    #[test]
    fn output_larger_than_the_free_space_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let free = free_bytes(dir.path()).expect("statvfs works on a temp dir");
        assert!(free > 0);
        let err = check_space(dir.path(), 7, free + 1).unwrap_err();
        assert!(err.to_string().contains("free"), "{err}");
        assert!(check_space(dir.path(), 7, free / 2).is_ok());
        // The bound covers a real file: 11 columns of at most 25 bytes.
        let req = request(dir.path(), 200);
        generate(&req, false, &AtomicBool::new(false)).unwrap();
        let written = std::fs::metadata(&req.out).unwrap().len()
            + std::fs::metadata(req.sidecar_path()).unwrap().len();
        assert!(written <= req.output_bytes_bound(4), "{written}");
    }
}

//! Inverse kinematics through a trained `.tnet` net, guarded so that it never
//! hands out an impossible tension (docs/design.md §5, §7): the quaternion's
//! sign is normalised (w ≥ 0, as in the dataset), a non-unit or non-finite
//! pose is refused, a pose outside the net's training ranges is refused (or
//! flagged, when extrapolation is allowed), and the net's raw output is
//! reported beside the tensions the firmware's command stage makes of it
//! (`command_stage::command_for`: each co-contraction set shifted into
//! range, then the clip to the robot's limits). The stage is what turns the
//! net's output into tensions at all: a net learns tensions only up to
//! co-contraction (`docs/design.md` §4).
//!
//! The net is evaluated by the firmware's own f32 `infer`, so the raw output
//! is bit-identical to what the MCU computes from the same file.

use std::path::{Path, PathBuf};

use tendril_shared::{McuNet, TendonLimits};

use crate::command_stage::{clipped_by, command_for, limits_for};
use crate::dataset::io::format_value;
use crate::dataset::POSE_COLUMNS;
use crate::robot::Robot;

use super::{infer, load_for_robot};

/// Largest accepted deviation of |q| from 1 (a quaternion within it is
/// renormalised; the dataset's are unit to ~1e-15).
pub const UNIT_TOLERANCE: f64 = 1e-3;
/// How far beyond its training range (as a fraction of the range) an input
/// may lie before the pose counts as outside the trained region: the
/// held-out rows of a dataset can exceed the training rows' extremes by a
/// hair.
pub const RANGE_MARGIN: f64 = 0.01;

/// Why no tensions could be given for a pose.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IkError {
    /// The `.tnet` file could not be loaded (the reason, said once).
    #[error("{0}")]
    Model(String),
    /// The net and the robot disagree on the tendon count.
    #[error("the net's tendon count ({net}) differs from robot {robot}'s ({robot_tendons}): give the robot it was trained for with --robot")]
    TendonCount {
        /// Outputs of the net.
        net: usize,
        /// Robot name.
        robot: String,
        /// Tendons of the robot.
        robot_tendons: usize,
    },
    /// A pose value is NaN or infinite.
    #[error("pose {column} = {value} is not a finite number")]
    NotFinite {
        /// Column name.
        column: &'static str,
        /// The value.
        value: f64,
    },
    /// The quaternion is not of unit length.
    #[error(
        "quaternion (qw, qx, qy, qz) has norm {norm}, not 1 (tolerance {UNIT_TOLERANCE}): \
         give a unit quaternion"
    )]
    NotUnit {
        /// Its norm.
        norm: f64,
    },
    /// A pose value lies outside the range the net was trained on.
    #[error(
        "pose {column} = {} is outside the net's training range [{lo:.6}, {hi:.6}]: the net \
         would extrapolate (pass --allow-extrapolation to get staged tensions anyway)",
        format_value(*value)
    )]
    OutsideTrainedRange {
        /// Column name.
        column: &'static str,
        /// The (sign-normalised) value.
        value: f64,
        /// Training minimum.
        lo: f64,
        /// Training maximum.
        hi: f64,
    },
    /// A batch input row is malformed or its pose is refused.
    #[error("{}: line {line}: {why}", path.display())]
    Row {
        /// The input file.
        path: PathBuf,
        /// 1-based line number (header = line 1).
        line: usize,
        /// What is wrong.
        why: String,
    },
    /// A batch file could not be read or written.
    #[error("{}: {why}", path.display())]
    File {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        why: String,
    },
    /// The net produced a NaN or infinite tension.
    #[error("the net's output for tendon {tendon} is {value}, not a finite tension")]
    NonFiniteOutput {
        /// Tendon index.
        tendon: usize,
        /// The value.
        value: f64,
    },
}

/// The tensions for one pose.
#[derive(Clone, Debug, PartialEq)]
pub struct IkAnswer {
    /// The command stage's tensions for the net's output, in the robot's
    /// limits [τ_min, τ_max], N: what the MCU would command.
    pub tensions: Vec<f64>,
    /// The net's output, N (tensions up to co-contraction).
    pub raw: Vec<f64>,
    /// Pose columns outside the trained range (only with extrapolation allowed).
    pub extrapolated: Vec<&'static str>,
    /// Tendons the stage had to clip by more than [`LIMIT_SLACK`] of their
    /// limit after the co-contraction shift: the net asked for a bend the
    /// limits do not allow.
    pub beyond_limits: Vec<usize>,
}

/// Overshoot of a tendon's range, as a fraction of its limit, that the clip
/// absorbs without flagging: the net's own error near a range end (a few mN).
pub const LIMIT_SLACK: f64 = 0.01;

/// A `.tnet` net with the robot limits it answers within.
pub struct GuardedNet {
    net: Box<McuNet>,
    limits: TendonLimits,
    max_tension: Vec<f64>,
    allow_extrapolation: bool,
}

impl GuardedNet {
    /// Load the net at `model` for `robot`, refusing a net trained for
    /// another robot unless `allow_robot_mismatch`
    /// ([`super::check_model_robot`]). With `allow_extrapolation`, poses
    /// outside the trained ranges are answered (and listed in
    /// [`IkAnswer::extrapolated`]) instead of refused.
    pub fn load(
        model: &Path,
        robot: &Robot,
        allow_extrapolation: bool,
        allow_robot_mismatch: bool,
    ) -> Result<GuardedNet, IkError> {
        let (net, _) = load_for_robot(model, robot, allow_robot_mismatch)
            .map_err(|e| IkError::Model(e.to_string()))?;
        Self::new(net, robot, allow_extrapolation)
    }

    /// Wrap a decoded net for `robot`.
    pub fn new(
        net: Box<McuNet>,
        robot: &Robot,
        allow_extrapolation: bool,
    ) -> Result<GuardedNet, IkError> {
        let outputs = net.shape().outputs;
        if outputs != robot.n_tendons() {
            return Err(IkError::TendonCount {
                net: outputs,
                robot: robot.name.clone(),
                robot_tendons: robot.n_tendons(),
            });
        }
        let limits = limits_for(robot, 1.0)
            .map_err(|e| IkError::Model(format!("tension limits of robot {}: {e}", robot.name)))?;
        Ok(GuardedNet {
            net,
            limits,
            max_tension: robot.max_tensions(),
            allow_extrapolation,
        })
    }

    /// Tendons the net drives.
    pub fn tendons(&self) -> usize {
        self.max_tension.len()
    }

    /// Check and normalise `pose` (px, py, pz m; qw, qx, qy, qz): finite,
    /// unit quaternion renormalised with w ≥ 0.
    pub fn normalise(pose: &[f64; 7]) -> Result<[f64; 7], IkError> {
        for (&value, column) in pose.iter().zip(POSE_COLUMNS) {
            if !value.is_finite() {
                return Err(IkError::NotFinite { column, value });
            }
        }
        let norm = pose[3..].iter().map(|q| q * q).sum::<f64>().sqrt();
        if (norm - 1.0).abs() > UNIT_TOLERANCE {
            return Err(IkError::NotUnit { norm });
        }
        // q and −q are the same rotation; the dataset (and so the net) uses w ≥ 0.
        let sign = if pose[3] < 0.0 { -1.0 } else { 1.0 };
        let mut out = *pose;
        for q in &mut out[3..] {
            *q *= sign / norm;
        }
        Ok(out)
    }

    /// Tensions for `pose`: see the module documentation for the checks.
    pub fn solve(&self, pose: &[f64; 7]) -> Result<IkAnswer, IkError> {
        let pose = Self::normalise(pose)?;
        let mut extrapolated = Vec::new();
        let ranges = self.net.input_lo().iter().zip(self.net.input_hi());
        for ((&value, column), (&lo, &hi)) in pose.iter().zip(POSE_COLUMNS).zip(ranges) {
            let (lo, hi) = (f64::from(lo), f64::from(hi));
            let margin = RANGE_MARGIN * (hi - lo);
            if value < lo - margin || value > hi + margin {
                if !self.allow_extrapolation {
                    return Err(IkError::OutsideTrainedRange {
                        column,
                        value,
                        lo,
                        hi,
                    });
                }
                extrapolated.push(column);
            }
        }
        let raw: Vec<f64> = infer(&self.net, &pose).into_iter().map(f64::from).collect();
        if let Some((tendon, &value)) = raw.iter().enumerate().find(|(_, t)| !t.is_finite()) {
            return Err(IkError::NonFiniteOutput { tendon, value });
        }
        let tensions = command_for(&self.limits, &raw);
        // The shift keeps the bend; what the clip takes off after it changes it.
        let beyond_limits = clipped_by(&self.limits, &raw)
            .iter()
            .zip(&self.max_tension)
            .enumerate()
            .filter(|(_, (&cut, &max))| cut > LIMIT_SLACK * max)
            .map(|(k, _)| k)
            .collect();
        Ok(IkAnswer {
            tensions,
            raw,
            extrapolated,
            beyond_limits,
        })
    }
}

/// What a batch run did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BatchSummary {
    /// Rows answered.
    pub rows: usize,
    /// Rows where the net asked for a tension beyond a limit (clipped after the co-contraction shift).
    pub beyond_limits: usize,
    /// Rows outside the trained ranges (answered: extrapolation allowed).
    pub extrapolated: usize,
}

/// A pose CSV opened for reading: the reader (lines capped: an endless
/// input such as `/dev/zero` fails at once) and where its pose columns
/// (px, py, pz, qw, qx, qy, qz) are. Shared by the net's and the exact IK's
/// batch readers.
pub(crate) type PoseCsv = csv::Reader<crate::fsutil::LineCapped<Box<dyn std::io::Read + Send>>>;

/// Open `input` and find its pose columns.
pub(crate) fn open_pose_csv(input: &Path) -> Result<(PoseCsv, Vec<usize>), IkError> {
    let file_error = |why: String| IkError::File {
        path: input.to_path_buf(),
        why,
    };
    let mut reader =
        csv::ReaderBuilder::new()
            .has_headers(true)
            .from_reader(crate::fsutil::LineCapped::new(
                crate::fsutil::open_input(input).map_err(|e| file_error(e.to_string()))?,
            ));
    let header: Vec<String> = reader
        .headers()
        .map_err(|e| file_error(format!("unreadable header: {e}")))?
        .iter()
        .map(|s| s.trim().to_string())
        .collect();
    let cols = POSE_COLUMNS
        .iter()
        .map(|c| {
            header.iter().position(|h| h == c).ok_or_else(|| {
                file_error(format!("missing column {c} (need px,py,pz,qw,qx,qy,qz)"))
            })
        })
        .collect::<Result<_, _>>()?;
    Ok((reader, cols))
}

/// The poses of the CSV at `input` (columns px, py, pz, qw, qx, qy, qz;
/// others ignored), in file order; the first unreadable row fails it,
/// naming its line (header = line 1).
pub fn read_poses(input: &Path) -> Result<Vec<[f64; 7]>, IkError> {
    let (mut reader, cols) = open_pose_csv(input)?;
    let mut poses = Vec::new();
    for (i, record) in reader.records().enumerate() {
        let row_error = |why: String| IkError::Row {
            path: input.to_path_buf(),
            line: i + 2,
            why,
        };
        let record = record.map_err(|e| row_error(e.to_string()))?;
        poses.push(pose_of_record(&record, &cols).map_err(row_error)?);
    }
    Ok(poses)
}

/// The pose in a CSV `record` whose px, py, pz, qw, qx, qy, qz sit at
/// `cols` ([`open_pose_csv`]); the error names the column that is not a
/// number.
pub fn pose_of_record(record: &csv::StringRecord, cols: &[usize]) -> Result<[f64; 7], String> {
    let mut pose = [0.0; 7];
    for ((p, &c), name) in pose.iter_mut().zip(cols).zip(POSE_COLUMNS) {
        let text = record.get(c).unwrap_or("").trim();
        *p = text
            .parse::<f64>()
            .map_err(|_| format!("column {name}: {text:?} is not a number"))?;
    }
    Ok(pose)
}

/// Answer every pose of the CSV at `input` ([`read_poses`]) and write
/// `output` atomically: `t0..` (the command stage's, N) then `raw_t0..` (the net's
/// output, N), one row per input row. A refused row fails the whole batch,
/// naming its line; nothing is written then.
pub fn solve_csv(
    ik: &GuardedNet,
    input: &Path,
    output: &Path,
    to_base: &crate::robot::RigidMap,
) -> Result<BatchSummary, IkError> {
    let file_error = |path: &Path, why: String| IkError::File {
        path: path.to_path_buf(),
        why,
    };
    if crate::dataset::disk::same_file(input, output) {
        return Err(file_error(
            output,
            "the output would overwrite the input; choose another --output".into(),
        ));
    }
    let mut answers = Vec::new();
    let mut summary = BatchSummary::default();
    for (i, pose) in read_poses(input)?.iter().enumerate() {
        let answer = ik.solve(&to_base.pose(*pose)).map_err(|e| IkError::Row {
            path: input.to_path_buf(),
            line: i + 2,
            why: e.to_string(),
        })?;
        summary.rows += 1;
        summary.beyond_limits += usize::from(!answer.beyond_limits.is_empty());
        summary.extrapolated += usize::from(!answer.extrapolated.is_empty());
        answers.push(answer);
    }
    let n = ik.tendons();
    crate::fsutil::write_atomic_with(output, |w| {
        let head: Vec<String> = (0..n)
            .map(|i| format!("t{i}"))
            .chain((0..n).map(|i| format!("raw_t{i}")))
            .collect();
        writeln!(w, "{}", head.join(","))?;
        for a in &answers {
            let cells: Vec<String> = a
                .tensions
                .iter()
                .chain(&a.raw)
                .map(f64::to_string)
                .collect();
            writeln!(w, "{}", cells.join(","))?;
        }
        Ok(())
    })
    .map_err(|e| file_error(output, e.to_string()))?;
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn answers_are_the_command_stage_of_the_raw_output_and_in_range() {
        // The firmware's built-in net for the seed robot, asked for poses over
        // its training box and 30 % beyond (extrapolation allowed), where
        // the raw output leaves [min, max] and the stage must shift and clip.
        let robot = crate::robot::repo_robot("seed-4t.toml");
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let ik = GuardedNet::load(
            &root.join("firmware/vectors/default.tnet"),
            &robot,
            true,
            false,
        )
        .unwrap();
        let limits = limits_for(&robot, 1.0).unwrap();
        let (min, max) = (robot.min_tensions(), robot.max_tensions());
        let (lo, hi) = (ik.net.input_lo().to_vec(), ik.net.input_hi().to_vec());
        let (mut out_of_range, mut clipped) = (0, 0);
        for i in 0..400 {
            let at = |c: usize, k: usize| {
                let f = ((i * (2 * c + 3) + k) % 23) as f64 / 22.0 * 1.6 - 0.3;
                f64::from(lo[c]) + f * f64::from(hi[c] - lo[c])
            };
            let mut pose: [f64; 7] = std::array::from_fn(|c| at(c, i / 23));
            let norm = pose[3..].iter().map(|q| q * q).sum::<f64>().sqrt();
            pose[3..].iter_mut().for_each(|q| *q /= norm);
            let a = ik.solve(&pose).unwrap();
            assert_eq!(a.tensions, command_for(&limits, &a.raw), "{pose:?}");
            for (k, t) in a.tensions.iter().enumerate() {
                assert!((min[k]..=max[k]).contains(t), "tendon {k}: {t} N");
            }
            out_of_range += usize::from(
                a.raw
                    .iter()
                    .zip(&min)
                    .zip(&max)
                    .any(|((r, lo), hi)| r < lo || r > hi),
            );
            clipped += usize::from(!a.beyond_limits.is_empty());
        }
        assert!(
            out_of_range > 20 && clipped > 0,
            "{out_of_range} rows out of range, {clipped} clipped"
        );
    }

    #[test]
    fn quaternion_sign_and_length_are_normalised_or_refused() {
        let p = GuardedNet::normalise(&[0.0, 0.0, 0.4, -0.6, 0.0, -0.8, 0.0]).unwrap();
        assert_eq!(&p[3..], &[0.6, 0.0, 0.8, 0.0]);
        let near = GuardedNet::normalise(&[0.0, 0.0, 0.4, 1.0005, 0.0, 0.0, 0.0]).unwrap();
        assert_eq!(near[3], 1.0);
        for bad in [
            [0.0, 0.0, 0.4, 0.0, 0.0, 0.0, 0.0],
            [0.0, 0.0, 0.4, 0.99, -0.05, 0.1, 0.0],
        ] {
            assert!(matches!(
                GuardedNet::normalise(&bad),
                Err(IkError::NotUnit { .. })
            ));
        }
        let e = GuardedNet::normalise(&[1e39 * 1e300, 0.0, 0.4, 1.0, 0.0, 0.0, 0.0]).unwrap_err();
        assert!(e.to_string().contains("px"), "{e}");
    }
}

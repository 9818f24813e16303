//! The robot a training run is for (`docs/design.md` §3.3, §5.1): the
//! dataset's sidecar records the robot file it was generated with (its
//! path as typed and the SHA-256 of its bytes). `tendril train` trains for
//! that robot and no other: a `--robot` whose bytes are not the recorded
//! ones, a recorded path that does not resolve, or a recorded file that has
//! changed since is refused (`--allow-robot-mismatch` turns the first and
//! last into warnings), never replaced by the built-in robot in silence.

use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

use super::error::TrainError;
use crate::dataset::{Dataset, Sidecar};
use crate::learn::targets::Targets;
use crate::robot::{Robot, DEFAULT_ROBOT};

/// The robot a training run on `data` (read from the file `data_file`) is
/// for, and the targets it implies.
#[derive(Clone, Debug)]
pub struct DataRobot {
    /// The robot.
    pub robot: Robot,
    /// Its file: `--robot` when given, else the robot file the dataset's
    /// sidecar records (a dataset without a sidecar needs `--robot`).
    pub path: PathBuf,
    /// [`Targets::for_dataset`] of the robot and the dataset's sidecar.
    pub targets: Targets,
}

fn bad(why: String) -> TrainError {
    TrainError::BadInput(why)
}

fn sha256_hex(text: &str) -> String {
    hex_of(&Sha256::digest(text.as_bytes()))
}

/// First 12 hex digits, for messages.
fn short(hex: &str) -> &str {
    hex.get(..12).unwrap_or(hex)
}

/// Where a recorded robot path may be: as recorded (absolute, or relative
/// to the current directory, as `tendril generate` was given it), then
/// relative to the sidecar's directory (a dataset moved with its robot).
fn candidates(recorded: &Path, sidecar: &Path) -> Vec<PathBuf> {
    let mut out = vec![recorded.to_path_buf()];
    if recorded.is_relative() {
        let dir = sidecar.parent().unwrap_or(Path::new("."));
        let beside = dir.join(recorded);
        if !out.contains(&beside) {
            out.push(beside);
        }
    }
    out
}

/// The sidecar of `data_file`, if it has one (a sidecar that exists but
/// cannot be read is an error: it would silently change the targets).
fn sidecar_of(data_file: &Path) -> Result<Option<(PathBuf, Sidecar)>, TrainError> {
    let path = Sidecar::path_for(data_file);
    if !path.exists() {
        return Ok(None);
    }
    let side = Sidecar::read(&path).map_err(|e| bad(format!("dataset sidecar: {e}")))?;
    Ok(Some((path, side)))
}

/// The robot recorded in `side` (at `side_path`): the first candidate path
/// whose bytes hash to the recorded SHA-256 (the built-in default robot
/// counts for [`DEFAULT_ROBOT`]).
fn recorded_robot(
    side: &Sidecar,
    side_path: &Path,
    allow_mismatch: bool,
) -> Result<(Robot, PathBuf), TrainError> {
    let recorded = Path::new(&side.robot_file);
    let places = candidates(recorded, side_path);
    let mut changed = None;
    for place in &places {
        let builtin = side.robot_file == DEFAULT_ROBOT && !place.exists();
        if !(place.is_file() || builtin) {
            continue;
        }
        let (robot, text) =
            Robot::load_with_source(place).map_err(|e| bad(format!("the dataset's robot: {e}")))?;
        let sha = sha256_hex(&text);
        if same_robot(side, &robot, &sha) {
            return Ok((robot, place.clone()));
        }
        changed.get_or_insert((robot, place.clone(), sha));
    }
    let Some((robot, place, sha)) = changed else {
        let looked: Vec<String> = places.iter().map(|p| p.display().to_string()).collect();
        return Err(bad(format!(
            "{}: the dataset was generated with robot file {} (robot {}), which does not \
             exist (looked for {}); give that robot with --robot",
            side_path.display(),
            side.robot_file,
            side.robot_name,
            looked.join(" and ")
        )));
    };
    let what = format!(
        "robot file {} has changed since the dataset was generated: its SHA-256 is {}…, \
         the sidecar {} records {}…",
        place.display(),
        short(&sha),
        side_path.display(),
        short(&side.robot_sha256)
    );
    if !allow_mismatch {
        return Err(bad(format!(
            "{what}; give the robot the data was generated with (or --allow-robot-mismatch \
             to train for this one anyway)"
        )));
    }
    log::warn!("{what}: training for it anyway (--allow-robot-mismatch)");
    Ok((robot, place))
}

/// Whether `robot` (its file hashing to `sha`) is the robot `side` records:
/// the same file, or a file that describes the same robot (its
/// fingerprint; a comment or the layout may differ).
fn same_robot(side: &Sidecar, robot: &Robot, sha: &str) -> bool {
    sha == side.robot_sha256
        || (!side.robot_fingerprint.is_empty()
            && side.robot_fingerprint == hex_of(&robot.fingerprint()))
}

fn hex_of(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// See [`DataRobot`]; the robot's tendon count must be the dataset's, and
/// a `--robot` (`given`) must be the one the sidecar records (module docs).
pub fn robot_for_data(
    data: &Dataset,
    data_file: &Path,
    given: Option<&Path>,
    allow_mismatch: bool,
) -> Result<DataRobot, TrainError> {
    let sidecar = sidecar_of(data_file)?;
    let (robot, path) = match (given, &sidecar) {
        (Some(path), side) => {
            let (robot, text) = Robot::load_with_source(path)
                .map_err(|e| bad(format!("robot for the targets: {e}")))?;
            if let Some((side_path, side)) = side {
                let sha = sha256_hex(&text);
                if !same_robot(side, &robot, &sha) {
                    let what = format!(
                        "--robot {} (robot {}, SHA-256 {}…) is not the robot the dataset was \
                         generated with: {} records {} (robot {}, SHA-256 {}…)",
                        path.display(),
                        robot.name,
                        short(&sha),
                        side_path.display(),
                        side.robot_file,
                        side.robot_name,
                        short(&side.robot_sha256)
                    );
                    if !allow_mismatch {
                        return Err(bad(format!(
                            "{what}; give that robot (or --allow-robot-mismatch to train for \
                             this one anyway)"
                        )));
                    }
                    log::warn!("{what}: training for --robot anyway (--allow-robot-mismatch)");
                }
            }
            (robot, path.to_path_buf())
        }
        (None, Some((side_path, side))) => recorded_robot(side, side_path, allow_mismatch)?,
        (None, None) => {
            // Measured rows have no sidecar; guessing the robot would centre
            // the targets on another robot's co-contraction sets.
            return Err(bad(format!(
                "{} has no sidecar (measured rows?): give the robot the rows were measured on \
                 with --robot FILE (its tendon count and co-contraction sets)",
                data_file.display()
            )));
        }
    };
    if robot.n_tendons() != data.n_tendons {
        return Err(bad(format!(
            "robot {} ({}) has {} tendons but the dataset has {}: give its robot with --robot",
            robot.name,
            path.display(),
            robot.n_tendons(),
            data.n_tendons
        )));
    }
    let targets = Targets::for_dataset(&robot, sidecar.as_ref().map(|(_, s)| s));
    Ok(DataRobot {
        robot,
        path,
        targets,
    })
}

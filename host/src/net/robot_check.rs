//! Does a net know the robot it is given? (docs/design.md §5.1). A version-2
//! `.tnet` records the fingerprint and name of the robot it was trained for
//! ([`tendril_shared::Provenance`]); every consumer — `tendril ik`,
//! `evaluate`, `sim`, `controller`, the main job and the Python package —
//! calls [`check_model_robot`] with the robot it was given. A net paired
//! with another robot answers with tensions for the wrong rod (61 mm off at
//! the tip for a rod half as stiff, issue 31), so a mismatch is an error
//! unless the user asks for it; a version-1 net cannot be checked and says so.

use std::path::Path;

use tendril_shared::{McuNet, Provenance, TnetError};

use super::read::{decode, ReadError};
use crate::robot::fingerprint::short_hex;
use crate::robot::Robot;

/// How the user overrides a mismatch, for the error message: the CLI flag.
pub const CLI_OVERRIDE: &str = "--allow-robot-mismatch";

/// A net trained for another robot than the one given (boxed: errors
/// travel by value through every `Result` of the consumers).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(
    "{}: the net was trained for robot {} ({}), not for the given robot {} ({}): its \
     tensions would not reach the poses on this robot; give the robot it was trained for \
     (or {} to use it anyway)",
    .0.model, .0.net_robot, .0.net_hash, .0.robot, .0.robot_hash, .0.how
)]
pub struct RobotMismatch(pub Box<MismatchDetail>);

/// Both robots of a [`RobotMismatch`].
#[derive(Debug, Clone, PartialEq)]
pub struct MismatchDetail {
    /// The `.tnet` file.
    pub model: String,
    /// The robot name the net records.
    pub net_robot: String,
    /// The first hex digits of the fingerprint the net records.
    pub net_hash: String,
    /// The given robot's name.
    pub robot: String,
    /// The first hex digits of its fingerprint.
    pub robot_hash: String,
    /// How to override ([`CLI_OVERRIDE`], or the Python keyword).
    pub how: String,
}

/// What [`check_model_robot`] found when it did not refuse.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RobotCheck {
    /// The net records the given robot.
    Match,
    /// A version-1 net: no robot recorded (a warning was logged).
    Unrecorded,
    /// Another robot, allowed by the user (a warning was logged).
    AllowedMismatch,
}

/// Compare the robot a net records (`provenance`, `None` for version 1)
/// with `robot`. A mismatch is an error naming both robots and `how` to
/// override, or with `allow_mismatch` a warning; an unrecorded robot is a
/// warning. The one check every consumer calls.
pub fn check_model_robot(
    model: &Path,
    provenance: Option<&Provenance>,
    robot: &Robot,
    allow_mismatch: bool,
    how: &str,
) -> Result<RobotCheck, RobotMismatch> {
    let Some(p) = provenance else {
        log::warn!(
            "{}: the net does not record its robot (a version-1 .tnet); cannot check it \
             against robot {}",
            model.display(),
            robot.name
        );
        return Ok(RobotCheck::Unrecorded);
    };
    let fingerprint = robot.fingerprint();
    if p.robot_sha256 == fingerprint {
        return Ok(RobotCheck::Match);
    }
    let mismatch = MismatchDetail {
        model: model.display().to_string(),
        net_robot: p.robot_name().to_string(),
        net_hash: short_hex(&p.robot_sha256),
        robot: robot.name.clone(),
        robot_hash: short_hex(&fingerprint),
        how: how.to_string(),
    };
    if !allow_mismatch {
        return Err(RobotMismatch(Box::new(mismatch)));
    }
    log::warn!(
        "{}: the net was trained for robot {} ({}), not for robot {} ({}): used anyway \
         ({how}); expect tip errors",
        mismatch.model,
        mismatch.net_robot,
        mismatch.net_hash,
        mismatch.robot,
        mismatch.robot_hash
    );
    Ok(RobotCheck::AllowedMismatch)
}

/// Why a net could not be loaded for a robot.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// The file could not be read or decoded.
    #[error(transparent)]
    Read(#[from] ReadError),
    /// The net was trained for another robot.
    #[error(transparent)]
    Mismatch(#[from] RobotMismatch),
}

/// Decode `.tnet` bytes (every check of the format, CRC included) and
/// read their provenance block.
pub fn decode_with_provenance(
    bytes: &[u8],
) -> Result<(Box<McuNet>, Option<Provenance>), TnetError> {
    let net = decode(bytes)?;
    let provenance = tendril_shared::read_provenance(bytes)?;
    Ok((net, provenance))
}

/// Read and decode a `.tnet` file with its provenance; errors name the file.
pub fn read_model(path: &Path) -> Result<(Box<McuNet>, Option<Provenance>), ReadError> {
    let bytes = super::read::read_tnet_bytes(path)?;
    decode_with_provenance(&bytes).map_err(|cause| ReadError::Format {
        path: path.display().to_string(),
        cause,
    })
}

/// Read the net at `path` and [`check_model_robot`] it against `robot`
/// (the override named as the CLI flag).
pub fn load_for_robot(
    path: &Path,
    robot: &Robot,
    allow_mismatch: bool,
) -> Result<(Box<McuNet>, Option<Provenance>), ModelError> {
    let (net, provenance) = read_model(path)?;
    check_model_robot(
        path,
        provenance.as_ref(),
        robot,
        allow_mismatch,
        CLI_OVERRIDE,
    )?;
    Ok((net, provenance))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::repo_robot;

    #[test]
    fn a_net_for_another_robot_is_refused_unless_allowed() {
        let robot = repo_robot("seed-4t.toml");
        let mut soft = robot.clone();
        soft.youngs_modulus /= 2.0;
        let p = Provenance::new(robot.fingerprint(), &robot.name, None);
        let path = Path::new("m.tnet");
        assert_eq!(
            check_model_robot(path, Some(&p), &robot, false, CLI_OVERRIDE),
            Ok(RobotCheck::Match)
        );
        let e = check_model_robot(path, Some(&p), &soft, false, CLI_OVERRIDE).unwrap_err();
        let text = e.to_string();
        for part in [
            "m.tnet",
            "seed-4t",
            &robot.short_fingerprint(),
            &soft.short_fingerprint(),
            "--allow-robot-mismatch",
        ] {
            assert!(text.contains(part), "{part} missing from: {text}");
        }
        assert_eq!(
            check_model_robot(path, Some(&p), &soft, true, CLI_OVERRIDE),
            Ok(RobotCheck::AllowedMismatch)
        );
        assert_eq!(
            check_model_robot(path, None, &soft, false, CLI_OVERRIDE),
            Ok(RobotCheck::Unrecorded)
        );
    }
}

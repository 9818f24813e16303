//! The provenance block of a version-2 `.tnet` (docs/design.md §5.1): which
//! robot the net was trained for and which split the trainer held out, so
//! that every consumer can check the robot it is given against the one the
//! net knows, and `tendril evaluate --rows test` scores only rows the net
//! never saw.
//!
//! The block is fixed-size ([`PROVENANCE_LEN`] bytes, no varints), so the
//! length of a file stays a `const` function of its shape
//! ([`super::NetShape::encoded_len_v2`]). The firmware skips it: a net runs
//! the same whatever robot it names; the *host* checks the robot before it
//! sends a net anywhere.

use super::TnetError;

/// Bytes of the robot name field (UTF-8, zero-padded; longer names are cut
/// at a character boundary).
pub const NAME_LEN: usize = 32;

/// Bytes of the provenance block: fingerprint 32, name 32, flags 1, split
/// seed 8, test fraction 8.
pub const PROVENANCE_LEN: usize = 32 + NAME_LEN + 1 + 8 + 8;

/// Bit of the flags byte: the split fields are recorded.
const HAS_SPLIT: u8 = 1;

/// The held-out test split a trainer used (`tendril train --seed`,
/// `--test-fraction`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SplitRecord {
    /// Seed of the split.
    pub seed: u64,
    /// Test fraction, in (0, 1).
    pub test_fraction: f64,
}

/// Which robot a net was trained for, and on which split.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Provenance {
    /// SHA-256 of the robot's canonical serialisation (the host's
    /// `Robot::fingerprint`): the identity the consumers compare.
    pub robot_sha256: [u8; 32],
    /// The robot's name, UTF-8, zero-padded (for messages only).
    robot_name: [u8; NAME_LEN],
    /// The trainer's split, if it recorded one.
    pub split: Option<SplitRecord>,
}

impl Provenance {
    /// A provenance for the robot `name` with fingerprint `robot_sha256`.
    /// A name longer than [`NAME_LEN`] bytes is cut at a character boundary.
    pub fn new(robot_sha256: [u8; 32], name: &str, split: Option<SplitRecord>) -> Provenance {
        let mut cut = name.len().min(NAME_LEN);
        while !name.is_char_boundary(cut) {
            cut -= 1;
        }
        let mut robot_name = [0u8; NAME_LEN];
        if let (Some(dst), Some(src)) = (robot_name.get_mut(..cut), name.as_bytes().get(..cut)) {
            dst.copy_from_slice(src);
        }
        Provenance {
            robot_sha256,
            robot_name,
            split,
        }
    }

    /// The robot's name as recorded (possibly cut, see [`Provenance::new`]).
    pub fn robot_name(&self) -> &str {
        let end = self
            .robot_name
            .iter()
            .position(|&b| b == 0)
            .unwrap_or(NAME_LEN);
        let bytes = self.robot_name.get(..end).unwrap_or(&[]);
        core::str::from_utf8(bytes).unwrap_or("")
    }

    /// The block's bytes, in file order.
    pub(crate) fn to_bytes(self) -> [u8; PROVENANCE_LEN] {
        let mut out = [0u8; PROVENANCE_LEN];
        let (seed, fraction, flags) = match self.split {
            Some(s) => (s.seed, s.test_fraction, HAS_SPLIT),
            None => (0, 0.0, 0),
        };
        let parts: [&[u8]; 5] = [
            &self.robot_sha256,
            &self.robot_name,
            &[flags],
            &seed.to_le_bytes(),
            &fraction.to_le_bytes(),
        ];
        let mut at = 0;
        for part in parts {
            if let Some(dst) = out.get_mut(at..at + part.len()) {
                dst.copy_from_slice(part);
            }
            at += part.len();
        }
        out
    }

    /// Parse and check a block ([`PROVENANCE_LEN`] bytes): known flags, a
    /// UTF-8 name, a test fraction in (0, 1) when recorded.
    pub fn parse(bytes: &[u8]) -> Result<Provenance, TnetError> {
        let bytes: &[u8; PROVENANCE_LEN] = bytes.try_into().map_err(|_| TnetError::Truncated)?;
        let (sha, rest) = bytes.split_at(32);
        let (name, rest) = rest.split_at(NAME_LEN);
        let (flags, rest) = rest.split_at(1);
        let (seed, fraction) = rest.split_at(8);
        let bad = TnetError::BadProvenance;
        let robot_sha256: [u8; 32] = sha.try_into().map_err(|_| bad)?;
        let robot_name: [u8; NAME_LEN] = name.try_into().map_err(|_| bad)?;
        let seed = u64::from_le_bytes(seed.try_into().map_err(|_| bad)?);
        let test_fraction = f64::from_le_bytes(fraction.try_into().map_err(|_| bad)?);
        let split = match flags {
            [0] => None,
            [HAS_SPLIT] if test_fraction > 0.0 && test_fraction < 1.0 => Some(SplitRecord {
                seed,
                test_fraction,
            }),
            _ => return Err(bad),
        };
        let end = robot_name.iter().position(|&b| b == 0).unwrap_or(NAME_LEN);
        let padding_clean = robot_name
            .get(end..)
            .is_some_and(|p| p.iter().all(|&b| b == 0));
        let name_ok = robot_name
            .get(..end)
            .is_some_and(|n| core::str::from_utf8(n).is_ok());
        if !(padding_clean && name_ok) {
            return Err(bad);
        }
        Ok(Provenance {
            robot_sha256,
            robot_name,
            split,
        })
    }
}

#[cfg(test)]
mod tests {
    use std::string::ToString;
    use std::vec;
    use std::vec::Vec;

    use super::*;
    use crate::crc32::crc32;
    use crate::tnet::{encode, encode_with, read_provenance, NetShape, TnetView, VERSION_1};
    use crate::{Activation, McuNet};

    /// A 7-2-4 net with its bytes as version 1 and version 2.
    fn blobs(p: &Provenance) -> (Vec<u8>, Vec<u8>) {
        let shape = NetShape {
            inputs: 7,
            hidden: 2,
            outputs: 4,
        };
        let hidden: Vec<f32> = (0..shape.hidden_weight_count())
            .map(|i| 0.01 * i as f32)
            .collect();
        let output: Vec<f32> = (0..shape.output_weight_count())
            .map(|i| -0.02 * i as f32)
            .collect();
        let (ilo, ihi, olo, ohi) = (vec![-1.0; 7], vec![1.0; 7], vec![0.0; 4], vec![10.0; 4]);
        let view = TnetView {
            shape,
            hidden_activation: Activation::SymmetricSigmoid,
            output_activation: Activation::Linear,
            input_lo: &ilo,
            input_hi: &ihi,
            output_lo: &olo,
            output_hi: &ohi,
            hidden_weights: &hidden,
            output_weights: &output,
        };
        let mut v1 = vec![0u8; shape.encoded_len()];
        assert_eq!(encode(&view, &mut v1).unwrap(), v1.len());
        let mut v2 = vec![0u8; shape.encoded_len_v2()];
        assert_eq!(encode_with(&view, Some(p), &mut v2).unwrap(), v2.len());
        (v1, v2)
    }

    /// Bytes before the block in a 7-2-4 file: magic, version, three
    /// one-byte dimensions, two activation codes.
    const HEADER: usize = 4 + 1 + 3 + 2;

    fn sample() -> Provenance {
        let split = SplitRecord {
            seed: 0x0123_4567_89ab_cdef,
            test_fraction: 0.03,
        };
        Provenance::new([0xa5; 32], "seed-4t", Some(split))
    }

    fn decode(bytes: &[u8]) -> Result<McuNet, TnetError> {
        let mut net = McuNet::empty();
        net.decode_into(bytes)?;
        Ok(net)
    }

    #[test]
    fn version_2_carries_its_provenance_and_decodes_to_the_same_net_as_version_1() {
        let p = sample();
        let (v1, v2) = blobs(&p);
        assert_eq!(v1[4], VERSION_1 as u8);
        assert_eq!(v2[4], super::super::VERSION as u8);
        assert_eq!(v2.len(), v1.len() + PROVENANCE_LEN);
        assert_eq!(read_provenance(&v1), Ok(None));
        let read = read_provenance(&v2).unwrap().unwrap();
        assert_eq!(read, p);
        assert_eq!(read.robot_name(), "seed-4t");
        // The weights are the same whichever version carries them.
        assert_eq!(decode(&v1).unwrap(), decode(&v2).unwrap());
    }

    #[test]
    fn the_incremental_check_accepts_version_2() {
        let (_, v2) = blobs(&sample());
        let mut job = crate::CheckJob::<
            { crate::POSE_DIM },
            { crate::MAX_HIDDEN },
            { crate::MAX_TENDONS },
            { crate::MAX_WEIGHTS },
        >::new(&v2);
        let verdict = loop {
            if let core::task::Poll::Ready(v) = job.advance(64) {
                break v;
            }
        };
        assert!(verdict.is_ok(), "{verdict:?}");
    }

    #[test]
    fn a_flipped_provenance_byte_is_caught_by_the_crc() {
        let (_, v2) = blobs(&sample());
        // Every byte of the block (after the 10-byte header): fingerprint,
        // name, flags, seed, fraction.
        for at in HEADER..HEADER + PROVENANCE_LEN {
            let mut bad = v2.clone();
            bad[at] ^= 0x10;
            assert!(
                matches!(decode(&bad), Err(TnetError::CrcMismatch { .. })),
                "byte {at}"
            );
        }
    }

    #[test]
    fn a_malformed_block_with_a_valid_crc_is_refused_by_the_provenance_reader() {
        let (_, v2) = blobs(&sample());
        let flags_at = HEADER + 32 + NAME_LEN;
        let mut bad = v2.clone();
        bad[flags_at] = 0x80;
        let n = bad.len() - 4;
        let crc = crc32(&bad[..n]);
        bad[n..].copy_from_slice(&crc.to_le_bytes());
        // The firmware runs it (it skips the block); the host refuses to trust it.
        assert!(decode(&bad).is_ok());
        assert_eq!(read_provenance(&bad), Err(TnetError::BadProvenance));
    }

    #[cfg(feature = "std")]
    #[test]
    fn stamping_a_version_1_file_gives_the_encoders_version_2() {
        let p = sample();
        let (v1, v2) = blobs(&p);
        assert_eq!(crate::tnet::stamp_provenance(&v1, &p).unwrap(), v2);
        let mut bad = v1.clone();
        bad[20] ^= 1;
        assert!(matches!(
            crate::tnet::stamp_provenance(&bad, &p),
            Err(TnetError::CrcMismatch { .. })
        ));
        assert!(crate::tnet::stamp_provenance(&v2, &p).is_err());
    }

    #[test]
    fn long_names_are_cut_at_a_character_boundary() {
        let name = "é".repeat(20); // 40 bytes
        let p = Provenance::new([0; 32], &name, None);
        assert_eq!(p.robot_name(), "é".repeat(16));
        let parsed = Provenance::parse(&p.to_bytes()).unwrap();
        assert_eq!(parsed, p);
    }

    #[test]
    fn an_unknown_version_names_both_readable_ones() {
        let (v1, _) = blobs(&sample());
        let mut bad = v1.clone();
        bad[4] = 3;
        let e = decode(&bad).unwrap_err();
        assert_eq!(e, TnetError::UnsupportedVersion { found: 3 });
        assert!(e.to_string().contains("versions 1 and 2"), "{e}");
    }
}

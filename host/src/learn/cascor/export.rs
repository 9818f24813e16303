//! Writing the trained net as a `.tnet` weight file (`docs/design.md` §5.1)
//! through the `tendril-shared` encoder, so every file the trainer writes
//! is one the firmware's decoder accepts. Reading and running a `.tnet` is
//! [`crate::net`]'s job.

use std::path::Path;

use tendril_shared::{Activation, NetShape, Provenance, TnetError, TnetView};

use super::net::{GrowingNet, OutputKind};

/// Why a net could not be exported.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// The format rejected the net or the bytes.
    // The cause is part of the message and deliberately not a `source`:
    // error chains printed with `{:#}` would repeat it.
    #[error("{path}: {cause}")]
    Format {
        /// The file concerned (or "<memory>").
        path: String,
        /// What the format says.
        cause: TnetError,
    },
    /// Writing the file failed.
    #[error("{path}: {cause}")]
    Io {
        /// The file concerned.
        path: String,
        /// The I/O error.
        cause: std::io::Error,
    },
    /// Normalisation ranges that disagree with the net's shape.
    #[error("{0}")]
    Ranges(String),
}

/// Min–max normalisation ranges the net was trained with (physical units).
#[derive(Clone, Debug, PartialEq)]
pub struct Ranges {
    /// Per-input lower bound (pose: m, unit quaternion).
    pub input_lo: Vec<f64>,
    /// Per-input upper bound.
    pub input_hi: Vec<f64>,
    /// Per-output lower bound (N).
    pub output_lo: Vec<f64>,
    /// Per-output upper bound (N).
    pub output_hi: Vec<f64>,
}

fn f32s(v: &[f64]) -> Vec<f32> {
    v.iter().map(|&x| x as f32).collect()
}

/// Encode `net` (normalised in → normalised out) with its `ranges` as
/// version-1 `.tnet` bytes (no robot recorded).
pub fn to_bytes(net: &GrowingNet, ranges: &Ranges) -> Result<Vec<u8>, ExportError> {
    to_bytes_with(net, ranges, None)
}

/// Encode `net` with its `ranges` and, when given, the robot and split it
/// was trained for: version 2, which every consumer checks against the
/// robot it is given (`docs/design.md` §5.1).
pub fn to_bytes_with(
    net: &GrowingNet,
    ranges: &Ranges,
    provenance: Option<&Provenance>,
) -> Result<Vec<u8>, ExportError> {
    if ranges.input_lo.len() != net.n_inputs
        || ranges.input_hi.len() != net.n_inputs
        || ranges.output_lo.len() != net.n_outputs
        || ranges.output_hi.len() != net.n_outputs
    {
        return Err(ExportError::Ranges(format!(
            "net is {}→{} but ranges have {}/{} inputs and {}/{} outputs",
            net.n_inputs,
            net.n_outputs,
            ranges.input_lo.len(),
            ranges.input_hi.len(),
            ranges.output_lo.len(),
            ranges.output_hi.len()
        )));
    }
    let hidden: Vec<f32> = net
        .hidden
        .iter()
        .flat_map(|w| w.iter().map(|&x| x as f32))
        .collect();
    let outputs: Vec<f32> = net
        .outputs
        .iter()
        .flat_map(|w| w.iter().map(|&x| x as f32))
        .collect();
    let (ilo, ihi, olo, ohi) = (
        f32s(&ranges.input_lo),
        f32s(&ranges.input_hi),
        f32s(&ranges.output_lo),
        f32s(&ranges.output_hi),
    );
    let view = TnetView {
        shape: NetShape {
            inputs: net.n_inputs,
            hidden: net.n_hidden(),
            outputs: net.n_outputs,
        },
        hidden_activation: Activation::SymmetricSigmoid,
        output_activation: match net.output_kind {
            OutputKind::Linear => Activation::Linear,
            OutputKind::Sigmoid => Activation::Sigmoid,
        },
        input_lo: &ilo,
        input_hi: &ihi,
        output_lo: &olo,
        output_hi: &ohi,
        hidden_weights: &hidden,
        output_weights: &outputs,
    };
    tendril_shared::encode_to_vec_with(&view, provenance).map_err(|cause| ExportError::Format {
        path: "<memory>".into(),
        cause,
    })
}

/// Write `net` with `ranges` to `path` atomically (version 1).
pub fn write_tnet(path: &Path, net: &GrowingNet, ranges: &Ranges) -> Result<(), ExportError> {
    write_tnet_with(path, net, ranges, None)
}

/// Write `net` with `ranges` and `provenance` ([`to_bytes_with`]) to
/// `path` atomically.
pub fn write_tnet_with(
    path: &Path,
    net: &GrowingNet,
    ranges: &Ranges,
    provenance: Option<&Provenance>,
) -> Result<(), ExportError> {
    let bytes = to_bytes_with(net, ranges, provenance).map_err(|e| match e {
        ExportError::Format { cause, .. } => ExportError::Format {
            path: path.display().to_string(),
            cause,
        },
        other => other,
    })?;
    crate::fsutil::write_atomic(path, &bytes).map_err(|cause| ExportError::Io {
        path: path.display().to_string(),
        cause,
    })
}

#[cfg(test)]
mod tests {
    use nalgebra::DMatrix;

    use super::*;
    use crate::net::{decode, infer};

    fn small_net() -> (GrowingNet, Ranges) {
        let net = GrowingNet {
            n_inputs: 7,
            n_outputs: 2,
            hidden: vec![
                vec![0.1, 0.5, -0.3, 0.2, 0.1, -0.4, 0.3, 0.05],
                vec![-0.2, 0.4, 0.9, 1.5, -0.1, 0.2, 0.3, -0.6, 2.0],
            ],
            outputs: vec![
                vec![0.3, -0.7, 0.2, 1.1, -0.6, 0.4, 0.1, 0.2, 0.9, -1.2],
                vec![0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0],
            ],
            output_kind: OutputKind::Linear,
        };
        let ranges = Ranges {
            input_lo: vec![-0.1, -0.1, 0.2, 0.8, -0.3, -0.3, -0.01],
            input_hi: vec![0.1, 0.1, 0.4, 1.0, 0.3, 0.3, 0.01],
            output_lo: vec![0.0, 0.0],
            output_hi: vec![10.0, 8.0],
        };
        (net, ranges)
    }

    #[test]
    fn decoded_net_matches_the_f64_net_to_f32_precision() {
        let (net, ranges) = small_net();
        let bytes = to_bytes(&net, &ranges).unwrap();
        let dec = decode(&bytes).unwrap();
        assert_eq!(dec.shape().hidden, 2);
        let pose = [0.03, -0.02, 0.35, 0.95, 0.1, -0.2, 0.001];
        let y32 = infer(&dec, &pose);
        let xn = DMatrix::from_fn(1, 7, |_, c| {
            (pose[c] - ranges.input_lo[c]) / (ranges.input_hi[c] - ranges.input_lo[c])
        });
        let y64 = net.predict(&xn);
        for o in 0..2 {
            let y = ranges.output_lo[o] + y64[(0, o)] * (ranges.output_hi[o] - ranges.output_lo[o]);
            assert!(
                (f64::from(y32[o]) - y).abs() < 1e-4 * (1.0 + y.abs()),
                "{o}: {} vs {y}",
                y32[o]
            );
        }
    }

    #[test]
    fn the_robot_and_split_go_into_the_file() {
        let (net, ranges) = small_net();
        let split = tendril_shared::SplitRecord {
            seed: 7,
            test_fraction: 0.05,
        };
        let p = Provenance::new([3; 32], "two-tendon", Some(split));
        let bytes = to_bytes_with(&net, &ranges, Some(&p)).unwrap();
        let (dec, read) = crate::net::decode_with_provenance(&bytes).unwrap();
        assert_eq!(read, Some(p));
        assert_eq!(*dec, *decode(&to_bytes(&net, &ranges).unwrap()).unwrap());
    }

    #[test]
    fn mismatched_ranges_are_refused() {
        let (net, mut ranges) = small_net();
        ranges.output_hi.pop();
        let e = to_bytes(&net, &ranges).unwrap_err().to_string();
        assert!(e.contains("ranges"), "{e}");
    }
}

//! Running a decoded `.tnet` net on the host through the firmware's own f32
//! `infer`, so `tendril ik`, the evaluation and the MCU compute
//! bit-identical tensions from the same file (`docs/design.md` §5).

use nalgebra::DMatrix;
use tendril_shared::{McuNet, POSE_DIM};

/// Tensions (N) for one pose through the firmware's f32 inference.
pub fn infer(net: &McuNet, pose: &[f64; POSE_DIM]) -> Vec<f32> {
    let mut x = [0.0f32; POSE_DIM];
    for (d, s) in x.iter_mut().zip(pose) {
        *d = *s as f32;
    }
    let y = tendril_firmware::infer(net, &x);
    y[..net.shape().outputs].to_vec()
}

/// Batch inference: poses `n × 7` → tensions `n × outputs` (N), through the firmware's f32 code.
pub fn infer_batch(net: &McuNet, poses: &DMatrix<f64>) -> DMatrix<f64> {
    let no = net.shape().outputs;
    let mut out = DMatrix::zeros(poses.nrows(), no);
    let mut x = [0.0f32; POSE_DIM];
    for r in 0..poses.nrows() {
        for (c, d) in x.iter_mut().enumerate() {
            *d = if c < poses.ncols() {
                poses[(r, c)] as f32
            } else {
                0.0
            };
        }
        let y = tendril_firmware::infer(net, &x);
        for c in 0..no {
            out[(r, c)] = f64::from(y[c]);
        }
    }
    out
}

//! Running a decoded `.tnet` net on the host through the firmware's own f32
//! `infer`, so `tendril ik`, the evaluation and the MCU compute
//! bit-identical tensions from the same file (`docs/design.md` §5). The
//! batch runs through [`HostNet`], which computes the same bits faster.

use nalgebra::DMatrix;
use tendril_shared::{McuNet, TendonLimits, POSE_DIM};

use super::HostNet;

/// Tensions (N) for one pose through the firmware's f32 inference.
pub fn infer(net: &McuNet, pose: &[f64; POSE_DIM]) -> Vec<f32> {
    let mut x = [0.0f32; POSE_DIM];
    for (d, s) in x.iter_mut().zip(pose) {
        *d = *s as f32;
    }
    let y = tendril_firmware::infer(net, &x);
    y[..net.shape().outputs].to_vec()
}

/// The tensions the MCU commands for `pose` in a steady state: the net's
/// output through [`infer`], then the command stage
/// ([`crate::command_stage::command_for`]: the co-contraction shift, the
/// clip to `limits`).
pub fn steady_command(net: &McuNet, limits: &TendonLimits, pose: &[f64; POSE_DIM]) -> Vec<f64> {
    let raw: Vec<f64> = infer(net, pose).into_iter().map(f64::from).collect();
    crate::command_stage::command_for(limits, &raw)
}

/// Batch inference: poses `n × 7` → tensions `n × outputs` (N), through
/// [`HostNet`]: the firmware's arithmetic, bit for bit, several rows at a
/// time. Builds the [`HostNet`] each call; callers that run one net many
/// times keep a [`HostNet`] and call [`HostNet::infer_rows`] themselves.
pub fn infer_batch(net: &McuNet, poses: &DMatrix<f64>) -> DMatrix<f64> {
    let fast = HostNet::new(net);
    let no = fast.outputs();
    let x = pose_rows(poses);
    let mut y = vec![0.0f32; x.len() * no];
    fast.infer_rows(&x, &mut y);
    DMatrix::from_fn(x.len(), no, |r, c| f64::from(y[r * no + c]))
}

/// The rows of `poses` (`n × ≤ 7`, f64) as f32 poses, missing columns 0:
/// the conversion the firmware's callers make.
pub fn pose_rows(poses: &DMatrix<f64>) -> Vec<[f32; POSE_DIM]> {
    (0..poses.nrows())
        .map(|r| {
            std::array::from_fn(|c| {
                if c < poses.ncols() {
                    poses[(r, c)] as f32
                } else {
                    0.0
                }
            })
        })
        .collect()
}

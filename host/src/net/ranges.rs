//! A decoded net's ranges in the form both host inference paths use
//! ([`super::fast`], bit-identical to the firmware, and [`super::relaxed`]).

use tendril_shared::{McuNet, MAX_TENDONS, POSE_DIM};

/// A net's input and output ranges as `lo` and width (inputs the net does
/// not have: 0 and 1, so they stay 0 as in the firmware's padding).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Ranges {
    pub(crate) in_lo: [f32; POSE_DIM],
    pub(crate) in_width: [f32; POSE_DIM],
    pub(crate) out_lo: [f32; MAX_TENDONS],
    pub(crate) out_width: [f32; MAX_TENDONS],
}

impl Ranges {
    pub(crate) fn of(net: &McuNet) -> Ranges {
        let mut r = Ranges {
            in_lo: [0.0; POSE_DIM],
            in_width: [1.0; POSE_DIM],
            out_lo: [0.0; MAX_TENDONS],
            out_width: [0.0; MAX_TENDONS],
        };
        for (i, (&lo, &hi)) in net.input_lo().iter().zip(net.input_hi()).enumerate() {
            r.in_lo[i] = lo;
            r.in_width[i] = hi - lo;
        }
        for (o, (&lo, &hi)) in net.output_lo().iter().zip(net.output_hi()).enumerate() {
            r.out_lo[o] = lo;
            r.out_width[o] = hi - lo;
        }
        r
    }
}

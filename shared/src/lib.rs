//! Types shared by the tendril host (training, IPC processes) and firmware
//! (inference, control step): message layouts, robot/tension limits and the
//! versioned `.tnet` weight format.
#![no_std]
#![deny(missing_docs)]
// Panic freedom is checked, not promised: the firmware links this crate.
#![cfg_attr(
    not(test),
    deny(
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::panic,
        clippy::indexing_slicing,
        clippy::unreachable,
        clippy::todo,
        clippy::unimplemented
    )
)]

#[cfg(any(feature = "std", test))]
extern crate std;

pub mod activation;
pub mod capacity;
pub mod counters;
pub mod crc32;
pub mod limits;
pub mod link;
pub mod messages;
pub mod net;
pub mod tnet;

pub use activation::Activation;
pub use capacity::{
    max_hidden_for, McuNet, MAX_HIDDEN, MAX_NET_FILE, MAX_TENDONS, MAX_WEIGHTS, POSE_DIM,
};
pub use limits::{CoContraction, LimitsError, TendonLimits};
pub use net::{weight_capacity, CascadeNet, CheckJob, Checked, Row};
pub use tnet::{
    encode, encode_with, encoded_len, encoded_len_with, read_provenance, NetHeader, NetShape,
    Provenance, SplitRecord, TnetError, TnetView,
};
#[cfg(feature = "std")]
pub use tnet::{encode_to_vec, encode_to_vec_with, stamp_provenance};

/// `encode` into a fresh vector, for this crate's tests (no `std` feature needed).
#[cfg(test)]
fn encode_to_vec_for_tests(net: &TnetView<'_>) -> std::vec::Vec<u8> {
    let mut buf = std::vec![0u8; encoded_len(net).expect("valid test net")];
    let n = encode(net, &mut buf).expect("buffer sized by encoded_len");
    buf.truncate(n);
    buf
}

//! The host ↔ MCU serial link: one frame layer used by both ends.
//!
//! # Frame format
//!
//! ```text
//! COBS( postcard(msg) ++ crc32_le(postcard(msg)) ) ++ 0x00
//! ```
//!
//! * **postcard** serialises the message (compact, `no_std`, no allocation).
//! * **CRC-32** (IEEE / zlib, [`crate::crc32`]; check value of `"123456789"`
//!   is `0xCBF43926`) of the postcard bytes, appended little-endian. postcard
//!   has no integrity check of its own: a flipped bit in a serial line usually
//!   still deserialises (a different number, a different enum variant), so
//!   without the CRC a corrupted setpoint would reach the control loop.
//! * **COBS** removes every `0x00` from payload and CRC, so `0x00` only ever
//!   means "end of frame". After any corruption — a lost byte, noise, a peer
//!   that resets mid-frame, a receiver that starts listening mid-stream — the
//!   receiver drops what it has at the next `0x00` and the frame after it
//!   decodes: resynchronisation costs at most the frame in flight. Overhead is
//!   one byte per 254 (see [`max_frame_len`]).
//!
//! A lone `0x00` (an empty frame) is ignored by the decoder, so a sender that
//! may have stopped mid-frame (after a reset, say) should send one `0x00`
//! first: otherwise its stale partial frame and its first new frame are read
//! as one frame and both are lost.
//!
//! A frame decodes only if its COBS is well formed, its CRC matches and its
//! payload is exactly one valid postcard `T` (no trailing bytes); each other
//! outcome is a [`FrameError`] and is counted in [`FrameCounters`].

mod frame;
pub mod wire;

pub use frame::{
    encode, encode_raw, max_frame_len, FrameCounters, FrameDecoder, FrameError, CRC_LEN,
};

#[cfg(test)]
mod tests;

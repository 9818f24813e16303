//! Frame encoder and streaming decoder (format: see [the module docs](super)).
//!
//! The checksum is this crate's own [`crate::crc32`] (CRC-32/ISO-HDLC, the
//! same polynomial as postcard's `use-crc` flavours with `CRC_32_ISO_HDLC`).
//! It is used instead of those flavours because (1) the firmware already
//! links its table for the `.tnet` check, while `use-crc` would pull in the
//! `crc` crate and a second table; (2) postcard's CRC deserialiser flavour
//! works on a complete buffer, whereas the decoder here runs the CRC
//! incrementally, one byte behind the COBS decoder, so a frame costs no
//! extra pass; and (3) its incremental `update`/`finish` API drops straight
//! into a serialiser [`Flavor`] that COBS-encodes as it goes, so encoding
//! is one postcard pass. (Not postcard's own `ser_flavors::Cobs`: it
//! indexes its slice and so links a panic path into the controller image.)
//!
//! Decoding uses the `cobs` crate's byte-at-a-time [`DecoderState`] (the
//! crate postcard's own COBS flavours are built on) rather than postcard's
//! `accumulator::CobsAccumulator`: the accumulator cannot tell a COBS error
//! from a deserialisation error, has no place for a CRC check between the
//! two, and after an overflow it starts a new frame in the middle of the
//! oversized one instead of dropping up to the next `0x00`.

use cobs::{DecodeResult, DecoderState};
use postcard::ser_flavors::Flavor;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::crc32::Crc32;

/// Bytes of CRC at the end of every decoded frame.
pub const CRC_LEN: usize = 4;

/// Longest frame (COBS overhead, CRC and terminating `0x00` included) that
/// [`encode`] writes for a postcard payload of `payload` bytes.
///
/// Use it to size encode buffers and [`FrameDecoder`]'s `N` at compile time:
/// `FrameDecoder<{ max_frame_len(64) }>` accepts every frame of a message whose
/// postcard encoding is at most 64 bytes. Saturates instead of overflowing.
pub const fn max_frame_len(payload: usize) -> usize {
    let data = payload.saturating_add(CRC_LEN);
    // COBS: one code byte per started run of 254 bytes, plus the final code
    // byte a run of exactly 254 leaves behind; then the terminator.
    data.saturating_add(data / 254)
        .saturating_add(1)
        .saturating_add(1)
}

/// Why a frame was not encoded or not decoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error, Serialize, Deserialize)]
pub enum FrameError {
    /// `encode`: the output buffer cannot hold the frame (see [`max_frame_len`]).
    #[error("frame does not fit the output buffer")]
    BufferTooSmall,
    /// `encode`: postcard cannot serialise the message (e.g. a sequence of
    /// unknown length).
    #[error("message cannot be serialised")]
    Serialize,
    /// More than `N` bytes arrived before the `0x00`; dropped up to it.
    #[error("frame longer than the decoder's buffer")]
    Oversized,
    /// The bytes before the `0x00` are not valid COBS.
    #[error("malformed COBS")]
    Cobs,
    /// The decoded frame is shorter than its CRC (counted as a CRC error: it
    /// cannot carry a matching checksum).
    #[error("frame shorter than its CRC")]
    TooShort,
    /// The CRC does not match the payload.
    #[error("CRC mismatch")]
    Crc,
    /// The CRC matches but the payload is not a valid postcard `T`.
    #[error("payload is not a valid message")]
    Decode,
    /// The payload holds a valid `T` followed by extra bytes (a sender with a
    /// different message layout: rejected rather than half-read).
    #[error("payload has bytes after the message")]
    TrailingBytes,
}

/// What a [`FrameDecoder`] has seen, for link health reporting.
///
/// Every counter saturates at `u32::MAX` instead of wrapping, so counters
/// never go down.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct FrameCounters {
    /// Frames decoded into a message.
    pub frames_ok: u32,
    /// Frames with a CRC mismatch, or too short to carry a CRC.
    pub crc_errors: u32,
    /// Frames with malformed COBS (including garbage ended by a `0x00`).
    pub cobs_errors: u32,
    /// Frames with a good CRC whose payload is not exactly one valid message.
    pub decode_errors: u32,
    /// Frames longer than the decoder's buffer.
    pub oversized: u32,
    /// Bytes of all rejected frames, their terminating `0x00` included.
    /// Lone `0x00` delimiters are neither dropped nor errors.
    pub bytes_dropped: u32,
}

impl FrameCounters {
    fn count(&mut self, err: FrameError, frame_bytes: usize) {
        let slot = match err {
            FrameError::Oversized => &mut self.oversized,
            FrameError::Cobs => &mut self.cobs_errors,
            FrameError::Crc | FrameError::TooShort => &mut self.crc_errors,
            FrameError::Decode | FrameError::TrailingBytes => &mut self.decode_errors,
            // Encoder-side errors never come out of the decoder.
            FrameError::BufferTooSmall | FrameError::Serialize => return,
        };
        *slot = slot.saturating_add(1);
        let n = u32::try_from(frame_bytes).unwrap_or(u32::MAX);
        self.bytes_dropped = self.bytes_dropped.saturating_add(n);
    }
}

/// COBS encoding on the fly into a slice, every write bounds-checked
/// (`get_mut`): postcard's own `Cobs<Slice>` flavour indexes its slice and
/// so links a panic path, which the controller image must not
/// (scripts/check-panic-free). Written here because it is ten lines.
struct CobsSlice<'a> {
    buf: &'a mut [u8],
    /// Where the current block's code byte goes.
    code_at: usize,
    /// The current block's code: 1 + its non-zero bytes so far.
    code: u8,
    /// Next free byte.
    at: usize,
}

impl<'a> CobsSlice<'a> {
    fn new(buf: &'a mut [u8]) -> Result<Self, FrameError> {
        if buf.is_empty() {
            return Err(FrameError::BufferTooSmall);
        }
        Ok(CobsSlice {
            buf,
            code_at: 0,
            code: 1,
            at: 1,
        })
    }

    fn put(&mut self, at: usize, b: u8) -> postcard::Result<()> {
        *self
            .buf
            .get_mut(at)
            .ok_or(postcard::Error::SerializeBufferFull)? = b;
        Ok(())
    }

    /// Close the current block and open the next at `at`.
    fn close_block(&mut self) -> postcard::Result<()> {
        self.put(self.code_at, self.code)?;
        self.code_at = self.at;
        self.code = 1;
        self.at += 1;
        Ok(())
    }

    fn push(&mut self, b: u8) -> postcard::Result<()> {
        if b == 0 {
            return self.close_block();
        }
        self.put(self.at, b)?;
        self.at += 1;
        self.code += 1;
        if self.code == 0xFF {
            self.close_block()?;
        }
        Ok(())
    }

    /// Write the last code byte and the terminating 0x00.
    fn finish(mut self) -> postcard::Result<&'a mut [u8]> {
        self.put(self.code_at, self.code)?;
        self.put(self.at, 0)?;
        let end = self.at + 1;
        self.buf
            .get_mut(..end)
            .ok_or(postcard::Error::SerializeBufferFull)
    }
}

/// A postcard serialiser flavour: CRC-32 of everything serialised, appended
/// little-endian at `finalize`, all COBS-encoded ([`CobsSlice`]).
struct CrcCobs<'a> {
    cobs: CobsSlice<'a>,
    crc: Crc32,
}

impl<'a> Flavor for CrcCobs<'a> {
    type Output = &'a mut [u8];

    fn try_push(&mut self, data: u8) -> postcard::Result<()> {
        self.crc.update(&[data]);
        self.cobs.push(data)
    }

    fn try_extend(&mut self, data: &[u8]) -> postcard::Result<()> {
        self.crc.update(data);
        data.iter().try_for_each(|&b| self.cobs.push(b))
    }

    fn finalize(mut self) -> postcard::Result<Self::Output> {
        for b in self.crc.finish().to_le_bytes() {
            self.cobs.push(b)?;
        }
        self.cobs.finish()
    }
}

fn crc_cobs(buf: &mut [u8]) -> Result<CrcCobs<'_>, FrameError> {
    Ok(CrcCobs {
        cobs: CobsSlice::new(buf)?,
        crc: Crc32::new(),
    })
}

fn ser_error(e: postcard::Error) -> FrameError {
    match e {
        postcard::Error::SerializeBufferFull => FrameError::BufferTooSmall,
        _ => FrameError::Serialize,
    }
}

/// Serialise `msg` into `buf` as one complete frame, terminating `0x00`
/// included; returns the frame (a prefix of `buf`).
///
/// A `buf` of [`max_frame_len`]`(postcard size of msg)` bytes always suffices.
pub fn encode<'a, T: Serialize + ?Sized>(
    msg: &T,
    buf: &'a mut [u8],
) -> Result<&'a [u8], FrameError> {
    let out = postcard::serialize_with_flavor(msg, crc_cobs(buf)?).map_err(ser_error)?;
    Ok(out)
}

/// Frame `payload` as it is (already serialised bytes): the same frame
/// [`encode`] writes for a message whose postcard encoding is `payload`.
pub fn encode_raw<'a>(payload: &[u8], buf: &'a mut [u8]) -> Result<&'a [u8], FrameError> {
    let mut flavor = crc_cobs(buf)?;
    flavor.try_extend(payload).map_err(ser_error)?;
    let out = flavor.finalize().map_err(ser_error)?;
    Ok(out)
}

/// The outcome of one complete frame at the COBS + CRC level.
struct RawFrame {
    /// Payload bytes (CRC excluded) at the start of the decoder's buffer.
    payload_len: usize,
    /// Encoded bytes of the frame, terminator included (for `bytes_dropped`).
    frame_bytes: usize,
}

/// Streaming frame decoder with an `N`-byte buffer: frames of up to `N`
/// encoded bytes (terminating `0x00` included) decode, longer ones are
/// dropped up to their `0x00` without growing anything.
///
/// Feed it the received bytes in any chunking, from any point in the stream:
/// garbage, truncated and corrupted frames end at the next `0x00`, are
/// reported once as a [`FrameError`], counted in [`FrameCounters`], and the
/// frame after them decodes. No allocation and no panics; each byte costs
/// O(1) (one COBS state step and one CRC table step), except a terminating
/// `0x00`, which also runs postcard over at most `N` bytes of payload.
pub struct FrameDecoder<const N: usize> {
    /// Decoded bytes of the current frame (payload then CRC).
    buf: [u8; N],
    /// Decoded bytes in `buf`.
    len: usize,
    /// Encoded (non-zero) bytes of the current frame so far; saturating.
    raw: usize,
    cobs: DecoderState,
    /// CRC of `buf[..len - CRC_LEN]`: it runs `CRC_LEN` bytes behind, so at
    /// the terminator it covers exactly the payload.
    crc: Crc32,
    /// The current frame outgrew `N`: drop bytes until the `0x00`.
    oversized: bool,
    counters: FrameCounters,
}

impl<const N: usize> Default for FrameDecoder<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> FrameDecoder<N> {
    /// An empty decoder (`const`, so it can live in a `static`).
    pub const fn new() -> Self {
        FrameDecoder {
            buf: [0; N],
            len: 0,
            raw: 0,
            cobs: DecoderState::Idle,
            crc: Crc32::new(),
            oversized: false,
            counters: FrameCounters {
                frames_ok: 0,
                crc_errors: 0,
                cobs_errors: 0,
                decode_errors: 0,
                oversized: 0,
                bytes_dropped: 0,
            },
        }
    }

    /// Counters since [`FrameDecoder::new`].
    pub fn counters(&self) -> FrameCounters {
        self.counters
    }

    /// Feed one byte. Returns `None` until a frame ends (a `0x00` after at
    /// least one other byte), then that frame's outcome: the message, or why
    /// it was dropped (already counted).
    pub fn push<T: DeserializeOwned>(&mut self, byte: u8) -> Option<Result<T, FrameError>> {
        let frame = match self.push_frame(byte)? {
            Ok(frame) => frame,
            Err(e) => return Some(Err(e)),
        };
        let payload = self.buf.get(..frame.payload_len).unwrap_or(&[]);
        let result = match postcard::take_from_bytes::<T>(payload) {
            Ok((msg, [])) => Ok(msg),
            Ok((_, _rest)) => Err(FrameError::TrailingBytes),
            Err(_) => Err(FrameError::Decode),
        };
        match &result {
            Ok(_) => self.counters.frames_ok = self.counters.frames_ok.saturating_add(1),
            Err(e) => self.counters.count(*e, frame.frame_bytes),
        }
        Some(result)
    }

    /// [`FrameDecoder::push`] without postcard: the payload bytes of a frame
    /// whose COBS and CRC are good (counted in `frames_ok`), valid until the
    /// next call.
    pub fn push_raw(&mut self, byte: u8) -> Option<Result<&[u8], FrameError>> {
        let frame = match self.push_frame(byte)? {
            Ok(frame) => frame,
            Err(e) => return Some(Err(e)),
        };
        self.counters.frames_ok = self.counters.frames_ok.saturating_add(1);
        Some(Ok(self.buf.get(..frame.payload_len).unwrap_or(&[])))
    }

    /// Feed a chunk of bytes, calling `on_msg` for each decoded message in
    /// order. Dropped frames are only counted (see [`FrameDecoder::counters`]).
    pub fn feed<T: DeserializeOwned>(&mut self, bytes: &[u8], mut on_msg: impl FnMut(T)) {
        for &b in bytes {
            if let Some(Ok(msg)) = self.push::<T>(b) {
                on_msg(msg);
            }
        }
    }

    /// COBS and CRC for one byte; counts COBS/CRC/size failures.
    fn push_frame(&mut self, byte: u8) -> Option<Result<RawFrame, FrameError>> {
        if byte != 0 {
            self.raw = self.raw.saturating_add(1);
            // A frame of `raw` bytes plus its terminator must fit in N.
            if self.oversized || self.raw >= N {
                self.oversized = true;
                return None;
            }
            // A non-zero byte never ends or breaks a COBS frame: only a 0x00
            // can come too early. `DataComplete`/`Err` cannot happen here.
            if let Ok(DecodeResult::DataContinue(b)) = self.cobs.feed(byte) {
                self.store(b);
            }
            return None;
        }
        if self.raw == 0 {
            // A lone delimiter (sync byte, or 0x00 0x00): no frame, no error.
            return None;
        }
        let frame_bytes = self.raw.saturating_add(1);
        let result = if self.oversized {
            Err(FrameError::Oversized)
        } else {
            match self.cobs.feed(0) {
                Ok(DecodeResult::DataComplete) => self.check_crc(frame_bytes),
                _ => Err(FrameError::Cobs),
            }
        };
        self.len = 0;
        self.raw = 0;
        self.cobs = DecoderState::Idle;
        self.crc = Crc32::new();
        self.oversized = false;
        if let Err(e) = result {
            self.counters.count(e, frame_bytes);
        }
        Some(result)
    }

    fn store(&mut self, b: u8) {
        // Decoded bytes never outnumber encoded ones, and `raw < N`: the slot
        // exists. Were it missing, the frame is treated as oversized.
        let Some(slot) = self.buf.get_mut(self.len) else {
            self.oversized = true;
            return;
        };
        *slot = b;
        if let Some(lagging) = self
            .len
            .checked_sub(CRC_LEN)
            .and_then(|i| self.buf.get(i..=i))
        {
            self.crc.update(lagging);
        }
        self.len += 1;
    }

    fn check_crc(&self, frame_bytes: usize) -> Result<RawFrame, FrameError> {
        let payload_len = self.len.checked_sub(CRC_LEN).ok_or(FrameError::TooShort)?;
        let sent = self
            .buf
            .get(payload_len..self.len)
            .and_then(|s| <[u8; CRC_LEN]>::try_from(s).ok())
            .ok_or(FrameError::TooShort)?;
        if u32::from_le_bytes(sent) != self.crc.finish() {
            return Err(FrameError::Crc);
        }
        Ok(RawFrame {
            payload_len,
            frame_bytes,
        })
    }
}

//! Test vectors for the MCU binary and its host twin: a little-endian binary
//! file of control-loop inputs, and [`run`], which drives inference and the
//! control step over them and prints every result as hex `f32` bits. The MCU
//! binary and the host parity test call the same [`run`], so their outputs
//! must match line for line.
//!
//! File layout (all little-endian): a 64-byte header
//! `magic "TVEC", version u32, count u32, n_tendons u32, max_tension f32,
//! slew_rate f32, watchdog_ns u64, max_dt_ns u64, ki f32, integral_limit f32,
//! feedback_timeout_ns u64, quaternion_tolerance f32, box_margin f32`, then
//! `count` records of 56 bytes:
//! `now_ns u64, flags u32, seq u32, pose 7×f32, tip_position 3×f32`.

use core::fmt;

use tendril_shared::{LimitsError, TendonLimits, MAX_TENDONS};

use crate::control::{
    control_step, ControlConfig, ControlSetpoint, ControlState, Feedback, IntegralConfig, SafeHold,
    Status, StepInput, POSE_DIM,
};
use crate::infer::infer;
use crate::swap::{NetStore, SwapError};

/// First four bytes of a vector file.
pub const MAGIC: [u8; 4] = *b"TVEC";
/// Vector format version.
pub const VERSION: u32 = 1;
/// Header size, bytes.
pub const HEADER_LEN: usize = 64;
/// Record size, bytes.
pub const RECORD_LEN: usize = 56;

/// Record flag: the record carries a setpoint.
pub const HAS_SETPOINT: u32 = 1 << 0;
/// Record flag: the record carries feedback.
pub const HAS_FEEDBACK: u32 = 1 << 1;
/// Record flag: before this step, offer a truncated copy of the update blob
/// (must be rejected; the running net stays).
pub const SWAP_BAD: u32 = 1 << 2;
/// Record flag: before this step, offer the update blob (must be accepted).
pub const SWAP_GOOD: u32 = 1 << 3;
/// Record flag: before this step, offer the update blob with a NaN weight
/// under a valid CRC (rejected only after the whole blob was read).
pub const SWAP_NAN: u32 = 1 << 4;
/// Record flag: before this step, go back to the built-in (flash) net.
pub const SWAP_REVERT: u32 = 1 << 5;

/// The hot-swap blobs a vector run offers (see the `SWAP_*` flags).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SwapBlobs<'a> {
    /// A valid update (`firmware/vectors/swap.tnet`).
    pub good: &'a [u8],
    /// The same with a NaN weight and a recomputed CRC
    /// (`firmware/vectors/swap_nan.tnet`).
    pub nan: &'a [u8],
}

/// The run configuration a vector file carries.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VecHeader {
    /// Number of records.
    pub count: u32,
    /// Tendons (must equal the net's outputs).
    pub n_tendons: u32,
    /// Max tension of every tendon, N.
    pub max_tension: f32,
    /// Slew rate of every tendon, N/s.
    pub slew_rate: f32,
    /// Watchdog silence, ns.
    pub watchdog_ns: u64,
    /// `dt` cap, ns.
    pub max_dt_ns: u64,
    /// Integral gain, 1/s.
    pub ki: f32,
    /// Integral bound, m.
    pub integral_limit: f32,
    /// Feedback timeout, ns.
    pub feedback_timeout_ns: u64,
    /// Quaternion norm tolerance.
    pub quaternion_tolerance: f32,
    /// Box margin.
    pub box_margin: f32,
}

/// One step's inputs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Record {
    /// Step time, ns.
    pub now_ns: u64,
    /// `HAS_SETPOINT | HAS_FEEDBACK | SWAP_*` bits.
    pub flags: u32,
    /// Setpoint sequence number.
    pub seq: u32,
    /// Setpoint pose.
    pub pose: [f32; POSE_DIM],
    /// Measured tip position.
    pub tip: [f32; 3],
}

/// A vector file that does not parse.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum VecError {
    /// Wrong magic or version.
    #[error("not a version-1 TVEC vector file")]
    BadHeader,
    /// Length disagrees with the record count.
    #[error("vector file length does not match its record count")]
    Length,
}

/// Why [`run`] stopped.
#[derive(Debug, PartialEq, Eq, thiserror::Error)]
pub enum RunError {
    /// The running net does not fit the vectors' robot.
    #[error("embedded net: {0}")]
    Net(#[from] SwapError),
    /// The vector file is malformed.
    #[error("vectors: {0}")]
    Vectors(#[from] VecError),
    /// The vector file's limits are invalid.
    #[error("vector limits: {0}")]
    Limits(#[from] LimitsError),
    /// The writer failed.
    #[error("output failed")]
    Fmt,
}

impl From<fmt::Error> for RunError {
    fn from(_: fmt::Error) -> Self {
        RunError::Fmt
    }
}

/// Little-endian reader over a byte slice that yields zeros past the end
/// (lengths are checked up front; this keeps it panic-free).
struct Le<'a>(&'a [u8]);

impl Le<'_> {
    fn bytes<const N: usize>(&mut self) -> [u8; N] {
        let mut b = [0u8; N];
        if let Some((head, rest)) = self.0.split_at_checked(N) {
            b.copy_from_slice(head);
            self.0 = rest;
        }
        b
    }
    fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.bytes())
    }
    fn u64(&mut self) -> u64 {
        u64::from_le_bytes(self.bytes())
    }
    fn f32(&mut self) -> f32 {
        f32::from_le_bytes(self.bytes())
    }
}

/// Little-endian writer; stops silently at the end of the buffer (callers
/// size it with `HEADER_LEN` / `RECORD_LEN`).
struct LeOut<'a>(&'a mut [u8]);

impl LeOut<'_> {
    fn put(&mut self, b: &[u8]) {
        let buf = core::mem::take(&mut self.0);
        if let Some((head, rest)) = buf.split_at_mut_checked(b.len()) {
            head.copy_from_slice(b);
            self.0 = rest;
        }
    }
}

impl VecHeader {
    /// Parse the header of `bytes`.
    pub fn parse(bytes: &[u8]) -> Result<VecHeader, VecError> {
        let head = bytes.get(..HEADER_LEN).ok_or(VecError::BadHeader)?;
        let mut r = Le(head);
        if r.bytes::<4>() != MAGIC || r.u32() != VERSION {
            return Err(VecError::BadHeader);
        }
        Ok(VecHeader {
            count: r.u32(),
            n_tendons: r.u32(),
            max_tension: r.f32(),
            slew_rate: r.f32(),
            watchdog_ns: r.u64(),
            max_dt_ns: r.u64(),
            ki: r.f32(),
            integral_limit: r.f32(),
            feedback_timeout_ns: r.u64(),
            quaternion_tolerance: r.f32(),
            box_margin: r.f32(),
        })
    }

    /// Write into `out[..HEADER_LEN]`.
    pub fn write(&self, out: &mut [u8; HEADER_LEN]) {
        let mut w = LeOut(out);
        w.put(&MAGIC);
        w.put(&VERSION.to_le_bytes());
        w.put(&self.count.to_le_bytes());
        w.put(&self.n_tendons.to_le_bytes());
        w.put(&self.max_tension.to_le_bytes());
        w.put(&self.slew_rate.to_le_bytes());
        w.put(&self.watchdog_ns.to_le_bytes());
        w.put(&self.max_dt_ns.to_le_bytes());
        w.put(&self.ki.to_le_bytes());
        w.put(&self.integral_limit.to_le_bytes());
        w.put(&self.feedback_timeout_ns.to_le_bytes());
        w.put(&self.quaternion_tolerance.to_le_bytes());
        w.put(&self.box_margin.to_le_bytes());
    }

    /// The control configuration this header describes.
    pub fn config(&self) -> Result<ControlConfig, LimitsError> {
        let limits =
            TendonLimits::uniform(self.n_tendons as usize, self.max_tension, self.slew_rate)?;
        let mut cfg = ControlConfig::new(limits);
        cfg.watchdog_ns = self.watchdog_ns;
        cfg.max_dt_ns = self.max_dt_ns;
        cfg.quaternion_tolerance = self.quaternion_tolerance;
        cfg.box_margin = self.box_margin;
        cfg.safe_hold = SafeHold::Freeze;
        cfg.integral = IntegralConfig {
            ki: self.ki,
            limit: self.integral_limit,
            feedback_timeout_ns: self.feedback_timeout_ns,
            window: f32::INFINITY,
            filter_tau_s: 0.0,
            map_gain: 0.0,
            map_scale: 1.0,
            map_limit: 0.0,
        };
        Ok(cfg)
    }
}

impl Record {
    fn parse(bytes: &[u8]) -> Record {
        let mut r = Le(bytes);
        let now_ns = r.u64();
        let flags = r.u32();
        let seq = r.u32();
        let mut pose = [0.0f32; POSE_DIM];
        for p in pose.iter_mut() {
            *p = r.f32();
        }
        let mut tip = [0.0f32; 3];
        for t in tip.iter_mut() {
            *t = r.f32();
        }
        Record {
            now_ns,
            flags,
            seq,
            pose,
            tip,
        }
    }

    /// Write into `out[..RECORD_LEN]`.
    pub fn write(&self, out: &mut [u8; RECORD_LEN]) {
        let mut w = LeOut(out);
        w.put(&self.now_ns.to_le_bytes());
        w.put(&self.flags.to_le_bytes());
        w.put(&self.seq.to_le_bytes());
        for p in &self.pose {
            w.put(&p.to_le_bytes());
        }
        for t in &self.tip {
            w.put(&t.to_le_bytes());
        }
    }
}

/// Parse a vector file: its header and an iterator over its records.
pub fn parse(bytes: &[u8]) -> Result<(VecHeader, impl Iterator<Item = Record> + '_), VecError> {
    let header = VecHeader::parse(bytes)?;
    let body = bytes.get(HEADER_LEN..).ok_or(VecError::Length)?;
    if body.len() != header.count as usize * RECORD_LEN {
        return Err(VecError::Length);
    }
    Ok((header, body.chunks_exact(RECORD_LEN).map(Record::parse)))
}

fn write_bits<W: fmt::Write>(out: &mut W, values: &[f32]) -> fmt::Result {
    for v in values {
        write!(out, " {:08x}", v.to_bits())?;
    }
    Ok(())
}

/// Totals of a [`run`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Summary {
    /// Steps run.
    pub steps: u32,
    /// Inferences printed.
    pub inferences: u32,
    /// OR of every step's status.
    pub status_union: u32,
}

/// Offer a blob to `store`, as a status bit.
fn offer<const H: usize, const OUT: usize, const W: usize, S>(
    store: &mut S,
    blob: &[u8],
    want: (usize, usize),
) -> Status
where
    S: NetStore<POSE_DIM, H, OUT, W>,
{
    match store.load(blob, want) {
        Ok(()) => Status::WEIGHTS_SWAPPED,
        Err(_) => Status::WEIGHTS_REJECTED,
    }
}

/// Run the vectors on `store`'s running net: first line
/// `net <inputs> <hidden> <outputs> <macs>`; then for each record apply the
/// `SWAP_*` flags (in the order bad, NaN, good, revert), print
/// `infer <i> <bits…>` for a finite setpoint pose (raw net output), run the
/// control step and print `step <i> <status> <bits…>`; last line
/// `done <steps>`.
pub fn run<const H: usize, const OUT: usize, const W: usize, S, Wr>(
    store: &mut S,
    swap: &SwapBlobs<'_>,
    vectors: &[u8],
    out: &mut Wr,
) -> Result<Summary, RunError>
where
    S: NetStore<POSE_DIM, H, OUT, W>,
    Wr: fmt::Write,
{
    let (header, records) = parse(vectors)?;
    let cfg = header.config()?;
    let n = cfg.limits.n_tendons();
    let want = (POSE_DIM, n);
    let s = store.active().shape();
    if (s.inputs, s.outputs) != want {
        return Err(RunError::Net(SwapError::ShapeMismatch {
            inputs: s.inputs,
            outputs: s.outputs,
            want_inputs: want.0,
            want_outputs: want.1,
        }));
    }
    writeln!(
        out,
        "net {} {} {} {}",
        s.inputs,
        s.hidden,
        s.outputs,
        s.macs()
    )?;
    let truncated = swap
        .good
        .get(..swap.good.len().saturating_sub(1))
        .unwrap_or(&[]);

    let mut state = ControlState::new(&cfg.limits, &[0.0; MAX_TENDONS], 0);
    let mut sum = Summary::default();
    for (i, rec) in records.enumerate() {
        let mut pending = Status::empty();
        if rec.flags & SWAP_BAD != 0 {
            pending |= offer(store, truncated, want);
        }
        if rec.flags & SWAP_NAN != 0 {
            pending |= offer(store, swap.nan, want);
        }
        if rec.flags & SWAP_GOOD != 0 {
            pending |= offer(store, swap.good, want);
        }
        if rec.flags & SWAP_REVERT != 0 && store.revert() {
            pending |= Status::WEIGHTS_SWAPPED;
        }
        let net = store.active();
        let has_sp = rec.flags & HAS_SETPOINT != 0;
        if has_sp && rec.pose.iter().all(|v| v.is_finite()) {
            let y = infer(net, &rec.pose);
            write!(out, "infer {i}")?;
            write_bits(out, y.get(..n).unwrap_or(&y))?;
            writeln!(out)?;
            sum.inferences += 1;
        }
        let input = StepInput {
            now_ns: rec.now_ns,
            setpoint: has_sp.then_some(ControlSetpoint {
                seq: u64::from(rec.seq),
                pose: rec.pose,
                tangent: None,
            }),
            feedback: (rec.flags & HAS_FEEDBACK != 0).then_some(Feedback {
                seq: i as u64 + 1,
                tip_position: rec.tip,
                // One sample per step: it stands for the step's own dt.
                interval_s: rec
                    .now_ns
                    .saturating_sub(state.last_step_ns)
                    .min(cfg.max_dt_ns) as f32
                    * 1e-9,
            }),
        };
        let (next, output) = control_step(&cfg, net, &state, &input);
        state = next;
        let status = output.status | pending;
        write!(out, "step {i} {:08x}", status.bits())?;
        write_bits(out, output.command.get(..n).unwrap_or(&output.command))?;
        writeln!(out)?;
        sum.steps += 1;
        sum.status_union |= status.bits();
    }
    writeln!(out, "done {}", sum.steps)?;
    Ok(sum)
}

#[cfg(test)]
mod tests {
    use std::vec::Vec;

    use crate::vectors::{self, Record, VecHeader};

    use crate::test_support::*;

    #[test]
    fn vector_header_and_records_round_trip() {
        let h = VecHeader {
            count: 2,
            n_tendons: 4,
            max_tension: 10.0,
            slew_rate: 200.0,
            watchdog_ns: 7,
            max_dt_ns: 8,
            ki: 0.5,
            integral_limit: 0.01,
            feedback_timeout_ns: 9,
            quaternion_tolerance: 0.02,
            box_margin: 0.03,
        };
        let r = Record {
            now_ns: 123,
            flags: vectors::HAS_SETPOINT,
            seq: 4,
            pose: mid_pose(),
            tip: [1.0, 2.0, 3.0],
        };
        let mut bytes = std::vec![0u8; vectors::HEADER_LEN + 2 * vectors::RECORD_LEN];
        h.write((&mut bytes[..vectors::HEADER_LEN]).try_into().unwrap());
        for k in 0..2 {
            let at = vectors::HEADER_LEN + k * vectors::RECORD_LEN;
            r.write(
                (&mut bytes[at..at + vectors::RECORD_LEN])
                    .try_into()
                    .unwrap(),
            );
        }
        let (h2, recs) = vectors::parse(&bytes).unwrap();
        assert_eq!(h2, h);
        let recs: Vec<Record> = recs.collect();
        assert_eq!(recs, std::vec![r, r]);
        assert!(vectors::parse(&bytes[..bytes.len() - 1]).is_err());
    }
}

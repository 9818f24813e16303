//! The tip tracker as a controller meets it (docs/design.md §6.2): it
//! samples the true tip at its own rate, adds positional and orientation
//! jitter, loses a fraction of its frames, and delivers each frame a
//! latency (itself jittered) after it was taken, in order. EM trackers
//! (NDI Aurora class) run at ≈ 40 Hz with ≈ 0.14 mm jitter; optical ones at
//! 60–400 Hz with 0.05–0.25 mm; stereo vision at 30–60 Hz, 20–50 ms late.

use std::collections::VecDeque;

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// A tracker's specification (a reality file's `[tracker]`).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrackerSpec {
    /// Frames per second, Hz.
    pub rate_hz: f64,
    /// Time from sampling to delivery, ms.
    #[serde(default)]
    pub latency_ms: f64,
    /// Standard deviation of the latency, ms (delivery stays in order).
    #[serde(default)]
    pub latency_jitter_ms: f64,
    /// Positional jitter: standard deviation per axis, mm.
    #[serde(default)]
    pub position_jitter_mm: f64,
    /// Orientation jitter: standard deviation of a small rotation about
    /// each axis, degrees.
    #[serde(default)]
    pub orientation_jitter_deg: f64,
    /// Fraction of frames lost, in [0, 1).
    #[serde(default)]
    pub dropout: f64,
}

impl TrackerSpec {
    /// The ideal plant's sensor: every millisecond, on time, 20 µm.
    pub const IDEAL: TrackerSpec = TrackerSpec {
        rate_hz: 1000.0,
        latency_ms: 0.0,
        latency_jitter_ms: 0.0,
        position_jitter_mm: 0.02,
        orientation_jitter_deg: 0.001,
        dropout: 0.0,
    };

    /// (field, problem) of the first value out of range.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        let check = |field: &'static str, v: f64, ok: bool, want: &str| {
            if v.is_finite() && ok {
                Ok(())
            } else {
                Err((field, format!("{v}: must be {want}")))
            }
        };
        let r = self.rate_hz;
        check(
            "rate_hz",
            r,
            (1.0..=10_000.0).contains(&r),
            "in [1, 10000] Hz",
        )?;
        let l = self.latency_ms;
        check(
            "latency_ms",
            l,
            (0.0..=500.0).contains(&l),
            "in [0, 500] ms",
        )?;
        let j = self.latency_jitter_ms;
        check(
            "latency_jitter_ms",
            j,
            (0.0..=100.0).contains(&j),
            "in [0, 100] ms",
        )?;
        let p = self.position_jitter_mm;
        check(
            "position_jitter_mm",
            p,
            (0.0..=10.0).contains(&p),
            "in [0, 10] mm",
        )?;
        let o = self.orientation_jitter_deg;
        check(
            "orientation_jitter_deg",
            o,
            (0.0..=10.0).contains(&o),
            "in [0, 10] degrees",
        )?;
        let d = self.dropout;
        check("dropout", d, (0.0..0.9).contains(&d), "in [0, 0.9)")
    }

    /// One line for reports.
    pub fn summary(&self) -> String {
        format!(
            "tracker {} Hz, {} ms late, {} mm jitter{}",
            self.rate_hz,
            self.latency_ms,
            self.position_jitter_mm,
            if self.dropout > 0.0 {
                format!(", {:.0} % dropped", self.dropout * 100.0)
            } else {
                String::new()
            }
        )
    }
}

/// One delivered frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    /// Frame number (1 for the first taken; lost frames leave gaps).
    pub seq: u32,
    /// When the tip was sampled, ns (the plant's clock).
    pub stamp_ns: u64,
    /// When it is delivered, ns.
    pub deliver_ns: u64,
    /// `px, py, pz` (m), `qw, qx, qy, qz` with the jitter.
    pub pose: [f64; 7],
}

/// The tracker: configured once, then [`Tracker::step`] at every plant step.
#[derive(Clone, Debug)]
pub struct Tracker {
    spec: TrackerSpec,
    period_ns: u64,
    next_sample_ns: Option<u64>,
    seq: u32,
    in_flight: VecDeque<Frame>,
    latest: Option<Frame>,
    /// Frames taken, delivered and lost so far.
    pub taken: u64,
    /// Frames delivered.
    pub delivered: u64,
    /// Frames lost (dropouts).
    pub lost: u64,
}

/// Frames in flight at most (a 500 ms latency at 400 Hz is 200).
const MAX_IN_FLIGHT: usize = 1024;

impl Tracker {
    /// A tracker as `spec` says (validated by the caller).
    pub fn new(spec: TrackerSpec) -> Tracker {
        Tracker {
            spec,
            period_ns: (1e9 / spec.rate_hz).round().max(1.0) as u64,
            next_sample_ns: None,
            seq: 0,
            in_flight: VecDeque::with_capacity(64),
            latest: None,
            taken: 0,
            delivered: 0,
            lost: 0,
        }
    }

    /// The specification.
    pub fn spec(&self) -> &TrackerSpec {
        &self.spec
    }

    /// At plant time `now_ns` with the true tip `truth`: take a frame if
    /// one is due (on the tracker's own grid), deliver those whose time has
    /// come. Returns whether a new frame was delivered.
    pub fn step(&mut self, now_ns: u64, truth: &[f64; 7], rng: &mut ChaCha8Rng) -> bool {
        let due = *self.next_sample_ns.get_or_insert(now_ns);
        if now_ns >= due {
            // On the tracker's grid; a stall longer than a frame skips the
            // frames it missed rather than taking them all at once.
            let behind = (now_ns - due) / self.period_ns;
            self.next_sample_ns = Some(due + (behind + 1) * self.period_ns);
            self.seq = self.seq.wrapping_add(1).max(1);
            self.taken += 1;
            if self.spec.dropout > 0.0 && rng.random::<f64>() < self.spec.dropout {
                self.lost += 1;
            } else {
                let latency_ms =
                    (self.spec.latency_ms + self.spec.latency_jitter_ms * gaussian(rng)).max(0.0);
                let mut deliver_ns = now_ns + (latency_ms * 1e6) as u64;
                // In order: a frame never overtakes the one before it.
                if let Some(last) = self.in_flight.back() {
                    deliver_ns = deliver_ns.max(last.deliver_ns);
                }
                let frame = Frame {
                    seq: self.seq,
                    stamp_ns: now_ns,
                    deliver_ns,
                    pose: self.jittered(truth, rng),
                };
                if self.in_flight.len() == MAX_IN_FLIGHT {
                    self.in_flight.pop_front();
                }
                self.in_flight.push_back(frame);
            }
        }
        let mut new = false;
        while self
            .in_flight
            .front()
            .is_some_and(|f| f.deliver_ns <= now_ns)
        {
            self.latest = self.in_flight.pop_front();
            self.delivered += 1;
            new = true;
        }
        new
    }

    /// The newest delivered frame.
    pub fn latest(&self) -> Option<&Frame> {
        self.latest.as_ref()
    }

    /// `truth` with the position jitter on each axis and a small random
    /// rotation (each axis's angle Gaussian) applied to the orientation.
    fn jittered(&self, truth: &[f64; 7], rng: &mut ChaCha8Rng) -> [f64; 7] {
        let mut m = *truth;
        let sd_p = self.spec.position_jitter_mm * 1e-3;
        if sd_p > 0.0 {
            for v in &mut m[..3] {
                *v += sd_p * gaussian(rng);
            }
        }
        let sd_o = self.spec.orientation_jitter_deg.to_radians();
        if sd_o > 0.0 {
            let a = [0; 3].map(|_| sd_o * gaussian(rng));
            let q = [m[3], m[4], m[5], m[6]];
            // q ⊗ exp(a/2), to first order in the small angle a.
            let d = [1.0, a[0] / 2.0, a[1] / 2.0, a[2] / 2.0];
            let p = [
                q[0] * d[0] - q[1] * d[1] - q[2] * d[2] - q[3] * d[3],
                q[0] * d[1] + q[1] * d[0] + q[2] * d[3] - q[3] * d[2],
                q[0] * d[2] - q[1] * d[3] + q[2] * d[0] + q[3] * d[1],
                q[0] * d[3] + q[1] * d[2] - q[2] * d[1] + q[3] * d[0],
            ];
            let n = p.iter().map(|v| v * v).sum::<f64>().sqrt();
            let sign = if p[0] < 0.0 { -1.0 } else { 1.0 };
            for (k, v) in p.iter().enumerate() {
                m[3 + k] = sign * v / n;
            }
        }
        m
    }
}

/// Standard normal draw (Box–Muller).
pub fn gaussian(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = rng.random::<f64>().max(1e-300);
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

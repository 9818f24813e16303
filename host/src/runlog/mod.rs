//! Run logs for the robotics tools people already use (docs/design.md §12).
//!
//! A closed-loop run leaves `run.mcap` beside its `report.json`: the rod's
//! shape as a Foxglove 3-D scene, the tip frames, the commanded and
//! measured tensions, the tracking error, the status bits and the faults,
//! on the loop's clock, with the report's summary as metadata. The same
//! channels can be served live over the Foxglove WebSocket protocol. The
//! plant writes it ([`RunLog`], a thread behind a queue): it has the rod's
//! true shape, and the controller never waits on it.
//!
//! Built on the Foxglove SDK (`foxglove`: the well-known schemas, the MCAP
//! sink, the WebSocket server) and read back with the `mcap` crate
//! ([`read`]), which is also what `tendril plot run.mcap` uses.

pub mod channels;
pub mod figure;
pub mod finalize;
pub mod read;
pub mod writer;

pub use read::RunLogFile;
pub use writer::{RunLog, RunLogConfig, RunLogStats, SceneRecord, StepRecord};

/// `points` ≥ 2 points evenly spaced along the polyline `line` by its
/// length, its first and last points kept exactly (empty stays empty).
pub fn resample(line: &[nalgebra::Vector3<f64>], points: usize) -> Vec<nalgebra::Vector3<f64>> {
    let (Some(first), Some(last)) = (line.first(), line.last()) else {
        return vec![];
    };
    let points = points.max(2);
    if line.len() < 2 {
        return vec![*first; points];
    }
    let mut along = Vec::with_capacity(line.len());
    let mut total = 0.0;
    along.push(0.0);
    for w in line.windows(2) {
        total += (w[1] - w[0]).norm();
        along.push(total);
    }
    let mut out = Vec::with_capacity(points);
    out.push(*first);
    let mut j = 0;
    for k in 1..points - 1 {
        let target = total * k as f64 / (points - 1) as f64;
        while j + 2 < along.len() && along[j + 1] < target {
            j += 1;
        }
        let span = along[j + 1] - along[j];
        let t = if span > 0.0 {
            (target - along[j]) / span
        } else {
            0.0
        };
        out.push(line[j] + (line[j + 1] - line[j]) * t.clamp(0.0, 1.0));
    }
    out.push(*last);
    out
}

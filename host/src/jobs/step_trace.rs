//! A step's tracker trace for `tendril calibrate --step` (docs/design.md
//! §11): a CSV (`calibrate::step::read_trace`), or the `/tracking` channel of
//! a run log (`run.mcap`: a sim's or `tendril dynamics`'), whose measured
//! tip is the tracker's newest frame at each plant step.

use std::path::Path;

use crate::calibrate::step::{read_trace, StepError, StepTrace};
use crate::runlog::RunLogFile;

/// The trace in `path`: a run log when it ends in `.mcap`, else a CSV.
/// A run log's frames are timed by the plant step that logged them (1 ms
/// steps: a frame is late by up to a step, a constant delay that moves no
/// frequency or damping).
pub fn read_step_trace(path: &Path) -> Result<StepTrace, StepError> {
    if !path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("mcap"))
    {
        return read_trace(path);
    }
    let bad = |why: String| StepError::Read(format!("{}: {why}", path.display()));
    let log = RunLogFile::open_topics(path, &[crate::runlog::channels::TRACKING])
        .map_err(|e| StepError::Read(e.to_string()))?;
    let tracking = log.tracking().map_err(|e| StepError::Read(e.to_string()))?;
    let mut trace = StepTrace::default();
    for (index, (t_ns, m)) in tracking.iter().enumerate() {
        if let Some(p) = m.measured_m {
            trace
                .push(*t_ns as f64 * 1e-9, p)
                .map_err(|why| bad(format!("/tracking message {}: {why}", index + 1)))?;
        }
    }
    if trace.t_s.is_empty() {
        return Err(bad(
            "no tracker frame on /tracking (a run log without a plant?)".into(),
        ));
    }
    Ok(trace)
}

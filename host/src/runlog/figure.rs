//! The sim's figure redrawn from a run log alone (`tendril plot run.mcap`):
//! the log is the single record of a run.

use std::path::Path;

use super::read::{ReadError, RunLogFile};
use crate::plot::sim::{SimFigure, TensionSample};

/// Most points drawn per series (a 60 s run at 1 kHz is decimated).
const MAX_POINTS: usize = 6000;

/// What a redraw found in the log.
#[derive(Clone, Debug, PartialEq)]
pub struct Redrawn {
    /// `/tracking` messages read.
    pub tracking: usize,
    /// `/tensions` messages read.
    pub tensions: usize,
    /// RMS of `/tracking`'s `error_mm` over the messages that have one, mm.
    pub rms_error_mm: Option<f64>,
    /// The file ended before its footer (a crashed run).
    pub truncated: bool,
}

/// What can stop a redraw.
#[derive(Debug, thiserror::Error)]
pub enum FigureError {
    /// The log could not be read.
    #[error(transparent)]
    Read(#[from] ReadError),
    /// The log has nothing to draw.
    #[error("{0}: no /tracking or /tensions messages (not a tendril run log?)")]
    Empty(String),
    /// Drawing failed.
    #[error("drawing {path}: {message}")]
    Draw {
        /// The figure.
        path: String,
        /// The plotting library's message.
        message: String,
    },
}

/// Draw the top view of the desired and true tip paths and the tensions of
/// the log at `mcap` into `png`.
pub fn redraw(mcap: &Path, png: &Path) -> Result<Redrawn, FigureError> {
    let log = RunLogFile::open_topics(
        mcap,
        &[super::channels::TRACKING, super::channels::TENSIONS],
    )?;
    let tracking = log.tracking()?;
    let tensions = log.tensions()?;
    if tracking.is_empty() && tensions.is_empty() {
        return Err(FigureError::Empty(mcap.display().to_string()));
    }
    let step = |n: usize| n.div_ceil(MAX_POINTS).max(1);
    let mm = |p: [f64; 3]| (p[0] * 1e3, p[1] * 1e3);
    let (mut desired, mut actual) = (Vec::new(), Vec::new());
    for (_, t) in tracking.iter().step_by(step(tracking.len())) {
        if let Some(d) = t.desired_m {
            desired.push(mm(d));
            actual.push(mm(t.actual_m));
        }
    }
    let t0 = tensions.first().map_or(0, |(t, _)| *t);
    let samples: Vec<TensionSample<'_>> = tensions
        .iter()
        .step_by(step(tensions.len()))
        .map(|(t, m)| TensionSample {
            t_s: t.saturating_sub(t0) as f64 * 1e-9,
            commanded: &m.commanded_n,
            actual: &m.measured_n,
        })
        .collect();
    let figure = SimFigure {
        desired_mm: desired,
        actual_mm: actual,
        tendons: tensions.first().map_or(0, |(_, m)| m.measured_n.len()),
        tensions: samples,
    };
    crate::plot::sim::draw(png, &figure).map_err(|e| FigureError::Draw {
        path: png.display().to_string(),
        message: e.to_string(),
    })?;
    let errors: Vec<f64> = tracking.iter().filter_map(|(_, t)| t.error_mm).collect();
    let rms_error_mm = (!errors.is_empty())
        .then(|| (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt());
    Ok(Redrawn {
        tracking: tracking.len(),
        tensions: tensions.len(),
        rms_error_mm,
        truncated: log.truncated,
    })
}

//! The path's start, learned on the model after its periodic offset
//! (`docs/design.md` §6.4, "Learning on the model"): the periodic offset is
//! right for the state the loop settles into, not for the seconds the rod
//! takes to get there from rest, where its mode rings (on `tdcr-3seg` for
//! two to four passes). A start offset of raised-cosine bumps over the
//! path's first seconds is learned on the rehearsed loop as the periodic
//! one is — each bump's effect on the window's error identified alone,
//! then u ← u − γ (HᵀH + λI)⁻¹ Hᵀ e — a lifted (time-domain) learning:
//! the start is not periodic, and the rod is not time-invariant along it.

use rayon::prelude::*;

use super::{least_squares_step, PassErrors, StartWindow};
use crate::ipc::IpcError;
use crate::plan::{StartOffset, TurningOffset};

/// How the start is learned.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StartSettings {
    /// The bumps' spacing, s of the path's time.
    pub step_s: f64,
    /// Bumps per axis.
    pub bumps: usize,
    /// The error window measured, from the path's start.
    pub window: StartWindow,
    /// Iterations of the offset.
    pub iterations: usize,
    /// γ, the share of the least-squares step taken each iteration.
    pub gain: f64,
    /// Amplitude of an identification's bump, m.
    pub amplitude_m: f64,
    /// λ relative to HᵀH's mean diagonal.
    pub regularisation: f64,
}

impl StartSettings {
    /// For a loop whose slowest mode rings at `mode_hz` with damping ratio
    /// `damping_ratio`, on a path that eases in over `ease_s`: four bumps a
    /// mode's period (the ring is at the mode), over the ease and four of
    /// the mode's periods after it (where the ring is made and can still
    /// be taken out; six a period over two periods, the same count, left
    /// 0.125 mm on `tdcr-3seg` where this leaves 0.115); the error measured
    /// until two decay times 1/(ζω) (at most 10 s) after the last bump, in
    /// 50 ms bins. `None` for a mode that is not a positive frequency and
    /// damping.
    pub fn for_mode(mode_hz: f64, damping_ratio: f64, ease_s: f64) -> Option<StartSettings> {
        if !(mode_hz > 0.0 && damping_ratio > 0.0 && ease_s >= 0.0 && mode_hz.is_finite()) {
            return None;
        }
        let step_s = 1.0 / (4.0 * mode_hz);
        let bumps = ((ease_s + 4.0 / mode_hz) / step_s).ceil() as usize;
        let decay_s = 1.0 / (std::f64::consts::TAU * mode_hz * damping_ratio);
        let length_s = (bumps + 1) as f64 * step_s + (2.0 * decay_s).min(10.0);
        let bin_s = 0.05;
        Some(StartSettings {
            step_s,
            bumps,
            window: StartWindow {
                bin_s,
                bins: (length_s / bin_s).ceil() as usize,
            },
            iterations: 6,
            gain: 0.7,
            amplitude_m: 2e-5,
            regularisation: 1e-3,
        })
    }

    /// The rehearsals a start's learning runs at most.
    pub fn most_rehearsals(&self) -> usize {
        1 + 3 * self.bumps + self.iterations
    }
}

/// What the start's learning found.
#[derive(Clone, Debug)]
pub struct StartLearning {
    /// The periodic offset with the best start (none if none helped).
    pub offset: TurningOffset,
    /// The window's RMS with the periodic offset alone, m.
    pub unaided_rms_m: f64,
    /// The window's RMS after each iteration, m.
    pub iteration_rms_m: Vec<f64>,
    /// Why the iterations stopped early, if they did.
    pub stopped: Option<String>,
    /// Rehearsals run.
    pub rehearsals: usize,
}

impl StartLearning {
    /// The window's RMS with the start kept, m.
    pub fn learned_rms_m(&self) -> f64 {
        self.iteration_rms_m
            .iter()
            .copied()
            .fold(self.unaided_rms_m, f64::min)
    }
}

fn flatten(bins: &[[f64; 3]]) -> nalgebra::DVector<f64> {
    nalgebra::DVector::from_iterator(bins.len() * 3, bins.iter().flatten().copied())
}

fn with_start(
    periodic: &TurningOffset,
    s: &StartSettings,
    u: &nalgebra::DVector<f64>,
) -> TurningOffset {
    let mut start = StartOffset::zero(s.step_s, s.bumps);
    for (k, b) in start.bumps.iter_mut().enumerate() {
        *b = [u[3 * k], u[3 * k + 1], u[3 * k + 2]];
    }
    TurningOffset {
        start: Some(start),
        ..periodic.clone()
    }
}

/// Learn the start on top of `periodic` with `rehearse` (a run of the
/// settings' window).
pub fn learn_start(
    periodic: &TurningOffset,
    s: &StartSettings,
    rehearse: &(dyn Fn(&TurningOffset) -> Result<PassErrors, IpcError> + Sync),
) -> Result<StartLearning, IpcError> {
    let plain = TurningOffset {
        start: None,
        ..periodic.clone()
    };
    let unaided = rehearse(&plain)?;
    let e0 = flatten(&unaided.start);
    let columns: Vec<_> = (0..3 * s.bumps)
        .into_par_iter()
        .map(|column| {
            let mut u = nalgebra::DVector::zeros(3 * s.bumps);
            u[column] = s.amplitude_m;
            let e = flatten(&rehearse(&with_start(&plain, s, &u))?.start);
            Ok((e - &e0) / s.amplitude_m)
        })
        .collect::<Result<_, IpcError>>()?;
    let map = nalgebra::DMatrix::from_columns(&columns);
    let step = least_squares_step(&map, s.regularisation)
        .ok_or_else(|| IpcError::Other("learning the start: a singular design".into()))?;
    let mut learning = StartLearning {
        offset: plain.clone(),
        unaided_rms_m: unaided.start_rms_m,
        iteration_rms_m: vec![],
        stopped: None,
        rehearsals: 1 + columns.len(),
    };
    let mut u = nalgebra::DVector::zeros(3 * s.bumps);
    let mut e = e0;
    let mut best = (unaided.start_rms_m, None, unaided.start.clone());
    for _ in 0..s.iterations {
        u -= &step * &e * s.gain;
        let offset = with_start(&plain, s, &u);
        if offset.largest_m() > crate::ipc::planner::MAX_TURNING_OFFSET_M {
            learning.stopped = Some(format!(
                "the start's offset reached {:.3} mm, over the planner's bound",
                offset.largest_m() * 1e3
            ));
            break;
        }
        let errors = rehearse(&offset)?;
        learning.rehearsals += 1;
        learning.iteration_rms_m.push(errors.start_rms_m);
        e = flatten(&errors.start);
        if errors.start_rms_m < best.0 {
            best = (errors.start_rms_m, Some(offset), errors.start.clone());
        } else if errors.start_rms_m > 1.1 * best.0 + 5e-6 {
            learning.stopped = Some(format!(
                "the start's error grew to {:.3} mm from {:.3} mm",
                errors.start_rms_m * 1e3,
                best.0 * 1e3
            ));
            break;
        }
    }
    if let Some(offset) = best.1 {
        learning.offset = offset;
    }
    // The start's error as the model's loop had it, for the stiffness
    // adaptation (`plan::ExpectedError`).
    if let Some(expected) = learning.offset.expected.as_mut() {
        expected.bin_s = s.window.bin_s;
        expected.start = best.2;
    }
    Ok(learning)
}

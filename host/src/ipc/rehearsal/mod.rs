//! Learning on the model before the run (`docs/design.md` §6.4, "Learning
//! on the model"): the offset that puts the tip on a circle, learned on
//! the loop rehearsed in process against the robot file's plant model,
//! in the circle's turning frame.
//!
//! The map from the offset's harmonics to the error's is identified on the
//! rehearsed loop itself — the low harmonics each alone (real and
//! imaginary part, each axis: the three tendons a segment couple harmonics
//! three apart, and the rod's first mode sits among them), the rest all at
//! once per axis, each to its own harmonic — and the offset then follows
//! u ← u − γ (HᵀH + λI)⁻¹ Hᵀ e from rehearsal to rehearsal, stopping with
//! the best offset if an iteration's error grows.

mod start;
mod virtual_loop;

use rayon::prelude::*;

pub use start::{StartLearning, StartSettings};
pub use virtual_loop::{Complex, PassErrors, StartWindow, VirtualLoop};

use crate::ipc::IpcError;
use crate::plan::TurningOffset;

/// How the learning on the model is run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    /// Harmonics of the path's period learned (0 to `harmonics` − 1).
    pub harmonics: usize,
    /// Harmonics identified one at a time (0 to `lifted` − 1), with their
    /// coupling to every other; the rest each to its own.
    pub lifted: usize,
    /// Passes a rehearsal runs after the settle; the last is measured
    /// ([`Settings::passes_to_settle`] sets it from the rod's mode).
    pub passes: usize,
    /// Iterations of the offset.
    pub iterations: usize,
    /// γ, the share of the least-squares step taken each iteration.
    pub gain: f64,
    /// Amplitude of an identification's offset, m.
    pub amplitude_m: f64,
    /// λ relative to HᵀH's mean diagonal.
    pub regularisation: f64,
    /// The path's start, learned after the periodic offset (none: not).
    pub start: Option<StartSettings>,
}

impl Default for Settings {
    /// Measured on `tdcr-3seg`'s dynamic circle (BENCHMARKS.md, "Learning
    /// on the model"): 7 lifted harmonics reached 0.054 mm in 8 iterations,
    /// 13 reached 0.044 mm for 30 more rehearsals.
    fn default() -> Settings {
        Settings {
            harmonics: 41,
            lifted: 7,
            passes: 3,
            iterations: 8,
            gain: 0.7,
            amplitude_m: 2e-5,
            regularisation: 1e-3,
            start: None,
        }
    }
}

/// The most passes a rehearsal runs: a mode that decays slower than this
/// allows is learned on a pass where its transient is not yet gone.
pub const MOST_PASSES: usize = 12;

impl Settings {
    /// The passes for a path of period `period_s` on a loop whose slowest
    /// mode rings at `mode_hz` with damping ratio `damping_ratio`: enough
    /// that the measured (last) pass starts four decay times 1/(ζω) after
    /// the path does, where the transient of the path's start is down to
    /// e⁻⁴ (2 %) of its size. The offset is learned for the periodic state
    /// the run then stays in; learned on a pass the start still rings in,
    /// it fits that ring, which the run no longer has (`tdcr-3seg`'s
    /// 0.4 Hz circle: 0.05 mm on the third pass of the rehearsal, 0.19 mm
    /// a pass in the run). At least the default's; at most [`MOST_PASSES`].
    pub fn passes_to_settle(mut self, period_s: f64, mode_hz: f64, damping_ratio: f64) -> Settings {
        let decay_s = 1.0 / (std::f64::consts::TAU * mode_hz * damping_ratio);
        let before_measured = (4.0 * decay_s / period_s).ceil();
        if before_measured.is_finite() && before_measured >= 0.0 {
            self.passes = self
                .passes
                .max(before_measured as usize + 1)
                .min(MOST_PASSES);
        }
        self
    }

    /// The rehearsals a learning runs at most: the unaided one, the
    /// identification's (harmonic 0 has no imaginary part; three for the
    /// rest at once) and one per iteration.
    pub fn most_rehearsals(&self) -> usize {
        let lifted = self.lifted.min(self.harmonics);
        let one_at_a_time = (lifted * 6).saturating_sub(3);
        let at_once = if lifted < self.harmonics { 3 } else { 0 };
        let start = self.start.map_or(0, |s| s.most_rehearsals());
        1 + one_at_a_time + at_once + self.iterations + start
    }
}

/// What the learning found.
#[derive(Clone, Debug)]
pub struct ModelLearning {
    /// The best offset (the last iteration's, unless one grew).
    pub offset: TurningOffset,
    /// The measured pass's RMS without the offset, m.
    pub unaided_rms_m: f64,
    /// The measured pass's RMS after each iteration, m.
    pub iteration_rms_m: Vec<f64>,
    /// Why the iterations stopped early, if they did.
    pub stopped: Option<String>,
    /// Rehearsals run.
    pub rehearsals: usize,
    /// The start's learning, when asked for (its offset is in `offset`).
    pub start: Option<StartLearning>,
}

impl ModelLearning {
    /// The measured pass's RMS with the offset kept, m.
    pub fn learned_rms_m(&self) -> f64 {
        self.iteration_rms_m
            .iter()
            .copied()
            .fold(self.unaided_rms_m, f64::min)
    }
}

/// The error (or offset) as a real vector: per harmonic m, per axis, the
/// real then the imaginary part.
fn index(axis: usize, m: usize, part: usize) -> usize {
    (m * 3 + axis) * 2 + part
}

fn flatten(h: &[Vec<Complex>; 3], n: usize) -> nalgebra::DVector<f64> {
    let mut v = nalgebra::DVector::zeros(6 * n);
    for (axis, harmonics) in h.iter().enumerate() {
        for (m, c) in harmonics.iter().enumerate().take(n) {
            v[index(axis, m, 0)] = c.re;
            v[index(axis, m, 1)] = c.im;
        }
    }
    v
}

fn offset_of(v: &nalgebra::DVector<f64>, center_m: [f64; 2], period_s: f64) -> TurningOffset {
    let n = v.len() / 6;
    let mut offset = TurningOffset::zero(center_m, period_s, n);
    for (m, axes) in offset.harmonics.iter_mut().enumerate() {
        for (axis, c) in axes.iter_mut().enumerate() {
            *c = [
                v[index(axis, m, 0)],
                if m == 0 { 0.0 } else { v[index(axis, m, 1)] },
            ];
        }
    }
    offset
}

/// Learn the offset for the circle about `center_m` on `rehearsed`.
/// `progress` is told of each rehearsal; a stop request ends the learning
/// with an error between rehearsals.
pub fn learn(
    rehearsed: &VirtualLoop,
    center_m: [f64; 2],
    settings: &Settings,
    progress: &(dyn Fn() + Sync),
) -> Result<ModelLearning, IpcError> {
    let n = settings.harmonics;
    let last = settings.passes.saturating_sub(1);
    let period_s = rehearsed.period_s;
    let zero = TurningOffset::zero(center_m, period_s, n);
    let stop = || {
        if crate::interrupt::stop_requested() {
            Err(IpcError::Other("learning on the model: interrupted".into()))
        } else {
            Ok(())
        }
    };
    let rehearse = |offset: &TurningOffset| -> Result<PassErrors, IpcError> {
        stop()?;
        let errors = rehearsed.run(offset, settings.passes, n, StartWindow::default())?;
        progress();
        Ok(errors)
    };
    let unaided = rehearse(&zero)?;
    let e0 = flatten(&unaided.harmonics[last], n);
    let identified = identify(&e0, settings, center_m, period_s, &rehearse)?;
    let mut learning = iterate(
        (&e0, unaided.rms_m[last]),
        &identified.map,
        settings,
        &zero,
        &rehearse,
    )?;
    learning.rehearsals += 1 + identified.rehearsals;
    if let Some(s) = &settings.start {
        let rehearse_start = |offset: &TurningOffset| -> Result<PassErrors, IpcError> {
            stop()?;
            let errors = rehearsed.run(offset, 0, 0, s.window)?;
            progress();
            Ok(errors)
        };
        let start = start::learn_start(&learning.offset, s, &rehearse_start)?;
        learning.rehearsals += start.rehearsals;
        learning.offset = start.offset.clone();
        learning.start = Some(start);
    }
    Ok(learning)
}

/// (HᵀH + λI)⁻¹Hᵀ, λ `regularisation` × HᵀH's mean diagonal: the
/// regularised least-squares step from an error to the input that cancels
/// it through `map`.
fn least_squares_step(
    map: &nalgebra::DMatrix<f64>,
    regularisation: f64,
) -> Option<nalgebra::DMatrix<f64>> {
    let hth = map.transpose() * map;
    let lambda = regularisation * hth.trace() / hth.nrows() as f64;
    let n = map.ncols();
    Some((hth + nalgebra::DMatrix::identity(n, n) * lambda).try_inverse()? * map.transpose())
}

/// The iterations from the unaided error `e0` (with its pass RMS, m) with
/// the identified `map`; offsets in `zero`'s circle.
fn iterate(
    (e0, unaided_rms_m): (&nalgebra::DVector<f64>, f64),
    map: &nalgebra::DMatrix<f64>,
    settings: &Settings,
    zero: &TurningOffset,
    rehearse: &(dyn Fn(&TurningOffset) -> Result<PassErrors, IpcError> + Sync),
) -> Result<ModelLearning, IpcError> {
    let last = settings.passes.saturating_sub(1);
    let n = zero.harmonics.len();
    let (center_m, period_s) = (zero.center_m, zero.period_s);
    let design = least_squares_step(map, settings.regularisation)
        .ok_or_else(|| IpcError::Other("learning on the model: a singular design".into()))?;
    let mut u = nalgebra::DVector::zeros(6 * n);
    let mut e = e0.clone();
    let mut best = (unaided_rms_m, u.clone(), e0.clone());
    let mut learning = ModelLearning {
        offset: zero.clone(),
        unaided_rms_m,
        iteration_rms_m: vec![],
        stopped: None,
        rehearsals: 0,
        start: None,
    };
    for _ in 0..settings.iterations {
        u -= &design * &e * settings.gain;
        let offset = offset_of(&u, center_m, period_s);
        if offset.largest_m() > crate::ipc::planner::MAX_TURNING_OFFSET_M {
            learning.stopped = Some(format!(
                "the offset reached {:.3} mm, over the planner's bound",
                offset.largest_m() * 1e3
            ));
            break;
        }
        let errors = rehearse(&offset)?;
        learning.rehearsals += 1;
        let rms = errors.rms_m[last];
        learning.iteration_rms_m.push(rms);
        e = flatten(&errors.harmonics[last], n);
        if rms < best.0 {
            best = (rms, u.clone(), e.clone());
        } else if rms > 1.1 * best.0 + 5e-6 {
            learning.stopped = Some(format!(
                "the error grew to {:.3} mm from {:.3} mm: the identified map is not the loop",
                rms * 1e3,
                best.0 * 1e3
            ));
            break;
        }
    }
    learning.offset = offset_of(&best.1, center_m, period_s);
    // The error is laid out as the offset is.
    learning.offset.expected = Some(crate::plan::ExpectedError {
        bin_s: 0.0,
        start: vec![],
        harmonics: offset_of(&best.2, center_m, period_s).harmonics,
    });
    Ok(learning)
}

/// The identified map from the offset's harmonics to the measured pass's
/// error harmonics (both as [`flatten`]ed vectors).
struct Identified {
    map: nalgebra::DMatrix<f64>,
    rehearsals: usize,
}

fn identify(
    e0: &nalgebra::DVector<f64>,
    settings: &Settings,
    center_m: [f64; 2],
    period_s: f64,
    rehearse: &(dyn Fn(&TurningOffset) -> Result<PassErrors, IpcError> + Sync),
) -> Result<Identified, IpcError> {
    let n = settings.harmonics;
    let lifted = settings.lifted.min(n);
    let last = settings.passes.saturating_sub(1);
    let a = settings.amplitude_m;
    let mut inputs = vec![];
    for m in 0..lifted {
        for axis in 0..3 {
            for part in 0..if m == 0 { 1 } else { 2 } {
                inputs.push((m, axis, part));
            }
        }
    }
    let single: Vec<_> = inputs
        .par_iter()
        .map(|&(m, axis, part)| {
            let mut offset = TurningOffset::zero(center_m, period_s, n);
            offset.harmonics[m][axis][part] = a;
            let e = flatten(&rehearse(&offset)?.harmonics[last], n);
            Ok((index(axis, m, part), (e - e0) / a))
        })
        .collect::<Result<_, IpcError>>()?;
    // The rest, all harmonics of one axis at once: phases spread (golden
    // angle) so that their sum stays near the amplitude's scale.
    let phase = |m: usize, axis: usize| {
        ((m * 7 + axis * 13) as f64 * 2.399_963).rem_euclid(std::f64::consts::TAU)
    };
    let axes = if lifted < n { 0..3 } else { 0..0 };
    let multi: Vec<_> = axes
        .into_par_iter()
        .map(|axis| {
            let mut offset = TurningOffset::zero(center_m, period_s, n);
            for m in lifted..n {
                let (s, c) = phase(m, axis).sin_cos();
                offset.harmonics[m][axis] = [a * c, a * s];
            }
            let e = flatten(&rehearse(&offset)?.harmonics[last], n);
            Ok(e - e0)
        })
        .collect::<Result<_, IpcError>>()?;
    let mut map = nalgebra::DMatrix::zeros(6 * n, 6 * n);
    for (column, values) in &single {
        map.set_column(*column, values);
    }
    for (axis, de) in multi.iter().enumerate() {
        for m in lifted..n {
            let u = Complex::from_polar(a, phase(m, axis));
            for to in 0..3 {
                let p = Complex::new(de[index(to, m, 0)], de[index(to, m, 1)]) / u;
                // An input's real part moves (Re P, Im P), its imaginary part (−Im P, Re P).
                map[(index(to, m, 0), index(axis, m, 0))] = p.re;
                map[(index(to, m, 1), index(axis, m, 0))] = p.im;
                map[(index(to, m, 0), index(axis, m, 1))] = -p.im;
                map[(index(to, m, 1), index(axis, m, 1))] = p.re;
            }
        }
    }
    Ok(Identified {
        map,
        rehearsals: single.len() + multi.len(),
    })
}

#[cfg(test)]
mod tests;

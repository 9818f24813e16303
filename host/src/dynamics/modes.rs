//! The rod's vibration modes at a pose, identified from the dynamic Cosserat
//! model itself (`docs/design.md` §6.4): the robot rests in its statics
//! equilibrium under the tensions `at`, every anchor group's first tendon
//! gets a small step, and the tip's displacement afterwards — the new
//! equilibrium's offset plus a damped sinusoid per underdamped mode — is
//! fitted by the matrix-pencil method (Hua & Sarkar 1990).
//!
//! *Why identify instead of linearising:* a time step of the model is a
//! shooting problem in arc length, not a state-space ODE, so its Jacobian is
//! not at hand; a step response of the very model the plant runs contains
//! the tendons' follower loads, the spacer disks' inertia, gravity and the
//! pose, which the Euler–Bernoulli formula has none of. The identification
//! is checked against that formula where it holds (a straight rod without
//! gravity) and against the ringing of the plant after a step.

use nalgebra::{Complex, DMatrix, DVector};

use super::{Damping, Dynamics, DynamicsError, DynamicsSettings};
use crate::robot::groups::anchor_groups;
use crate::robot::{first_bending_mode_rad_s, Robot};

/// One underdamped vibration mode.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Mode {
    /// Undamped natural frequency f_n = ω_n / 2π, Hz.
    pub freq_hz: f64,
    /// Damping ratio ζ (dimensionless, 0 < ζ < 1).
    pub damping_ratio: f64,
    /// Its amplitude in the tip's step response relative to the strongest
    /// mode's (0..1]: how strongly a tendon step excites it.
    pub share: f64,
}

impl Mode {
    /// The damped frequency f_d = f_n √(1 − ζ²), Hz: what a ringing rod shows.
    pub fn damped_freq_hz(&self) -> f64 {
        self.freq_hz * (1.0 - self.damping_ratio * self.damping_ratio).sqrt()
    }
}

/// How a pose's modes are identified.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModeSearch {
    /// Simulated time after the step, s (None: four periods of the
    /// Euler–Bernoulli first mode, at least 1 s).
    pub duration_s: Option<f64>,
    /// Time step of the dynamic model, s.
    pub dt_s: f64,
    /// Size of the tension step, as a fraction of each kicked tendon's
    /// maximum tension: small, so the response is the linearisation's.
    pub kick_fraction: f64,
    /// Modes closer than this relative frequency are one (the two bending
    /// planes of a symmetric rod, split slightly when it is bent).
    pub merge_within: f64,
}

impl Default for ModeSearch {
    fn default() -> Self {
        ModeSearch {
            duration_s: None,
            dt_s: 1e-3,
            kick_fraction: 0.002,
            merge_within: 0.05,
        }
    }
}

/// Why the modes could not be identified.
#[derive(Debug, thiserror::Error)]
pub enum ModesError {
    /// The dynamic model failed.
    #[error(transparent)]
    Dynamics(#[from] DynamicsError),
    /// A setting is out of range.
    #[error("mode search: {0}")]
    BadSettings(String),
    /// The step response holds no underdamped mode.
    #[error("no underdamped mode in the step response: every mode is overdamped at this damping")]
    NoMode,
}

/// Ratio of the fitted sample rate to the Euler–Bernoulli second mode
/// (6.27 f₁): the pencil sees the first two modes well resolved.
const SAMPLES_PER_MODE2_PERIOD: f64 = 10.0;
/// Singular values below this fraction of the largest are noise (the
/// solver's tolerance and the step's nonlinearity).
const RANK_TOLERANCE: f64 = 1e-5;
/// At most this many poles are fitted.
const MAX_ORDER: usize = 24;
/// Poles whose share of the velocity amplitude is below this are discarded
/// as fitting artefacts.
const MIN_SHARE: f64 = 0.005;

/// The underdamped modes of `robot` (with material `damping`) at rest under
/// `at` (N), lowest first, up to the rod's second bending mode resolved by
/// the search's sampling.
pub fn identify(
    robot: &Robot,
    damping: Damping,
    at: &[f64],
    search: &ModeSearch,
) -> Result<Vec<Mode>, ModesError> {
    if !(search.dt_s > 0.0 && search.dt_s <= 0.01) {
        return Err(ModesError::BadSettings(format!(
            "time step {} s must be in (0, 0.01]",
            search.dt_s
        )));
    }
    if !(search.kick_fraction > 0.0 && search.kick_fraction <= 0.2) {
        return Err(ModesError::BadSettings(format!(
            "kick {} must be in (0, 0.2] of the maximum tension",
            search.kick_fraction
        )));
    }
    let f1_beam = first_bending_mode_rad_s(robot) / std::f64::consts::TAU;
    let duration_s = search.duration_s.unwrap_or((4.0 / f1_beam).max(1.0));
    if !(duration_s.is_finite() && duration_s > 0.0 && duration_s <= 60.0) {
        return Err(ModesError::BadSettings(format!(
            "duration {duration_s} s must be in (0, 60]"
        )));
    }
    let settings = DynamicsSettings {
        dt_s: search.dt_s,
        ..DynamicsSettings::default()
    };
    let mut dynamics = Dynamics::at_rest(
        robot,
        damping,
        settings,
        at,
        nalgebra::Vector3::zeros(),
        nalgebra::Vector3::zeros(),
    )?;
    // Each segment's first tendon, stepped up (or down if it is near its
    // maximum): a moment at every anchor, so every bending mode moves.
    let max = robot.max_tensions();
    let mut kicked = at.to_vec();
    for group in anchor_groups(robot) {
        let i = group[0];
        let delta = search.kick_fraction * max[i];
        kicked[i] = if at[i] + delta <= max[i] {
            at[i] + delta
        } else {
            at[i] - delta
        };
    }
    let sample_s = 1.0 / (SAMPLES_PER_MODE2_PERIOD * 6.27 * f1_beam);
    let stride = ((sample_s / search.dt_s).floor() as usize).max(1);
    let steps = (duration_s / search.dt_s).round() as usize;
    // The tip's displacement averaged over each stride (a moving average
    // keeps every exponential an exponential and damps what would alias).
    // Displacement, not velocity: velocity weighs mode k by ω_k, and a
    // strongly bent rod's first mode then drowns under its second.
    let start = dynamics.tip().position;
    let mut channels: [Vec<f64>; 3] = Default::default();
    let mut sum = [0.0; 3];
    for k in 1..=steps {
        let tip = dynamics.step(&kicked)?;
        for (s, v) in sum.iter_mut().zip((tip.position - start).iter()) {
            *s += v;
        }
        if k % stride == 0 {
            for (c, s) in channels.iter_mut().zip(sum.iter_mut()) {
                c.push(*s / stride as f64);
                *s = 0.0;
            }
        }
    }
    let fitted_dt = stride as f64 * search.dt_s;
    let poles = matrix_pencil(&channels, fitted_dt)?;
    let modes = merge(
        poles,
        search.merge_within,
        0.8 * std::f64::consts::PI / fitted_dt,
    );
    if modes.is_empty() {
        return Err(ModesError::NoMode);
    }
    Ok(modes)
}

/// A continuous-time pole s = −ζω_n + iω_d (Im > 0) and its share of the
/// signals' amplitude.
#[derive(Clone, Copy, Debug)]
struct Pole {
    s: Complex<f64>,
    share: f64,
}

/// The poles of the damped sinusoids (and the constant) the `channels` (sampled every `dt_s`)
/// share, by the matrix pencil on their stacked Hankel matrices.
fn matrix_pencil(channels: &[Vec<f64>], dt_s: f64) -> Result<Vec<Pole>, ModesError> {
    let n = channels.iter().map(Vec::len).min().unwrap_or(0);
    if n < 12 {
        return Err(ModesError::BadSettings(format!(
            "{n} samples are too few to fit modes: lengthen the duration"
        )));
    }
    let pencil = n / 3;
    let rows = n - pencil;
    let mut hankel = DMatrix::<f64>::zeros(channels.len() * rows, pencil + 1);
    for (c, x) in channels.iter().enumerate() {
        for i in 0..rows {
            for j in 0..=pencil {
                hankel[(c * rows + i, j)] = x[i + j];
            }
        }
    }
    let svd = hankel.svd(false, true);
    let sigma = &svd.singular_values;
    let largest = sigma.max();
    if largest <= 0.0 || !largest.is_finite() {
        return Err(ModesError::NoMode);
    }
    let order = sigma
        .iter()
        .filter(|&&s| s > RANK_TOLERANCE * largest)
        .count()
        .clamp(1, MAX_ORDER.min(pencil));
    let v_t = svd.v_t.expect("asked for V");
    // V' = the leading right singular vectors as columns, (pencil+1) × order.
    let v = v_t.rows(0, order).transpose();
    let v1 = v.rows(0, pencil).into_owned();
    let v2 = v.rows(1, pencil).into_owned();
    let a = v1
        .pseudo_inverse(1e-12)
        .map_err(|e| ModesError::BadSettings(e.to_string()))?
        * v2;
    let z: Vec<Complex<f64>> = a.complex_eigenvalues().iter().copied().collect();
    // Amplitudes: least squares of every channel on the poles' sequences
    // z^k (complex Vandermonde), the share a pole's largest amplitude.
    let vandermonde = DMatrix::from_fn(n, z.len(), |k, i| z[i].powu(k as u32));
    let pinv = vandermonde
        .clone()
        .pseudo_inverse(1e-12)
        .map_err(|e| ModesError::BadSettings(e.to_string()))?;
    let mut amplitude = vec![0.0f64; z.len()];
    for x in channels {
        let x = DVector::from_iterator(n, x.iter().take(n).map(|&v| Complex::new(v, 0.0)));
        let c = &pinv * x;
        for (a, c) in amplitude.iter_mut().zip(c.iter()) {
            *a = a.max(c.norm());
        }
    }
    // Shares among the oscillating poles (not the step's constant offset).
    let top = z
        .iter()
        .zip(&amplitude)
        .filter(|(z, _)| z.im > 0.0)
        .map(|(_, &a)| a)
        .fold(0.0, f64::max);
    Ok(z.iter()
        .zip(&amplitude)
        .filter(|(z, _)| z.im > 0.0 && z.norm() > 0.0)
        .map(|(z, &a)| Pole {
            s: z.ln() / dt_s,
            share: if top > 0.0 { a / top } else { 0.0 },
        })
        .collect())
}

/// Underdamped modes from the poles: shares above [`MIN_SHARE`], below
/// `band_rad_s`, those within `within` (relative) of each other merged
/// (the stronger one kept), lowest first.
fn merge(poles: Vec<Pole>, within: f64, band_rad_s: f64) -> Vec<Mode> {
    let mut modes: Vec<Mode> = poles
        .into_iter()
        .filter(|p| p.share >= MIN_SHARE && p.s.im < band_rad_s && p.s.re < 0.0)
        .map(|p| {
            let omega_n = p.s.norm();
            Mode {
                freq_hz: omega_n / std::f64::consts::TAU,
                damping_ratio: -p.s.re / omega_n,
                share: p.share,
            }
        })
        .collect();
    modes.sort_by(|a, b| a.freq_hz.total_cmp(&b.freq_hz));
    let mut merged: Vec<Mode> = Vec::new();
    for m in modes {
        match merged.last_mut() {
            // The stronger pole speaks for the pair: a weak neighbour is
            // the other bending plane or a fitting artefact.
            Some(last) if m.freq_hz <= last.freq_hz * (1.0 + within) => {
                if m.share > last.share {
                    *last = m;
                }
            }
            _ => merged.push(m),
        }
    }
    merged
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::repo_robot;
    use std::f64::consts::TAU;

    /// Two damped sinusoids, two channels of different mix: the pencil
    /// gives back their frequencies and damping ratios.
    #[test]
    fn the_pencil_finds_two_damped_sinusoids_exactly() {
        let (f1, z1, f2, z2) = (3.2, 0.05, 19.0, 0.2);
        let s = |f: f64, z: f64| {
            let w = TAU * f;
            (-z * w, w * (1.0 - z * z).sqrt())
        };
        let dt = 0.004;
        let signal = |a: f64, b: f64| -> Vec<f64> {
            (0..300)
                .map(|k| {
                    let t = k as f64 * dt;
                    let (r1, i1) = s(f1, z1);
                    let (r2, i2) = s(f2, z2);
                    a * (r1 * t).exp() * (i1 * t + 0.3).sin() + b * (r2 * t).exp() * (i2 * t).cos()
                })
                .collect()
        };
        let poles = matrix_pencil(&[signal(1.0, 0.4), signal(-0.5, 0.2)], dt).unwrap();
        let modes = merge(poles, 0.05, 0.8 * std::f64::consts::PI / dt);
        assert_eq!(modes.len(), 2, "{modes:?}");
        for (m, (f, z)) in modes.iter().zip([(f1, z1), (f2, z2)]) {
            assert!((m.freq_hz / f - 1.0).abs() < 1e-6, "{m:?} vs {f} Hz");
            assert!(
                (m.damping_ratio / z - 1.0).abs() < 1e-5,
                "{m:?} vs zeta {z}"
            );
        }
    }

    /// A straight rod without gravity is the uniform cantilever: the
    /// identified modes are Euler–Bernoulli's (β₁L = 1.8751, β₂L = 4.6941:
    /// 3.611 and 22.63 Hz on the seed backbone; BDF-α at 1 ms is 0.1 % and
    /// 0.5 % low) and stiffness-proportional damping B = t_r K gives every
    /// mode ζ = ω t_r / 2.
    #[test]
    fn a_straight_rod_without_gravity_has_the_beam_modes_and_their_damping() {
        let robot = repo_robot("seed-4t.toml").without_gravity();
        let t_r = 3e-3;
        let modes = identify(
            &robot,
            Damping::proportional(&robot, t_r),
            &[0.0; 4],
            &ModeSearch::default(),
        )
        .unwrap();
        eprintln!("{modes:#?}");
        assert!(modes.len() >= 2, "{modes:?}");
        for (m, f) in modes.iter().zip([3.611, 22.63]) {
            assert!((m.freq_hz / f - 1.0).abs() < 0.01, "{m:?} vs {f} Hz");
            let zeta = TAU * f * t_r / 2.0;
            assert!(
                (m.damping_ratio / zeta - 1.0).abs() < 0.05,
                "{m:?}: zeta vs {zeta:.4}"
            );
        }
    }

    #[test]
    fn bad_searches_are_refused() {
        let robot = repo_robot("seed-4t.toml");
        for search in [
            ModeSearch {
                dt_s: 0.0,
                ..ModeSearch::default()
            },
            ModeSearch {
                kick_fraction: f64::NAN,
                ..ModeSearch::default()
            },
            ModeSearch {
                duration_s: Some(-1.0),
                ..ModeSearch::default()
            },
        ] {
            let e = identify(&robot, Damping::of_robot(&robot), &[0.0; 4], &search);
            assert!(
                matches!(e, Err(ModesError::BadSettings(_))),
                "{search:?}: {e:?}"
            );
        }
    }
}

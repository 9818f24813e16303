//! Is the closed loop oscillating? A sustained tone in the tracking error
//! (docs/design.md §6, "Oscillation and the tracking bound").
//!
//! A loop with too much integral gain for its plant (the dynamic rod at the
//! default `ki`, issue 31) settles into a limit cycle near the rod's first
//! mode: the tip circles the path with a 3–4 Hz ripple of a millimetre or
//! so, which an RMS alone cannot tell from a slow model error. The test
//! here looks for what only an oscillation has: in most 2 s windows of the
//! run, the error's spectrum above the trajectory's own content holds one
//! narrow peak (a local maximum that carries most of that band's power) of
//! at least [`MIN_TONE_RMS_MM`]. Slow errors (the net's, following the
//! path at its own frequency and its harmonics) sit below the band; sensor
//! noise is spread over the band and has no peak carrying its power; a step
//! transient is excluded (windows holding a jump of the desired position,
//! or starting within [`AFTER_JUMP_S`] of one, are not examined), and a
//! tone must be found in at least [`MIN_TONE_WINDOWS`] windows.

use serde::{Deserialize, Serialize};

use super::sample::Sample;

/// Resampling rate of the error, Hz (the band of interest ends far below 125 Hz).
const FS_HZ: f64 = 250.0;
/// Window length, s: 0.5 Hz resolution.
const WINDOW_S: f64 = 2.0;
/// Window step, s.
const HOP_S: f64 = 0.5;
/// Smallest tone (RMS over all three axes) that counts as an oscillation, mm:
/// five times the default sensor noise, a tenth of the nominal circle's
/// millimetre bound.
pub const MIN_TONE_RMS_MM: f64 = 0.1;
/// Share of the band's power the peak must carry (a tone, not broadband noise).
const MIN_TONE_SHARE: f64 = 0.5;
/// Share of the examined windows that must hold the tone (sustained, not a blip).
const MIN_WINDOW_SHARE: f64 = 0.5;
/// Fewest windows with a tone that make an oscillation: it must last (3 s
/// at least; a stable loop's ringing after a step decays well within that).
const MIN_TONE_WINDOWS: usize = 3;
/// A desired position that moves further than this between two samples is a jump, m.
const JUMP_M: f64 = 1e-3;
/// Windows starting within this long after a jump are skipped, s: the
/// dynamic rod's first mode (ζ₁ ≈ 17 %, ω₁ ≈ 22.7 rad/s) rings down by
/// e^(−ζ₁ω₁ · 1 s) ≈ 2 % in that time.
const AFTER_JUMP_S: f64 = 1.0;
/// Largest gap between tracking samples inside a window, s.
const MAX_GAP_S: f64 = 0.05;
/// At most this many windows are examined (evenly spread) in a long run.
const MAX_WINDOWS: usize = 400;

/// The verdict of the oscillation test, with its evidence (`report.json`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Oscillation {
    /// A sustained tone was found.
    pub detected: bool,
    /// Lower edge of the band searched, Hz (above the trajectory's content).
    pub band_from_hz: f64,
    /// Windows of [`WINDOW_S`] examined.
    pub windows: usize,
    /// Of those, windows holding a tone.
    pub windows_with_tone: usize,
    /// Median frequency of the tone over those windows, Hz.
    pub frequency_hz: Option<f64>,
    /// Median RMS of the tone over those windows (all three axes), mm; the
    /// amplitude of a sinusoid is √2 times this.
    pub tone_rms_mm: Option<f64>,
    /// Median RMS of the whole tracking error (all three axes) over the same
    /// windows, mm: what the tone is a part of. The run's own RMS is no
    /// bound on the tone, since a limit cycle that grows after the settle
    /// is larger in its late windows than over the run.
    #[serde(default)]
    pub window_rms_mm: Option<f64>,
}

/// The error's last third against its first: a loop that drifts away or
/// whose limit cycle is slower than the tone band (a tracker 500 ms late
/// under the integral correction swung 25 mm at a fraction of a hertz, and
/// the tone test found nothing) has a tracking error that grows.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Growth {
    /// RMS of the tracking error over the first third of the tracked samples, mm.
    pub first_third_rms_mm: f64,
    /// ... over the last third, mm.
    pub last_third_rms_mm: f64,
    /// The last third's RMS is above [`GROWTH_FACTOR`] times the first's
    /// and above [`GROWTH_FLOOR_MM`].
    pub growing: bool,
}

/// How much larger the last third's error must be to count as growth.
pub const GROWTH_FACTOR: f64 = 3.0;
/// ... and how large at least, mm (below it, noise and settling).
pub const GROWTH_FLOOR_MM: f64 = 0.5;

/// The [`Growth`] of the tracking error over the tracked samples (holds
/// left out); `None` with fewer than 30 samples.
pub fn growth(samples: &[Sample]) -> Option<Growth> {
    let tracked: Vec<f64> = samples
        .iter()
        .filter(|s| !s.hold)
        .map(|s| s.error_mm())
        .collect();
    let n = tracked.len();
    if n < 30 {
        return None;
    }
    let rms = |e: &[f64]| (e.iter().map(|x| x * x).sum::<f64>() / e.len() as f64).sqrt();
    let (first, last) = (rms(&tracked[..n / 3]), rms(&tracked[n - n / 3..]));
    Some(Growth {
        first_third_rms_mm: first,
        last_third_rms_mm: last,
        growing: last > GROWTH_FACTOR * first && last > GROWTH_FLOOR_MM,
    })
}

/// The lower edge of the band for a trajectory whose own content ends at
/// `trajectory_hz`: five harmonics above it, and never below 1 Hz.
pub fn band_from(trajectory_hz: f64) -> f64 {
    (5.0 * trajectory_hz).max(1.0)
}

/// One window's strongest tone in the band: (frequency Hz, RMS mm, share of the band's power).
fn tone(window: &[[f64; 3]], band_from_hz: f64) -> Option<(f64, f64, f64)> {
    let n = window.len();
    let df = FS_HZ / n as f64;
    let hann: Vec<f64> = (0..n)
        .map(|i| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * i as f64 / n as f64).cos())
        .collect();
    let w2: f64 = hann.iter().map(|w| w * w).sum();
    let twiddle: Vec<(f64, f64)> = (0..n)
        .map(|m| (2.0 * std::f64::consts::PI * m as f64 / n as f64).sin_cos())
        .collect();
    // At least 4 so that the bins three below the peak exist (above DC).
    let k_from = ((band_from_hz / df).ceil() as usize).max(4);
    let k_to = n / 2 - 3;
    if k_from + 3 >= k_to {
        return None;
    }
    // One-sided power per bin, summed over the axes, scaled so that a bin's
    // value is its share of the mean square (Parseval with the window's energy).
    let mut power = vec![0.0; k_to + 4];
    for axis in 0..3 {
        let y = detrended(window.iter().map(|e| e[axis]));
        for (k, p) in power
            .iter_mut()
            .enumerate()
            .skip(k_from.saturating_sub(3).max(1))
        {
            let (mut re, mut im) = (0.0, 0.0);
            for (i, (v, w)) in y.iter().zip(&hann).enumerate() {
                let (sin, cos) = twiddle[(k * i) % n];
                re += v * w * cos;
                im -= v * w * sin;
            }
            *p += 2.0 * (re * re + im * im) / (n as f64 * w2);
        }
    }
    let band = &power[k_from..=k_to];
    let (offset, _) = band.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1))?;
    let k = k_from + offset;
    // A peak, not the slope of something below the band.
    if !(power[k] > power[k - 3] && power[k] > power[k + 3]) {
        return None;
    }
    let lobe = &power[k - 2..=k + 2];
    let tone_ms: f64 = lobe.iter().sum();
    let band_ms: f64 = band.iter().sum();
    let centroid = lobe
        .iter()
        .enumerate()
        .map(|(j, p)| (k + j - 2) as f64 * p)
        .sum::<f64>()
        / tone_ms;
    Some((centroid * df, tone_ms.sqrt(), tone_ms / band_ms))
}

/// `values` minus their least-squares line.
fn detrended(values: impl Iterator<Item = f64>) -> Vec<f64> {
    let y: Vec<f64> = values.collect();
    let n = y.len() as f64;
    let mx = (n - 1.0) / 2.0;
    let my = y.iter().sum::<f64>() / n;
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for (i, v) in y.iter().enumerate() {
        let dx = i as f64 - mx;
        sxy += dx * (v - my);
        sxx += dx * dx;
    }
    let slope = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    y.iter()
        .enumerate()
        .map(|(i, v)| v - my - slope * (i as f64 - mx))
        .collect()
}

/// RMS of a window's error over its three axes, mm.
fn window_rms(window: &[[f64; 3]]) -> f64 {
    let ms = window
        .iter()
        .map(|e| e.iter().map(|v| v * v).sum::<f64>())
        .sum::<f64>()
        / window.len() as f64;
    ms.sqrt()
}

fn median(v: &mut [f64]) -> Option<f64> {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied()
}

/// Look for a sustained tone in the tracking error of `samples` (outside
/// holds) above `band_from_hz`.
pub fn detect(samples: &[Sample], band_from_hz: f64) -> Oscillation {
    let tracked: Vec<&Sample> = samples.iter().filter(|s| !s.hold).collect();
    let mut out = Oscillation {
        band_from_hz,
        ..Oscillation::default()
    };
    let (Some(first), Some(last)) = (tracked.first(), tracked.last()) else {
        return out;
    };
    // Jumps of the desired position, and gaps in the samples.
    let mut jumps = Vec::new();
    let mut gaps = Vec::new();
    for w in tracked.windows(2) {
        let d: f64 = (0..3)
            .map(|k| (w[1].desired[k] - w[0].desired[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        // A shaped move is a step's transient too, though it never jumps.
        if d > JUMP_M || w[1].moving {
            jumps.push(w[1].t);
        }
        if w[1].t - w[0].t > MAX_GAP_S {
            gaps.push((w[0].t, w[1].t));
        }
    }
    let starts: Vec<f64> = {
        let span = last.t - first.t - WINDOW_S;
        if span < 0.0 {
            Vec::new()
        } else {
            let count = ((span / HOP_S).floor() as usize + 1).min(MAX_WINDOWS);
            let hop = if count > 1 {
                span / (count - 1) as f64
            } else {
                0.0
            };
            (0..count).map(|i| first.t + i as f64 * hop).collect()
        }
    };
    let n = (WINDOW_S * FS_HZ) as usize;
    let (mut freqs, mut rms, mut whole) = (Vec::new(), Vec::new(), Vec::new());
    let mut j = 0;
    for t0 in starts {
        let t1 = t0 + WINDOW_S;
        if jumps.iter().any(|&t| t >= t0 - AFTER_JUMP_S && t <= t1)
            || gaps.iter().any(|&(a, b)| b > t0 && a < t1)
        {
            continue;
        }
        // Linear interpolation of the error onto the uniform grid.
        while j + 1 < tracked.len() && tracked[j + 1].t <= t0 {
            j += 1;
        }
        let mut k = j;
        let mut window = Vec::with_capacity(n);
        for i in 0..n {
            let t = t0 + i as f64 / FS_HZ;
            while k + 1 < tracked.len() && tracked[k + 1].t <= t {
                k += 1;
            }
            let a = tracked[k];
            let b = tracked.get(k + 1).copied().unwrap_or(a);
            let f = if b.t > a.t {
                ((t - a.t) / (b.t - a.t)).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let e = |s: &Sample, ax: usize| (s.desired[ax] - s.actual[ax]) * 1e3;
            window.push([0, 1, 2].map(|ax| e(a, ax) + f * (e(b, ax) - e(a, ax))));
        }
        out.windows += 1;
        if let Some((f, r, share)) = tone(&window, band_from_hz) {
            if r >= MIN_TONE_RMS_MM && share >= MIN_TONE_SHARE {
                freqs.push(f);
                rms.push(r);
                whole.push(window_rms(&window));
            }
        }
    }
    out.windows_with_tone = freqs.len();
    out.frequency_hz = median(&mut freqs);
    out.tone_rms_mm = median(&mut rms);
    out.window_rms_mm = median(&mut whole);
    out.detected = out.windows_with_tone >= MIN_TONE_WINDOWS
        && out.windows_with_tone as f64 >= MIN_WINDOW_SHARE * out.windows as f64;
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Samples at 1 kHz for `secs` along a 0.2 Hz circle of 15 mm, with the
    /// error `error(t)` (m, per axis) between desired and actual.
    fn run(secs: f64, error: impl Fn(f64) -> [f64; 3]) -> Vec<Sample> {
        (0..(secs * 1000.0) as usize)
            .map(|i| {
                let t = i as f64 * 1e-3;
                let a = 2.0 * std::f64::consts::PI * 0.2 * t;
                let desired = [0.015 * a.cos(), 0.015 * a.sin(), 0.39];
                let e = error(t);
                Sample {
                    t,
                    desired,
                    actual: [0, 1, 2].map(|k| desired[k] - e[k]),
                    hold: false,
                    moving: false,
                }
            })
            .collect()
    }

    /// The net's slow error: 0.5 mm following the path at its own frequency
    /// and second harmonic, plus a constant offset.
    fn slow(t: f64) -> [f64; 3] {
        let a = 2.0 * std::f64::consts::PI * 0.2 * t;
        [
            0.5e-3 * a.cos() + 0.2e-3,
            0.3e-3 * (2.0 * a).sin(),
            0.1e-3 * a.sin(),
        ]
    }

    #[test]
    fn a_3_3_hz_ripple_on_a_slow_error_is_flagged_with_its_frequency_and_size() {
        // 1 mm amplitude in x and y, 90° apart (the tip circling): RMS 1 mm.
        let w = 2.0 * std::f64::consts::PI * 3.3;
        let samples = run(10.0, |t| {
            let s = slow(t);
            [
                s[0] + 1e-3 * (w * t).cos(),
                s[1] + 1e-3 * (w * t).sin(),
                s[2],
            ]
        });
        let o = detect(&samples, band_from(0.2));
        assert!(o.detected, "{o:?}");
        assert_eq!(o.windows, 16, "{o:?}");
        let f = o.frequency_hz.unwrap();
        assert!((f - 3.3).abs() < 0.15, "frequency {f}");
        let r = o.tone_rms_mm.unwrap();
        assert!((r - 1.0).abs() < 0.1, "tone RMS {r} mm, expected 1 mm");
    }

    /// A limit cycle that grows after the first 3 s (0.2 → 2 mm) is larger
    /// in most windows than over the whole run, but never larger than the
    /// error in the windows it was found in.
    #[test]
    fn a_growing_ripple_is_bounded_by_its_windows_error_not_by_the_runs() {
        let w = 2.0 * std::f64::consts::PI * 3.3;
        let amplitude = |t: f64| 0.2e-3 + 1.8e-3 * (t - 3.0).clamp(0.0, 1.0);
        let samples = run(10.0, |t| {
            let s = slow(t);
            let a = amplitude(t);
            [s[0] + a * (w * t).cos(), s[1] + a * (w * t).sin(), s[2]]
        });
        let o = detect(&samples, band_from(0.2));
        assert!(o.detected, "{o:?}");
        let tone = o.tone_rms_mm.unwrap();
        let whole = o.window_rms_mm.unwrap();
        assert!(
            tone <= whole,
            "tone {tone} mm above its windows' error {whole} mm"
        );
        assert!(
            tone >= 0.8 * whole,
            "tone {tone} mm, windows' error {whole} mm"
        );
        let run_rms = (samples
            .iter()
            .map(|s| {
                (0..3)
                    .map(|k| (s.desired[k] - s.actual[k]).powi(2))
                    .sum::<f64>()
            })
            .sum::<f64>()
            / samples.len() as f64)
            .sqrt()
            * 1e3;
        assert!(
            run_rms < tone,
            "run {run_rms} mm, tone {tone} mm: the case this test is about"
        );
    }

    #[test]
    fn the_slow_error_alone_is_not_an_oscillation() {
        let o = detect(&run(10.0, slow), band_from(0.2));
        assert!(!o.detected, "{o:?}");
        assert_eq!(o.windows_with_tone, 0, "{o:?}");
    }

    #[test]
    fn white_sensor_noise_is_not_an_oscillation() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let noise: Vec<[f64; 3]> = (0..10_000)
            .map(|_| [0, 1, 2].map(|_| rng.random_range(-0.3e-3..0.3e-3)))
            .collect();
        let o = detect(
            &run(10.0, |t| {
                let s = slow(t);
                let e = noise[((t * 1000.0) as usize).min(9_999)];
                [s[0] + e[0], s[1] + e[1], s[2] + e[2]]
            }),
            band_from(0.2),
        );
        assert!(!o.detected, "{o:?}");
    }

    #[test]
    fn a_small_ripple_or_a_short_burst_is_not_sustained_oscillation() {
        let w = 2.0 * std::f64::consts::PI * 3.3;
        // 0.05 mm: below the stated size.
        let small = detect(
            &run(10.0, |t| {
                let s = slow(t);
                [s[0] + 0.05e-3 * (w * t).cos(), s[1], s[2]]
            }),
            band_from(0.2),
        );
        assert!(!small.detected, "{small:?}");
        // 1 mm, but for 2 s of 10.
        let burst = detect(
            &run(10.0, |t| {
                let s = slow(t);
                let on = if (4.0..6.0).contains(&t) { 1e-3 } else { 0.0 };
                [s[0] + on * (w * t).cos(), s[1], s[2]]
            }),
            band_from(0.2),
        );
        assert!(!burst.detected, "{burst:?}");
        assert!(burst.windows_with_tone > 0, "{burst:?}");
    }

    #[test]
    fn an_error_that_grows_is_growth_and_a_steady_or_settling_one_is_not() {
        // A slow swing that builds up: 0.1 mm early, 2 mm late.
        let grows = growth(&run(12.0, |t| [1e-4 * (1.0 + 1.5 * t), 0.0, 0.0])).unwrap();
        assert!(grows.growing, "{grows:?}");
        assert!(grows.last_third_rms_mm > 3.0 * grows.first_third_rms_mm);
        let steady = growth(&run(12.0, slow)).unwrap();
        assert!(!steady.growing, "{steady:?}");
        // Tiny errors that grow stay below the floor: noise, not a drift.
        let tiny = growth(&run(12.0, |t| [1e-6 * t, 0.0, 0.0])).unwrap();
        assert!(!tiny.growing, "{tiny:?}");
        assert!(growth(&run(0.01, slow)).is_none());
    }
}

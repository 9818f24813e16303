//! The rod's first bending mode from a measured step (`tendril calibrate
//! --step TRACE`, `docs/design.md` §11): the tracker's trace of the tip
//! after a tension step, fitted by one damped sinusoid per axis sharing its
//! decay σ and damped frequency ω_d,
//!
//!   y_c(t) = a_c + e^{−σt} (b_c cos ω_d t + d_c sin ω_d t),  c = x, y, z,
//!
//! by least squares over all eleven parameters (Gauss–Newton from the best
//! point of a grid over ω_d and σ/ω_d, where the model is linear in the
//! rest). The mode is ω_n = √(σ² + ω_d²), ζ = σ/ω_n; the dynamic rod's
//! damping parameter, its retardation time (B = t_r K gives every mode
//! ζ = ω t_r / 2, `dynamics::Damping`), is t_r = 2ζ/ω_n. The 95 % intervals
//! come from the fit's covariance s² (JᵀJ)⁻¹ (s² the residual variance) by
//! the delta method: the tracker's jitter is what they measure.

use std::path::Path;

use nalgebra::{DMatrix, DVector};
use serde::Serialize;

/// Two-sided 95 % point of the normal distribution.
const Z95: f64 = 1.96;

/// The trace: frame times (s) and the tip's positions (m).
#[derive(Clone, Debug, Default)]
pub struct StepTrace {
    /// Sample times, s (increasing).
    pub t_s: Vec<f64>,
    /// Tip positions, m.
    pub tip_m: Vec<[f64; 3]>,
}

/// A value and its 95 % interval.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Estimate {
    /// The fitted value.
    pub value: f64,
    /// Lower and upper ends of its 95 % interval.
    pub interval_95: [f64; 2],
}

impl Estimate {
    fn of(value: f64, sd: f64) -> Estimate {
        Estimate {
            value,
            interval_95: [value - Z95 * sd, value + Z95 * sd],
        }
    }

    /// Whether `x` is inside the interval.
    pub fn covers(&self, x: f64) -> bool {
        self.interval_95[0] <= x && x <= self.interval_95[1]
    }
}

/// The first mode fitted to a step.
#[derive(Clone, Debug, Serialize)]
pub struct StepFit {
    /// Undamped natural frequency f_n, Hz.
    pub freq_hz: Estimate,
    /// Damping ratio ζ.
    pub damping_ratio: Estimate,
    /// Damped frequency f_d (what the rod rings at), Hz.
    pub damped_freq_hz: Estimate,
    /// The dynamic rod's retardation time t_r = 2ζ/ω_n, s: a robot file's
    /// `[damping] retardation_s`.
    pub retardation_s: Estimate,
    /// The ringing's amplitude at the window's start (largest axis), mm.
    pub amplitude_mm: f64,
    /// RMS of the fit's residual per axis, mm: the tracker's jitter, if the
    /// model holds.
    pub residual_mm: f64,
    /// Frames fitted.
    pub frames: usize,
    /// The window fitted, s (trace time).
    pub window_s: [f64; 2],
}

/// Why a trace gives no mode.
#[derive(Debug, thiserror::Error)]
pub enum StepError {
    /// The file could not be read or is not a trace.
    #[error("{0}")]
    Read(String),
    /// Too little of a trace to fit.
    #[error("{0}")]
    TooShort(String),
    /// No ringing above the noise.
    #[error("{0}")]
    NoRinging(String),
}

/// Read a trace: CSV with a time column (`t_s`, or `t_ns` as a tendril
/// plant log has) and the tip's position in metres (`x_m,y_m,z_m`, or a
/// plant log's measured `mx,my,mz`, or `px,py,pz`). Rows that repeat the
/// previous position (a log that holds the last frame) are one frame.
pub fn read_trace(path: &Path) -> Result<StepTrace, StepError> {
    let bad = |what: String| StepError::Read(format!("{}: {what}", path.display()));
    let mut reader = csv::Reader::from_path(path).map_err(|e| bad(e.to_string()))?;
    let header = reader.headers().map_err(|e| bad(e.to_string()))?.clone();
    let find = |name: &str| header.iter().position(|h| h.trim() == name);
    let (time, scale) = match (find("t_s"), find("t_ns")) {
        (Some(i), _) => (i, 1.0),
        (None, Some(i)) => (i, 1e-9),
        _ => return Err(bad("no time column (t_s or t_ns)".into())),
    };
    let position = [
        ["x_m", "y_m", "z_m"],
        ["mx", "my", "mz"],
        ["px", "py", "pz"],
    ]
    .iter()
    .find_map(|names| {
        let cols: Option<Vec<usize>> = names.iter().map(|n| find(n)).collect();
        cols.map(|c| [c[0], c[1], c[2]])
    })
    .ok_or_else(|| bad("no position columns (x_m,y_m,z_m; mx,my,mz; or px,py,pz)".into()))?;
    let mut trace = StepTrace::default();
    for (line, record) in reader.records().enumerate() {
        let record = record.map_err(|e| bad(e.to_string()))?;
        let number = |i: usize| -> Result<f64, StepError> {
            let cell = record.get(i).unwrap_or("").trim();
            cell.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    bad(format!(
                        "line {}: {cell:?} is not a finite number",
                        line + 2
                    ))
                })
        };
        let t = number(time)? * scale;
        let p = [
            number(position[0])?,
            number(position[1])?,
            number(position[2])?,
        ];
        trace
            .push(t, p)
            .map_err(|why| bad(format!("line {}: {why}", line + 2)))?;
    }
    Ok(trace)
}

impl StepTrace {
    /// Add a tracker frame at `t` s: a frame equal to the last one is the
    /// same frame repeated (a log row per loop step) and is skipped; time
    /// must increase.
    pub fn push(&mut self, t: f64, p: [f64; 3]) -> Result<(), String> {
        if self.tip_m.last() == Some(&p) {
            return Ok(());
        }
        if self.t_s.last().is_some_and(|&last| t <= last) {
            return Err(format!("time {t} s does not increase"));
        }
        self.t_s.push(t);
        self.tip_m.push(p);
        Ok(())
    }
}

/// The model's value and its derivatives at one sample.
struct Basis {
    e_cos: f64,
    e_sin: f64,
}

fn basis(t: f64, sigma: f64, omega: f64) -> Basis {
    let e = (-sigma * t).exp();
    Basis {
        e_cos: e * (omega * t).cos(),
        e_sin: e * (omega * t).sin(),
    }
}

/// Least squares of each axis on (1, e cos, e sin) at fixed (σ, ω): the
/// coefficients and the residual sum of squares.
fn linear_fit(t: &[f64], y: &[[f64; 3]], sigma: f64, omega: f64) -> ([[f64; 3]; 3], f64) {
    let mut ata = nalgebra::Matrix3::<f64>::zeros();
    let mut aty = [nalgebra::Vector3::<f64>::zeros(); 3];
    for (&ti, yi) in t.iter().zip(y) {
        let b = basis(ti, sigma, omega);
        let row = nalgebra::Vector3::new(1.0, b.e_cos, b.e_sin);
        ata += row * row.transpose();
        for (c, v) in aty.iter_mut().zip(yi) {
            *c += row * *v;
        }
    }
    let Some(inverse) = ata.try_inverse() else {
        return ([[0.0; 3]; 3], f64::INFINITY);
    };
    let coef: [[f64; 3]; 3] = std::array::from_fn(|c| {
        let x = inverse * aty[c];
        [x[0], x[1], x[2]]
    });
    let rss = rss_of(t, y, sigma, omega, &coef);
    (coef, rss)
}

/// The residual sum of squares of the model (σ, ω, per-axis coefficients).
fn rss_of(t: &[f64], y: &[[f64; 3]], sigma: f64, omega: f64, coef: &[[f64; 3]; 3]) -> f64 {
    t.iter()
        .zip(y)
        .map(|(&ti, yi)| {
            let b = basis(ti, sigma, omega);
            (0..3)
                .map(|c| (yi[c] - coef[c][0] - coef[c][1] * b.e_cos - coef[c][2] * b.e_sin).powi(2))
                .sum::<f64>()
        })
        .sum()
}

/// Fit the first mode to `trace` from `skip_s` after its first frame (the
/// step; the motors' rise and the higher modes are over by then).
pub fn fit_step(trace: &StepTrace, skip_s: f64) -> Result<StepFit, StepError> {
    let start = trace.t_s.first().copied().unwrap_or(0.0) + skip_s.max(0.0);
    let from = trace.t_s.partition_point(|&t| t < start);
    let t: Vec<f64> = trace.t_s[from..].iter().map(|&v| v - start).collect();
    let y = &trace.tip_m[from..];
    let n = t.len();
    let span = t.last().copied().unwrap_or(0.0);
    if n < 30 || span <= 0.0 {
        return Err(StepError::TooShort(format!(
            "{n} frames over {span:.2} s after the first {skip_s} s: a step trace needs at least \
             30 frames over several periods of the ringing"
        )));
    }
    // The grid: damped frequencies from two periods in the window to a
    // third of the frame rate, 1 % apart; decays from 1 % to 40 % of ω.
    let median_dt = {
        let mut d: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
        d.sort_by(f64::total_cmp);
        d[d.len() / 2]
    };
    let (low, high) = (
        std::f64::consts::TAU * 2.0 / span,
        std::f64::consts::TAU / (3.0 * median_dt),
    );
    if low >= high {
        return Err(StepError::TooShort(format!(
            "a {span:.2} s window at {:.0} frames/s holds no two periods of any frequency it can resolve",
            1.0 / median_dt
        )));
    }
    let mut best = (f64::INFINITY, 0.0, 0.0);
    let mut omega = low;
    while omega <= high {
        for ratio in [0.01, 0.02, 0.05, 0.1, 0.2, 0.4] {
            let (_, rss) = linear_fit(&t, y, ratio * omega, omega);
            if rss < best.0 {
                best = (rss, ratio * omega, omega);
            }
        }
        omega *= 1.01;
    }
    let (_, mut sigma, mut omega) = best;
    let (mut coef, mut rss) = linear_fit(&t, y, sigma, omega);
    // Gauss–Newton on all eleven parameters, with a Levenberg damping that
    // grows when a step does not lower the residual.
    let p = 11;
    let mut lambda = 1e-3;
    let jacobian = |sigma: f64, omega: f64, coef: &[[f64; 3]; 3]| {
        let mut j = DMatrix::<f64>::zeros(3 * n, p);
        let mut r = DVector::<f64>::zeros(3 * n);
        for (i, (&ti, yi)) in t.iter().zip(y).enumerate() {
            let b = basis(ti, sigma, omega);
            for c in 0..3 {
                let [a, bc, dc] = coef[c];
                let row = 3 * i + c;
                r[row] = yi[c] - (a + bc * b.e_cos + dc * b.e_sin);
                j[(row, 0)] = -ti * (bc * b.e_cos + dc * b.e_sin);
                j[(row, 1)] = ti * (-bc * b.e_sin + dc * b.e_cos);
                j[(row, 2 + 3 * c)] = 1.0;
                j[(row, 3 + 3 * c)] = b.e_cos;
                j[(row, 4 + 3 * c)] = b.e_sin;
            }
        }
        (j, r)
    };
    for _ in 0..50 {
        let (j, r) = jacobian(sigma, omega, &coef);
        let jtj = j.transpose() * &j;
        let jtr = j.transpose() * &r;
        let mut damped = jtj.clone();
        for k in 0..p {
            damped[(k, k)] *= 1.0 + lambda;
        }
        let Some(step) = damped.lu().solve(&jtr) else {
            break;
        };
        let (s2, w2) = (sigma + step[0], omega + step[1]);
        let c2: [[f64; 3]; 3] =
            std::array::from_fn(|c| std::array::from_fn(|k| coef[c][k] + step[2 + 3 * c + k]));
        let rss2 = rss_of(&t, y, s2, w2, &c2);
        if rss2 < rss && w2 > 0.0 {
            let done = (rss - rss2) < 1e-12 * rss;
            (sigma, omega, coef, rss) = (s2, w2, c2, rss2);
            lambda = (lambda * 0.3).max(1e-9);
            if done {
                break;
            }
        } else {
            lambda *= 10.0;
            if lambda > 1e8 {
                break;
            }
        }
    }
    let (j, _) = jacobian(sigma, omega, &coef);
    let dof = (3 * n).saturating_sub(p).max(1) as f64;
    let s2 = rss / dof;
    let covariance = (j.transpose() * &j).try_inverse().ok_or_else(|| {
        StepError::NoRinging("the fit is singular: no ringing in the trace".into())
    })? * s2;
    let amplitude = coef.iter().map(|c| c[1].hypot(c[2])).fold(0.0, f64::max);
    let residual = (s2 * dof / (3 * n) as f64).sqrt();
    if !(sigma > 0.0 && omega > 0.0) || amplitude < 3.0 * residual {
        return Err(StepError::NoRinging(format!(
            "no decaying ringing above the noise: amplitude {:.4} mm against a residual of {:.4} mm \
             (σ {sigma:.3} /s): give a larger step or a trace that starts at it",
            amplitude * 1e3,
            residual * 1e3
        )));
    }
    // The delta method on (σ, ω_d).
    let (vss, vsw, vww) = (covariance[(0, 0)], covariance[(0, 1)], covariance[(1, 1)]);
    let through =
        |g: [f64; 2]| (g[0] * g[0] * vss + 2.0 * g[0] * g[1] * vsw + g[1] * g[1] * vww).sqrt();
    let wn = sigma.hypot(omega);
    let tau = std::f64::consts::TAU;
    let freq_sd = through([sigma / wn, omega / wn]) / tau;
    let zeta_sd = through([omega * omega / wn.powi(3), -sigma * omega / wn.powi(3)]);
    let tr_sd = through([
        2.0 * (omega * omega - sigma * sigma) / wn.powi(4),
        -4.0 * sigma * omega / wn.powi(4),
    ]);
    Ok(StepFit {
        freq_hz: Estimate::of(wn / tau, freq_sd),
        damping_ratio: Estimate::of(sigma / wn, zeta_sd),
        damped_freq_hz: Estimate::of(omega / tau, vww.sqrt() / tau),
        retardation_s: Estimate::of(2.0 * sigma / (wn * wn), tr_sd),
        amplitude_mm: amplitude * 1e3,
        residual_mm: residual * 1e3,
        frames: n,
        window_s: [start, start + span],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A synthetic damped sinusoid with a known mode and white jitter: the
    /// fit finds it, and its 95 % intervals cover the truth.
    #[test]
    fn a_damped_sinusoid_is_fitted_with_intervals_that_cover_it() {
        let (f, zeta) = (3.6, 0.05);
        let wn = std::f64::consts::TAU * f;
        let (sigma, wd) = (zeta * wn, wn * (1.0 - zeta * zeta).sqrt());
        let mut state = 12345u64;
        let mut noise = || {
            // A sum of uniforms: near-normal, σ 0.14 mm.
            let mut s = 0.0;
            for _ in 0..12 {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                s += (state >> 11) as f64 / (1u64 << 53) as f64;
            }
            (s - 6.0) * 0.14e-3
        };
        let mut trace = StepTrace::default();
        for i in 0..160 {
            let t = i as f64 / 40.0;
            let ring = (-sigma * t).exp() * (wd * t).cos();
            trace.t_s.push(t + 100.0);
            trace.tip_m.push([
                0.01 + 2e-3 * ring + noise(),
                0.5e-3 * ring + noise(),
                0.3 + noise(),
            ]);
        }
        let fit = fit_step(&trace, 0.0).unwrap();
        assert!(fit.freq_hz.covers(f), "{fit:?}");
        assert!(fit.damping_ratio.covers(zeta), "{fit:?}");
        assert!(fit.retardation_s.covers(2.0 * zeta / wn), "{fit:?}");
        let width = fit.damping_ratio.interval_95[1] - fit.damping_ratio.interval_95[0];
        assert!(width < 0.02, "ζ within ±1 %: {fit:?}");
        assert!((fit.residual_mm - 0.14).abs() < 0.03, "{fit:?}");
        // A trace with nothing but jitter rings at nothing.
        let flat = StepTrace {
            t_s: trace.t_s.clone(),
            tip_m: trace
                .t_s
                .iter()
                .map(|_| [noise(), noise(), noise()])
                .collect(),
        };
        assert!(matches!(fit_step(&flat, 0.0), Err(StepError::NoRinging(_))));
        let short = StepTrace {
            t_s: trace.t_s[..10].to_vec(),
            tip_m: trace.tip_m[..10].to_vec(),
        };
        assert!(matches!(fit_step(&short, 0.0), Err(StepError::TooShort(_))));
    }
}

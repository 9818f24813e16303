//! `tendril sim`'s verdicts on a drive's run (`docs/design.md` §13): the
//! sim report's own tests, applied to the tracker's tips against the path
//! where the planner was when each was sampled — the robot's true tip is
//! the robot's own.

use serde::Serialize;
use tendril::ipc::sim::analysis::{steady_states, Sample};
use tendril::ipc::sim::oscillation::{self, Growth, Oscillation};
use tendril::ipc::sim::report::SteadyState;
use tendril::plan::PathShape;

/// The verdicts, with their evidence (`--stats`).
#[derive(Clone, Debug, Default, Serialize)]
pub struct Verdicts {
    /// What `tendril sim` would call a problem of the loop: an
    /// oscillation, a growing error, a tracking error above the bound.
    /// Empty: the run is clean.
    pub problems: Vec<String>,
    /// The tone test.
    pub oscillation: Oscillation,
    /// The error's last third against its first (`None`: too few tips).
    pub growth: Option<Growth>,
    /// Every stretch of at least 1 s with a fixed desired position (steps,
    /// targets): its steady error, settle time and ringing.
    pub steady_states: Vec<SteadyState>,
}

/// What the tracking error is held to, by the path's kind (as `tendril
/// sim` holds it).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bound {
    /// The RMS is the path's accuracy (a smooth path); otherwise its steady
    /// states are (steps, a table, targets: the RMS would be the moves'
    /// transients).
    pub rms: bool,
    /// The bound, mm (`--max-rms-mm`).
    pub max_rms_mm: f64,
}

impl Bound {
    /// The bound for following `shape`, or targets from a topic.
    pub fn of(shape: &PathShape, target_topic: bool, max_rms_mm: f64) -> Bound {
        Bound {
            rms: !target_topic
                && !matches!(shape, PathShape::Steps { .. } | PathShape::Table { .. }),
            max_rms_mm,
        }
    }
}

/// Judge the tips: the tone test above the path's fundamental `path_hz`,
/// the error's growth and the bound (smooth paths), the steady states and
/// the bound on the worst of them (steps, targets).
pub fn judge(
    samples: &[Sample],
    path_hz: f64,
    bound: Bound,
    tracking_rms_mm: Option<f64>,
) -> Verdicts {
    let oscillation = oscillation::detect(samples, oscillation::band_from(path_hz));
    let growth = oscillation::growth(samples);
    let steady = steady_states(samples);
    let mut problems = Vec::new();
    if let (true, Some(f), Some(r)) = (
        oscillation.detected,
        oscillation.frequency_hz,
        oscillation.tone_rms_mm,
    ) {
        problems.push(format!(
            "the loop oscillates: {f:.2} Hz, {r:.3} mm RMS in the tracking error, in {} of \
             {} 2 s windows",
            oscillation.windows_with_tone, oscillation.windows
        ));
    }
    let max = bound.max_rms_mm;
    if bound.rms {
        if let Some(g) = growth.as_ref().filter(|g| g.growing) {
            problems.push(format!(
                "the tracking error grows ({:.3} mm RMS in the run's first third, {:.3} mm \
                 in its last)",
                g.first_third_rms_mm, g.last_third_rms_mm
            ));
        }
        if let Some(rms) = tracking_rms_mm.filter(|&r| r > max) {
            problems.push(format!(
                "RMS tracking error {rms:.3} mm exceeds the bound {max} mm (--max-rms-mm)"
            ));
        }
    } else if let Some(worst) = (steady.iter())
        .max_by(|a, b| a.error_mm.total_cmp(&b.error_mm))
        .filter(|s| s.error_mm > max)
    {
        problems.push(format!(
            "steady-state error {:.3} mm at {:.1} s exceeds the bound {max} mm (--max-rms-mm)",
            worst.error_mm, worst.t_s
        ));
    }
    Verdicts {
        problems,
        oscillation,
        growth,
        steady_states: steady,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hold() -> PathShape {
        PathShape::Hold {
            center_m: vec![0.0, 0.0],
            height_m: None,
        }
    }

    /// Ten seconds of tips at 200 Hz on a 0.2 Hz circle of 15 mm, off the
    /// path by `tone_mm` at 3.5 Hz (amplitude) and a constant `offset_mm`.
    fn circle(tone_mm: f64, offset_mm: f64) -> Vec<Sample> {
        (0..2000)
            .map(|i| {
                let t = i as f64 / 200.0;
                let w = 2.0 * std::f64::consts::PI * 0.2 * t;
                let d = [0.015 * w.cos(), 0.015 * w.sin(), 0.0];
                let e = 1e-3 * (tone_mm * (2.0 * std::f64::consts::PI * 3.5 * t).sin() + offset_mm);
                Sample {
                    t,
                    desired: d,
                    actual: [d[0] + e, d[1], d[2]],
                    hold: false,
                    moving: false,
                }
            })
            .collect()
    }

    fn rms_mm(samples: &[Sample]) -> Option<f64> {
        let sum: f64 = samples.iter().map(|s| s.error_mm().powi(2)).sum();
        Some((sum / samples.len() as f64).sqrt())
    }

    #[test]
    fn a_circle_tracked_within_the_bound_is_clean() {
        let s = circle(0.0, 0.05);
        let v = judge(&s, 0.2, Bound::of(&hold(), false, 2.0), rms_mm(&s));
        assert!(v.problems.is_empty(), "{:?}", v.problems);
        assert!(v.oscillation.windows >= 10 && !v.oscillation.detected);
    }

    #[test]
    fn a_tone_above_the_path_is_an_oscillation_at_its_frequency() {
        let s = circle(0.3, 0.0);
        let v = judge(&s, 0.2, Bound::of(&hold(), false, 2.0), rms_mm(&s));
        let f = v.oscillation.frequency_hz.unwrap();
        assert!(
            v.oscillation.detected && (f - 3.5).abs() < 0.3,
            "{:?}",
            v.oscillation
        );
        assert!(v.problems[0].contains("oscillates"), "{:?}", v.problems);
    }

    #[test]
    fn above_the_bound_is_a_problem_on_a_smooth_path_and_on_the_steady_states_of_targets() {
        let s = circle(0.0, 3.0);
        let v = judge(&s, 0.2, Bound::of(&hold(), false, 2.0), rms_mm(&s));
        assert!(
            v.problems
                .iter()
                .any(|p| p.contains("RMS tracking error 3.000 mm")),
            "{:?}",
            v.problems
        );
        // Targets from a topic: a held target 3 mm off is judged by its
        // steady state, not the RMS.
        let held: Vec<Sample> = (0..600)
            .map(|i| Sample {
                t: i as f64 / 200.0,
                desired: [0.01, 0.0, 0.0],
                actual: [0.013, 0.0, 0.0],
                hold: false,
                moving: false,
            })
            .collect();
        let v = judge(&held, 0.0, Bound::of(&hold(), true, 2.0), None);
        assert_eq!(v.steady_states.len(), 1);
        assert!(
            v.problems
                .iter()
                .any(|p| p.contains("steady-state error 3.000 mm")),
            "{:?}",
            v.problems
        );
    }
}

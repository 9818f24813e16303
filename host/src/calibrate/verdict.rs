//! Whether a fit is a calibration (`docs/design.md` §11): a fit that
//! fixed everything, ran into its bounds, judges worse on the rows it did
//! not see, or leaves residuals no tracker makes is reported as such —
//! `tendril calibrate` then writes its report and no robot file, and exits
//! non-zero (issue 47: each of these used to write a "calibrated" file).

use super::report::{Report, Verdict};

/// Residual noise per axis above which no tracker explains the rows, m:
/// EM trackers jitter ≈ 0.14 mm and are ≈ 1 mm off near metal, optical
/// ones jitter 0.05–0.25 mm (`docs/design.md` §11). Above it, most rows
/// are outliers or the model misses the robot, and the robust loss cannot
/// tell which: its noise scale is the median row's.
pub const MAX_TRACKER_SIGMA_M: f64 = 1e-3;
/// The fit misses its own rows by more than this fraction of how far the
/// tips are apart: the model does not describe the rows.
pub const MAX_RESIDUAL_OF_SPREAD: f64 = 0.25;
/// Held-out rows may judge the fit this much worse than the nominal file
/// (median) before it counts as worse: noise on a file that was right.
const HELD_OUT_TOLERANCE: f64 = 1.05;

/// What [`judge`] needs besides the report.
pub struct Evidence {
    /// Fitted parameters that ended at a bound of the fit, with the bound.
    pub at_bound: Vec<String>,
    /// The measured tips' median distance from their median, m.
    pub median_spread_m: f64,
}

/// Judge `report` (see the module documentation).
pub fn judge(report: &Report, evidence: &Evidence) -> Verdict {
    let mm = |x: f64| x * 1e3;
    let mut problems = Vec::new();
    if report.parameters.iter().all(|p| p.fixed) {
        problems.push(
            "nothing was fitted: every parameter of --fit was fixed as not identifiable".into(),
        );
    }
    if !evidence.at_bound.is_empty() {
        problems.push(format!(
            "{} ended at the bound of the fit: the rows pull further than a calibration may \
             move the file (another robot, or rows in other units?)",
            evidence.at_bound.join(", ")
        ));
    }
    let (before, after) = (&report.held_out_before, &report.held_out_after);
    if after.rows > 0 && after.median_m > HELD_OUT_TOLERANCE * before.median_m + 1e-6 {
        problems.push(format!(
            "the held-out rows fit worse after the fit (median {:.3} mm against {:.3} mm \
             before): it fitted the rows' noise or outliers, not the robot",
            mm(after.median_m),
            mm(before.median_m)
        ));
    }
    // Noise on the recorded tensions moves the rows' tips through the
    // robot's compliance: twice its predicted scatter more may remain.
    let tension = report.tension_scatter_m.unwrap_or(0.0);
    if report.robust_sigma_m > MAX_TRACKER_SIGMA_M + 2.0 * tension {
        let why = if tension > 0.0 {
            format!(
                "more than a tracker's noise (at most 1 mm) and twice the {:.2} mm the load \
                 cells' noise makes",
                mm(tension)
            )
        } else {
            "more than a tracker's noise (at most 1 mm; noisy load cells: give \
             --tension-noise-n)"
                .to_string()
        };
        problems.push(format!(
            "the residual is {:.2} mm per axis (robust σ), {why}: most rows are outliers, or \
             the rows are another robot's, or not in metres and newtons — the fit cannot tell \
             which",
            mm(report.robust_sigma_m)
        ));
    }
    let miss = report.fit_after.median_m;
    if miss > MAX_RESIDUAL_OF_SPREAD * evidence.median_spread_m {
        problems.push(format!(
            "the calibrated model misses its own rows by {:.3} mm (median), a quarter or more \
             of how far the measured tips are apart ({:.3} mm): the model does not describe \
             these rows",
            mm(miss),
            mm(evidence.median_spread_m)
        ));
    }
    Verdict {
        calibrated: problems.is_empty(),
        problems,
    }
}

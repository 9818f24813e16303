//! What a calibration tells the user: fitted values with 95 % intervals,
//! what the data cannot separate, residuals before and after, the rows the
//! robust loss down-weighted. Serialised as JSON and rendered as markdown.

use serde::Serialize;

/// One parameter of `--fit`.
#[derive(Clone, Debug, Serialize)]
pub struct FittedParam {
    /// Name (`E`, `offset[2]`, `base_tx`).
    pub name: String,
    /// Unit of the values.
    pub unit: String,
    /// The nominal file's value.
    pub nominal: f64,
    /// The fitted value (the nominal one when `fixed`).
    pub fitted: f64,
    /// Standard deviation from the covariance σ² (JᵀWJ)⁻¹ (NaN when fixed).
    pub std: f64,
    /// Half-width of the 95 % interval, 1.96 σ (NaN when fixed).
    pub half_width_95: f64,
    /// Fixed at the nominal value because the data cannot determine it.
    pub fixed: bool,
}

/// A parameter the data cannot separate from others, hence fixed.
#[derive(Clone, Debug, Serialize)]
pub struct Unidentified {
    /// The parameter fixed at its nominal value.
    pub fixed: String,
    /// The parameters it moves with in the undetermined direction.
    pub confounded_with: Vec<String>,
    /// Standard deviation of that direction, as a fraction of the scales.
    pub std_fraction: f64,
    /// What data would separate them.
    pub separate_with: String,
}

/// A row the Huber loss down-weighted below one half.
#[derive(Clone, Debug, Serialize)]
pub struct DownWeighted {
    /// Line of the measured CSV (header = line 1).
    pub line: usize,
    /// The row's residual norm at the fit, m (orientation weighed in).
    pub residual_m: f64,
    /// Its weight.
    pub weight: f64,
}

/// Tip position errors ‖p_measured − p_model‖ over a set of rows (all
/// zero for no rows: check `rows` before reading them).
#[derive(Clone, Debug, Serialize)]
pub struct ResidualStats {
    /// Rows.
    pub rows: usize,
    /// Root mean square, m.
    pub rms_m: f64,
    /// Median, m.
    pub median_m: f64,
    /// Largest, m.
    pub max_m: f64,
}

impl ResidualStats {
    /// The statistics of `errors` (m); zeros for no rows.
    pub fn of(errors: impl Iterator<Item = f64>) -> ResidualStats {
        let mut e: Vec<f64> = errors.collect();
        e.sort_by(f64::total_cmp);
        let n = e.len();
        if n == 0 {
            return ResidualStats {
                rows: 0,
                rms_m: 0.0,
                median_m: 0.0,
                max_m: 0.0,
            };
        }
        ResidualStats {
            rows: n,
            rms_m: (e.iter().map(|x| x * x).sum::<f64>() / n as f64).sqrt(),
            median_m: e[n / 2],
            max_m: e[n - 1],
        }
    }
}

/// The judgement on a fit ([`super::verdict::judge`]).
#[derive(Clone, Debug, Default, Serialize)]
pub struct Verdict {
    /// The robot file is a calibration: none of the problems below.
    pub calibrated: bool,
    /// One line per reason it is not.
    pub problems: Vec<String>,
}

/// The calibration report.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// Name of the nominal robot.
    pub robot: String,
    /// Rows the fit used.
    pub rows_fit: usize,
    /// Rows held out to judge it.
    pub rows_held_out: usize,
    /// Whether orientations entered the fit.
    pub used_orientation: bool,
    /// Relative central-difference step of the sensitivities.
    pub fd_step_relative: f64,
    /// Every parameter of `--fit`.
    pub parameters: Vec<FittedParam>,
    /// What was fixed because the data cannot separate it.
    pub unidentifiable: Vec<Unidentified>,
    /// Fitted pairs with |correlation| > 0.95.
    pub correlated: Vec<(String, String, f64)>,
    /// Residual standard deviation per axis, √(Σ w‖r‖² / (m − p)), m.
    pub residual_sigma_m: f64,
    /// Robust (median-based) per-axis noise scale, m.
    pub robust_sigma_m: f64,
    /// The load cells' noise the fit was told of (`--tension-noise-n`), N.
    pub tension_noise_n: f64,
    /// The tip scatter per axis that noise makes through the robot's
    /// compliance (RMS over the fit rows, from the statics' tangent), m;
    /// None without tension noise.
    pub tension_scatter_m: Option<f64>,
    /// Rows with any down-weighting.
    pub rows_with_weight_below_1: usize,
    /// Rows weighted below one half, named.
    pub downweighted: Vec<DownWeighted>,
    /// Tip errors of the nominal model on the fit rows.
    pub fit_before: ResidualStats,
    /// ... of the calibrated model.
    pub fit_after: ResidualStats,
    /// Tip errors of the nominal model on the held-out rows.
    pub held_out_before: ResidualStats,
    /// ... of the calibrated model.
    pub held_out_after: ResidualStats,
    /// Levenberg–Marquardt iterations.
    pub iterations: usize,
    /// Statics solves.
    pub solves: usize,
    /// Wall time, s.
    pub seconds: f64,
    /// Whether the fit is a calibration, and why not
    /// ([`super::verdict::judge`]).
    pub verdict: Verdict,
}

impl Report {
    /// The report as pretty JSON (what `tendril calibrate` writes).
    pub fn json(&self) -> String {
        // Plain data of numbers and strings: serialising cannot fail.
        serde_json::to_string_pretty(self).expect("a report serialises")
    }

    /// A note when the fit turned the tracker's frame (from the nominal
    /// file's `[base]`) by more than the tip noise at the rod's length. The
    /// calibrated file's `[base]` carries the turn, so the loop uses it
    /// (`docs/design.md` §2.4); but with E fixed the turn is not only the
    /// tracker's: the base tilt absorbs the weak signal that would separate
    /// E (§11), and the file is then right only with its frame. None
    /// without `length` among the parameters (no length to scale by).
    pub fn frame_rotation_note(&self) -> Option<String> {
        let fitted = |name: &str| self.parameters.iter().find(|p| p.name == name && !p.fixed);
        let value = |name: &str| fitted(name).map(|p| p.fitted);
        let w: Vec<f64> = ["base_rx", "base_ry", "base_rz"]
            .iter()
            .map(|n| fitted(n).map_or(0.0, |p| p.fitted - p.nominal))
            .collect();
        let angle = w.iter().map(|x| x * x).sum::<f64>().sqrt();
        let length = value("length").or_else(|| {
            self.parameters
                .iter()
                .find(|p| p.name == "length")
                .map(|p| p.nominal)
        })?;
        let at_tip = angle * length;
        if at_tip <= self.residual_sigma_m.max(10e-6) {
            return None;
        }
        Some(format!(
            "The fit turned the tracker's frame by ({:.2}, {:.2}, {:.2}) mrad, up to {:.2} mm at \
             the tip. The calibrated file's [base] carries the turn, and the planner, the \
             controller and fk/ik use it; but with E fixed it also carries part of the robot \
             (the base tilt absorbs the signal that separates E), so keep the file and its \
             [base] together. Rows with a known tip load (calibrate --plan-tip-mass-g) make E \
             identifiable; if the tracker's orientation relative to the base is known, fit \
             `base_t` instead of `base`.",
            w[0] * 1e3,
            w[1] * 1e3,
            w[2] * 1e3,
            at_tip * 1e3
        ))
    }

    /// The report as markdown.
    pub fn markdown(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        let mm = |x: f64| format!("{:.3}", x * 1e3);
        let _ = writeln!(s, "# Calibration of {}\n", self.robot);
        if !self.verdict.calibrated {
            let _ = writeln!(
                s,
                "**Not a calibration: no robot file was written.**\n\n{}\n",
                self.verdict
                    .problems
                    .iter()
                    .map(|p| format!("- {p}"))
                    .collect::<Vec<_>>()
                    .join("\n")
            );
        }
        let _ = writeln!(
            s,
            "{} fit rows, {} held out; orientation {}; {} LM iterations, {} solves, {:.2} s; \
             sensitivities from the statics' tangent, the residuals differenced over a \
             relative step {:e}.\n",
            self.rows_fit,
            self.rows_held_out,
            if self.used_orientation {
                "used"
            } else {
                "not used"
            },
            self.iterations,
            self.solves,
            self.seconds,
            self.fd_step_relative
        );
        let _ = writeln!(s, "## Parameters (95 % intervals)\n");
        let _ = writeln!(s, "| parameter | nominal | fitted | ± 95 % | unit |");
        let _ = writeln!(s, "|---|---|---|---|---|");
        for p in &self.parameters {
            let pm = if p.fixed {
                "fixed (not identifiable)".to_string()
            } else {
                format!("{:.4e}", p.half_width_95)
            };
            let _ = writeln!(
                s,
                "| {} | {:.6e} | {:.6e} | {} | {} |",
                p.name, p.nominal, p.fitted, pm, p.unit
            );
        }
        if !self.unidentifiable.is_empty() {
            let _ = writeln!(s, "\n## Not identifiable from these data\n");
            for u in &self.unidentifiable {
                let _ = writeln!(
                    s,
                    "- **{}** moves with {} ({}): fixed at the nominal value; those parameters \
                     are effective values relative to it. To separate them: {}.",
                    u.fixed,
                    if u.confounded_with.is_empty() {
                        "nothing the tip sees".to_string()
                    } else {
                        u.confounded_with.join(", ")
                    },
                    if u.std_fraction.is_finite() {
                        format!("σ of that direction {:.2} of the scales", u.std_fraction)
                    } else {
                        "unseen in these rows whatever their number".to_string()
                    },
                    u.separate_with
                );
            }
        }
        if let Some(note) = self.frame_rotation_note() {
            let _ = writeln!(s, "\n## The tracker frame's rotation\n\n{note}");
        }
        if !self.correlated.is_empty() {
            let _ = writeln!(s, "\n## Strongly correlated fitted pairs\n");
            for (a, b, c) in &self.correlated {
                let _ = writeln!(s, "- {a} and {b}: {c:.3}");
            }
        }
        let _ = writeln!(s, "\n## Tip position error (mm)\n");
        let _ = writeln!(s, "| rows | model | rms | median | max |");
        let _ = writeln!(s, "|---|---|---|---|---|");
        for (rows, model, st) in [
            ("fit", "nominal", &self.fit_before),
            ("fit", "calibrated", &self.fit_after),
            ("held out", "nominal", &self.held_out_before),
            ("held out", "calibrated", &self.held_out_after),
        ] {
            if st.rows == 0 {
                // No rows, no figure: a zero would read as a perfect fit.
                let _ = writeln!(s, "| {rows} (0) | {model} | — | — | — |");
                continue;
            }
            let _ = writeln!(
                s,
                "| {rows} ({}) | {model} | {} | {} | {} |",
                st.rows,
                mm(st.rms_m),
                mm(st.median_m),
                mm(st.max_m)
            );
        }
        let _ = writeln!(
            s,
            "\nResidual σ per axis {} mm (robust {} mm).",
            mm(self.residual_sigma_m),
            mm(self.robust_sigma_m)
        );
        if let Some(t) = self.tension_scatter_m {
            let _ = writeln!(
                s,
                "The load cells' {} N of noise makes {} mm per axis at the tip (the robot's \
                 compliance at the fitted values).",
                self.tension_noise_n,
                mm(t)
            );
        }
        let _ = writeln!(
            s,
            "\n## Down-weighted rows\n\n{} rows have a Huber weight below 1; below 0.5 (outliers): {}.",
            self.rows_with_weight_below_1,
            if self.downweighted.is_empty() {
                "none".to_string()
            } else {
                self.downweighted
                    .iter()
                    .map(|d| format!("line {} ({} mm, weight {:.2})", d.line, mm(d.residual_m), d.weight))
                    .collect::<Vec<_>>()
                    .join(", ")
            }
        );
        s
    }
}

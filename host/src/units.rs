//! Numbers for people: every value a user reads keeps at least two
//! significant digits, and a length is printed in the unit that fits its
//! size (a 0.06 µm tip error used to print as "0.000 mm"). Machine-readable
//! output (CSV, JSON) keeps full precision; this is for the console, the
//! report tables and the chart labels only.

/// Significant digits every printed value keeps at least.
const SIGNIFICANT: i32 = 2;

/// Decimals that show `v` with at least [`SIGNIFICANT`] significant digits,
/// and never fewer than `min_decimals`. Zero and non-finite values need no
/// more than `min_decimals`.
fn decimals(v: f64, min_decimals: usize) -> usize {
    if v == 0.0 || !v.is_finite() {
        return min_decimals;
    }
    // Rounded to two significant digits first, so 0.0999 counts as 0.10
    // (two decimals), not as 0.0999 (three).
    let magnitude = round_significant(v.abs()).log10().floor() as i32;
    let needed = (SIGNIFICANT - 1 - magnitude).max(0) as usize;
    needed.max(min_decimals)
}

/// `v` rounded to [`SIGNIFICANT`] significant digits.
fn round_significant(v: f64) -> f64 {
    if v == 0.0 || !v.is_finite() {
        return v;
    }
    let scale = 10f64.powi(SIGNIFICANT - 1 - v.abs().log10().floor() as i32);
    (v * scale).round() / scale
}

/// A plain number with at least `min_decimals` decimals and at least two
/// significant digits: `number(0.2, 3)` is "0.200", `number(1.5e-5, 3)` is
/// "0.000015", `number(36.04, 1)` is "36.0". Zero is "0" followed by
/// `min_decimals` zeros; NaN and infinities print as Rust prints them.
pub fn number(v: f64, min_decimals: usize) -> String {
    format!("{:.*}", decimals(v, min_decimals), v)
}

/// Whether `a` is below `b` at the precision both would be printed with by
/// [`number`]: rounded to the decimals the larger of the two needs.
pub fn shown_below(a: f64, b: f64, min_decimals: usize) -> bool {
    if !a.is_finite() {
        return false;
    }
    if !b.is_finite() {
        return true;
    }
    let d = decimals(a.abs().max(b.abs()), min_decimals) as i32;
    let round = |v: f64| (v * 10f64.powi(d)).round();
    round(a) < round(b)
}

/// Length units from the largest down: the first whose value is ≥ 1 is
/// used; below a nanometre, nanometres.
const LENGTH_UNITS: [(f64, &str); 4] = [(1.0, "m"), (1e-3, "mm"), (1e-6, "µm"), (1e-9, "nm")];

/// A length in metres in the unit that fits it, with two significant
/// digits or more: "12 µm", "1.5 mm", "350 mm", "2.5 m", "0.060 nm". Zero is "0 m";
/// NaN and infinities print as Rust prints them, without a unit.
pub fn length(m: f64) -> String {
    if !m.is_finite() {
        return format!("{m}");
    }
    if m == 0.0 {
        return "0 m".into();
    }
    let i = LENGTH_UNITS
        .iter()
        .position(|&(scale, _)| m.abs() >= scale)
        .unwrap_or(LENGTH_UNITS.len() - 1);
    let (scale, unit) = LENGTH_UNITS[i];
    let text = number(m / scale, 0);
    // 999.7 µm rounds to "1000": one unit up it is "1.0 mm".
    if i > 0 && text.parse::<f64>().is_ok_and(|v| v.abs() >= 1000.0) {
        let (scale, unit) = LENGTH_UNITS[i - 1];
        return format!("{} {unit}", number(m / scale, 0));
    }
    format!("{text} {unit}")
}

/// A length given in millimetres (the unit the metrics are kept in), as
/// [`length`] prints it.
pub fn length_mm(mm: f64) -> String {
    length(mm * 1e-3)
}

/// An optional length in millimetres; `None` is "–".
pub fn length_mm_or_dash(mm: Option<f64>) -> String {
    mm.map_or_else(|| "–".into(), length_mm)
}

/// An angle in degrees with at least two significant digits and at least
/// three decimals: "0.250°", "0.0012°".
pub fn degrees(deg: f64) -> String {
    format!("{}°", number(deg, 3))
}

/// A value the user gave, echoed in a message: Rust's shortest
/// round-trip form, in exponent form when that is shorter ("1e300", not
/// 301 digits).
pub fn given(v: f64) -> String {
    let plain = format!("{v}");
    let exponent = format!("{v:e}");
    if exponent.len() < plain.len() {
        exponent
    } else {
        plain
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lengths_pick_the_unit_that_fits_with_two_significant_digits() {
        assert_eq!(length(6e-11), "0.060 nm");
        assert_eq!(length(6.3e-8), "63 nm");
        assert_eq!(length(1.5e-3), "1.5 mm");
        assert_eq!(length(1.2e-5), "12 µm");
        assert_eq!(length(0.35), "350 mm");
        assert_eq!(length(2.5), "2.5 m");
        assert_eq!(length(123e-6), "123 µm");
        assert_eq!(length(-1.5e-3), "-1.5 mm");
    }

    #[test]
    fn a_length_rounding_up_to_the_next_unit_moves_to_it() {
        assert_eq!(length(0.9996e-3), "1.0 mm");
        assert_eq!(length(9.96e-3), "10 mm");
        assert_eq!(length(999.4e-6), "999 µm");
    }

    #[test]
    fn zero_and_non_finite_lengths_print_plainly() {
        assert_eq!(length(0.0), "0 m");
        assert_eq!(length(f64::NAN), "NaN");
        assert_eq!(length(f64::INFINITY), "inf");
        assert_eq!(length_mm_or_dash(None), "–");
    }

    #[test]
    fn millimetres_convert_before_formatting() {
        assert_eq!(length_mm(0.000063), "63 nm");
        assert_eq!(length_mm(0.027), "27 µm");
        assert_eq!(length_mm(1.625), "1.6 mm");
    }

    #[test]
    fn numbers_keep_their_decimals_and_two_significant_digits() {
        assert_eq!(number(0.2, 3), "0.200");
        assert_eq!(number(1.5e-5, 3), "0.000015");
        assert_eq!(number(0.0999, 0), "0.10");
        assert_eq!(number(36.04, 1), "36.0");
        assert_eq!(number(0.0, 3), "0.000");
        assert_eq!(number(f64::NAN, 3), "NaN");
        assert_eq!(degrees(0.0012), "0.0012°");
    }

    #[test]
    fn comparison_is_at_the_printed_precision() {
        assert!(shown_below(0.2, 0.5, 3));
        // 0.2001 and 0.2004 both print as 0.200.
        assert!(!shown_below(0.2001, 0.2004, 3));
        // Tiny values are compared at their own two significant digits.
        assert!(shown_below(1.5e-5, 2.7e-5, 3));
        assert!(shown_below(1.0, f64::NAN, 3));
        assert!(!shown_below(f64::NAN, 1.0, 3));
    }
}

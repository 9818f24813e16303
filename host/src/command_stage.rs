//! The host side of the firmware's command stage (`docs/design.md` §5.2):
//! the full tension limits the control step runs with (the co-contraction
//! sets come from [`crate::robot::groups`]). The stage itself is the
//! firmware's (`tendril_firmware::command`), so the numbers a user gets from
//! `evaluate` / `compare` are the ones the MCU would command.

use nalgebra::DMatrix;

use tendril_firmware::command::co_contract;
use tendril_shared::{LimitsError, TendonLimits, MAX_TENDONS};

use crate::robot::{cocontraction_sets, Robot};

/// The limits the control step enforces on `robot`: `[min_tension,
/// max_tension]` per tendon, one slew rate (N/s), its co-contraction sets.
pub fn limits_for(robot: &Robot, slew_n_per_s: f64) -> Result<TendonLimits, LimitsError> {
    let f32s = |v: Vec<f64>| v.into_iter().map(|x| x as f32).collect::<Vec<f32>>();
    let n = robot.n_tendons();
    TendonLimits::new(&f32s(robot.max_tensions()), &vec![slew_n_per_s as f32; n])?
        .with_min_tension(&f32s(robot.min_tensions()))?
        .with_cocontraction(cocontraction_sets(robot))
}

/// What the MCU would command for a net's `target` tensions in steady state
/// (no slew): the co-contraction shift, then the clip to `[min, max]`.
pub fn command_for(limits: &TendonLimits, target: &[f64]) -> Vec<f64> {
    let shifted = shifted(limits, target);
    shifted
        .iter()
        .zip(limits.min_tension().iter().zip(limits.max_tension()))
        .map(|(&v, (&lo, &hi))| tendril_firmware::control::clamp(v, lo, hi) as f64)
        .collect()
}

/// The stage's co-contraction shift alone (f32, as on the MCU): what
/// [`command_for`] clips.
fn shifted(limits: &TendonLimits, target: &[f64]) -> [f32; MAX_TENDONS] {
    let mut t = [0.0f32; MAX_TENDONS];
    for (slot, &v) in t.iter_mut().zip(target) {
        *slot = v as f32;
    }
    co_contract(&mut t, limits);
    t
}

/// How far [`command_for`]'s clip moved each tendon after the shift, N: a
/// tension the limits do not allow even with co-contraction.
pub fn clipped_by(limits: &TendonLimits, target: &[f64]) -> Vec<f64> {
    let shifted = shifted(limits, target);
    command_for(limits, target)
        .iter()
        .zip(&shifted)
        .map(|(&c, &s)| (c - f64::from(s)).abs())
        .collect()
}

/// [`command_for`] on every row of `tensions` (`n × T`, N); a NaN entry
/// counts as 0 N (the stage then lifts it to its floor).
pub fn command_rows(limits: &TendonLimits, tensions: &DMatrix<f64>) -> DMatrix<f64> {
    let mut out = tensions.clone();
    let mut row = vec![0.0; tensions.ncols()];
    for r in 0..tensions.nrows() {
        for (c, v) in row.iter_mut().enumerate() {
            let t = tensions[(r, c)];
            *v = if t.is_nan() { 0.0 } else { t };
        }
        for (c, v) in command_for(limits, &row).into_iter().enumerate() {
            out[(r, c)] = v;
        }
    }
    out
}

/// The plain per-tendon clip to `[min, max]` (what the stage replaces).
pub fn plain_clip(robot: &Robot, target: &[f64]) -> Vec<f64> {
    target
        .iter()
        .zip(&robot.tendons)
        .map(|(&v, t)| v.clamp(t.min_tension, t.max_tension))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::robot::repo_robot as robot;

    #[test]
    fn on_generated_seed_paper_rows_the_stage_recovers_the_tip_the_clip_loses() {
        // True tensions from the seed-paper sampler (all four in [5, 15] N);
        // a "prediction" that co-contracts the pair (1, 3) by +4 N — the tip
        // barely moves by itself, but whenever it takes tendon 3 over 15 N
        // the plain clip cuts the bend. The net's own answer, solved without
        // limits (the statics accept any tension), is the reference: through
        // the stage the tip is no further off than that answer (the stage
        // only removes co-contraction); through the clip it is millimetres off.
        use crate::dataset::Sampler;
        use crate::statics::{SolverSettings, Statics};
        let r = robot("seed-paper.toml");
        let statics = Statics::new(&r, SolverSettings::default());
        // The same robot with room above 15 N, to solve the net's own answer.
        let mut roomy = r.clone();
        for t in &mut roomy.tendons {
            t.max_tension = 30.0;
        }
        let unlimited = Statics::new(&roomy, SolverSettings::default());
        let limits = limits_for(&r, 100.0).unwrap();
        let rows = Sampler::Uniform.draw_between(40, &r.min_tensions(), &r.max_tensions(), 7);
        let (mut worst_stage, mut worst_clip, mut worst_own, mut cut) = (0.0f64, 0.0f64, 0.0f64, 0);
        for t in rows {
            let truth = statics.solve(&t, None).unwrap().position;
            let mut predicted = t.clone();
            predicted[1] += 4.0;
            predicted[3] += 4.0;
            if predicted[3] <= 15.0 {
                continue;
            }
            cut += 1;
            let staged = statics
                .solve(&command_for(&limits, &predicted), None)
                .unwrap();
            let clipped = statics.solve(&plain_clip(&r, &predicted), None).unwrap();
            let own = unlimited.solve(&predicted, None).unwrap();
            worst_own = worst_own.max((own.position - truth).norm());
            worst_stage = worst_stage.max((staged.position - truth).norm());
            worst_clip = worst_clip.max((clipped.position - truth).norm());
        }
        assert!(cut >= 5, "only {cut} rows left the range");
        let mm = |x: f64| x * 1e3;
        assert!(
            worst_stage <= worst_own + 1e-9,
            "stage {:.4} mm vs the net's own answer {:.4} mm",
            mm(worst_stage),
            mm(worst_own)
        );
        assert!(
            worst_clip > 1e-3 && worst_clip > 10.0 * worst_own,
            "clip {:.4} mm vs the net's own answer {:.4} mm",
            mm(worst_clip),
            mm(worst_own)
        );
    }

    #[test]
    fn the_stage_keeps_the_seed_paper_differential_the_clip_does_not() {
        let r = robot("seed-paper.toml");
        let limits = limits_for(&r, 100.0).unwrap();
        let net = [6.99, 8.08, 15.02, 17.87];
        let staged = command_for(&limits, &net);
        let clipped = plain_clip(&r, &net);
        let diff = |t: &[f64]| (t[2] - t[0], t[3] - t[1]);
        let (a, b) = diff(&staged);
        assert!(
            (a - 8.03).abs() < 1e-4 && (b - 9.79).abs() < 1e-4,
            "{staged:?}"
        );
        let (_, b_clip) = diff(&clipped);
        assert!((b_clip - 6.92).abs() < 1e-9, "{clipped:?}");
    }
}

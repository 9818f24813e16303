//! The residual a calibrated model cannot explain (`docs/design.md` §11.5):
//! the measured tip poses against the calibrated robot file's statics at the
//! measured tensions, fitted as a smooth function of the tensions, so that a
//! dataset generated from the file can carry it (`tendril generate
//! --residual-from`). A grey box: the model gives the shape of the map, the
//! rows the part of it no parameter of the file reaches (a softer rod than
//! any fitted E explains without a known load, the real tendons' routing).
//!
//! The residual r(τ) = (p_meas − p_model, log(q_meas q_model⁻¹)) — metres
//! and a rotation vector, in the base frame — is a ridge regression on the
//! monomials of the normalised tensions up to degree d. d and λ are picked
//! on a validation fifth of the rows; rows whose position residual is far
//! from the first fit's (a tracker's outliers) are left out and the fit
//! repeated. Tensions outside the measured ranges are clamped to them: a
//! polynomial is not extrapolated.

use nalgebra::{DMatrix, Quaternion, UnitQuaternion, Vector3};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rayon::prelude::*;

use crate::dataset::Dataset;
use crate::learn::linalg::ridge_solve;
use crate::statics::Statics;

/// Degrees of the tension polynomial tried.
const DEGREES: [usize; 3] = [1, 2, 3];
/// Ridge strengths tried, relative to the mean diagonal of the Gram matrix.
const LAMBDAS: [f64; 8] = [1e-8, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1];
/// Fraction of the rows the choice of degree and λ is judged on.
const VALID_FRACTION: f64 = 0.2;
/// A row whose position residual is off the first fit by more than this
/// many times the median row's is an outlier...
const OUTLIER_FACTOR: f64 = 5.0;
/// ...and never one within this of the fit, m (rows of a model are within
/// microns of it, and a tenth of a millimetre is no tracker's outlier).
const OUTLIER_FLOOR_M: f64 = 1e-4;
/// Fewest rows a residual is fitted from.
pub const MIN_ROWS: usize = 50;

/// A fitted residual: apply it to a pose of the model at the same tensions.
#[derive(Clone, Debug, PartialEq)]
pub struct Residual {
    degree: usize,
    /// Per-tension centre and half-width of the measured range, N.
    centre: Vec<f64>,
    half_width: Vec<f64>,
    /// Monomial exponents, one list per feature.
    exponents: Vec<Vec<u8>>,
    /// Weights, features × 6 (Δp in m, then the rotation vector in rad).
    weights: DMatrix<f64>,
}

/// What the fit found (in the dataset's sidecar as `residual`).
pub type ResidualReport = crate::dataset::ResidualRecord;

/// Why no residual could be fitted.
#[derive(Debug, thiserror::Error)]
pub enum ResidualError {
    /// The rows do not fit the robot or are too few.
    #[error("{0}")]
    Rows(String),
    /// The statics failed at a measured row's tensions.
    #[error("the statics at measured row {row} (line {}): {why}", row + 2)]
    Solve {
        /// 0-based row.
        row: usize,
        /// What the solver said.
        why: String,
    },
}

impl Residual {
    /// Move `pose` (the model's, base frame, `[px, py, pz, qw, qx, qy, qz]`)
    /// by the residual at `tensions`.
    pub fn apply(&self, tensions: &[f64], pose: &mut [f64; 7]) {
        let r = self.at(tensions);
        for k in 0..3 {
            pose[k] += r[k];
        }
        let q =
            UnitQuaternion::from_quaternion(Quaternion::new(pose[3], pose[4], pose[5], pose[6]));
        let q = UnitQuaternion::from_scaled_axis(Vector3::new(r[3], r[4], r[5])) * q;
        let s = if q.w < 0.0 { -1.0 } else { 1.0 };
        pose[3..].copy_from_slice(&[s * q.w, s * q.i, s * q.j, s * q.k]);
    }

    /// The residual at `tensions`: Δp (m), then the rotation vector (rad).
    fn at(&self, tensions: &[f64]) -> [f64; 6] {
        let phi = self.features(tensions);
        std::array::from_fn(|k| {
            phi.iter()
                .enumerate()
                .map(|(j, f)| f * self.weights[(j, k)])
                .sum()
        })
    }

    /// Move every row's pose of `data` (the model's rows, base frame) by
    /// the residual at its tensions.
    pub fn apply_all(&self, data: &mut Dataset) {
        for i in 0..data.len() {
            let tensions: Vec<f64> = data.tensions.row(i).iter().copied().collect();
            let mut pose: [f64; 7] = std::array::from_fn(|c| data.poses[(i, c)]);
            self.apply(&tensions, &mut pose);
            for (c, v) in pose.into_iter().enumerate() {
                data.poses[(i, c)] = v;
            }
        }
    }

    fn features(&self, tensions: &[f64]) -> Vec<f64> {
        let z: Vec<f64> = tensions
            .iter()
            .zip(self.centre.iter().zip(&self.half_width))
            .map(|(t, (c, h))| ((t - c) / h).clamp(-1.0, 1.0))
            .collect();
        self.exponents
            .iter()
            .map(|e| {
                e.iter()
                    .zip(&z)
                    .map(|(&k, z)| z.powi(i32::from(k)))
                    .product()
            })
            .collect()
    }
}

/// Move the rows of the dataset generated at `csv` (its `sidecar` in hand)
/// by `residual`, and write both again (each atomically), the sidecar
/// describing the moved rows and recording the fit.
pub fn add_to_dataset(
    csv: &std::path::Path,
    sidecar: &mut crate::dataset::Sidecar,
    residual: &Residual,
    record: ResidualReport,
) -> Result<(), crate::dataset::DatasetError> {
    let mut data = Dataset::read_csv(csv)?;
    residual.apply_all(&mut data);
    data.write_csv(csv)?;
    crate::dataset::generate::describe_again(sidecar, &data);
    sidecar.residual = Some(record);
    sidecar.write(&crate::dataset::Sidecar::path_for(csv))
}

/// Every exponent list of `n` variables with total degree ≤ `d`, each
/// monomial once.
fn exponents(n: usize, d: usize) -> Vec<Vec<u8>> {
    fn extend(prefix: &mut Vec<u8>, n: usize, left: usize, out: &mut Vec<Vec<u8>>) {
        if prefix.len() == n {
            out.push(prefix.clone());
            return;
        }
        for k in 0..=left {
            prefix.push(k as u8);
            extend(prefix, n, left - k, out);
            prefix.pop();
        }
    }
    let mut out = Vec::new();
    extend(&mut Vec::with_capacity(n), n, d, &mut out);
    out
}

/// The residual of the rows' tips (tracker frame, mapped into the robot's
/// base frame through its `[base]`) against `statics` at their tensions.
pub fn fit(
    statics: &Statics,
    rows: &Dataset,
    file: &str,
    seed: u64,
) -> Result<(Residual, ResidualReport), ResidualError> {
    let n = statics.robot().n_tendons();
    if rows.n_tendons != n {
        return Err(ResidualError::Rows(format!(
            "{file} has {} tension columns; robot {} has {n} tendons",
            rows.n_tendons,
            statics.robot().name
        )));
    }
    if rows.len() < MIN_ROWS {
        return Err(ResidualError::Rows(format!(
            "{file} has {} rows; a residual needs at least {MIN_ROWS}",
            rows.len()
        )));
    }
    let to_base = statics.robot().base.to_base();
    let targets: Vec<[f64; 6]> = (0..rows.len())
        .into_par_iter()
        .map(|i| {
            let t: Vec<f64> = rows.tensions.row(i).iter().copied().collect();
            let model = statics
                .solve(&t, None)
                .map_err(|e| ResidualError::Solve {
                    row: i,
                    why: e.to_string(),
                })?
                .pose();
            let measured = to_base.pose(std::array::from_fn(|c| rows.poses[(i, c)]));
            Ok(residual_of(&measured, &model))
        })
        .collect::<Result<_, _>>()?;
    let (centre, half_width): (Vec<f64>, Vec<f64>) = (0..n)
        .map(|j| {
            let c = rows.tensions.column(j);
            let (lo, hi) = (c.min(), c.max());
            ((lo + hi) / 2.0, ((hi - lo) / 2.0).max(1e-9))
        })
        .unzip();
    let mut order: Vec<usize> = (0..rows.len()).collect();
    order.shuffle(&mut rand::rngs::StdRng::seed_from_u64(seed));
    let n_valid = ((rows.len() as f64 * VALID_FRACTION).round() as usize).max(1);
    let (valid, fit_rows) = order.split_at(n_valid);
    let mut kept: Vec<usize> = fit_rows.to_vec();
    let no_fit = || {
        ResidualError::Rows(format!(
            "{file}: no ridge solve of the residual succeeded (a tension column that never \
             changes?)"
        ))
    };
    let mut best = choose(&centre, &half_width, rows, &targets, &kept, valid).ok_or_else(no_fit)?;
    // Leave out the rows the first fit calls outliers, then fit again.
    let errors: Vec<f64> = kept
        .iter()
        .map(|&i| position_miss(&best.0, rows, &targets, i))
        .collect();
    let mut sorted = errors.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    let before = kept.len();
    kept = kept
        .iter()
        .zip(&errors)
        .filter(|(_, &e)| e <= (OUTLIER_FACTOR * median).max(OUTLIER_FLOOR_M))
        .map(|(&i, _)| i)
        .collect();
    if kept.len() < before {
        best = choose(&centre, &half_width, rows, &targets, &kept, valid).ok_or_else(no_fit)?;
    }
    let (residual, lambda) = best;
    let rms = |f: &dyn Fn(usize) -> f64| {
        (valid.iter().map(|&i| f(i).powi(2)).sum::<f64>() / valid.len() as f64).sqrt()
    };
    let none = |i: usize| Vector3::new(targets[i][0], targets[i][1], targets[i][2]).norm();
    let none_angle = |i: usize| Vector3::new(targets[i][3], targets[i][4], targets[i][5]).norm();
    let report = ResidualReport {
        file: file.to_string(),
        rows: rows.len(),
        outliers: before - kept.len(),
        degree: residual.degree,
        lambda,
        valid_position_rms_mm: (
            1e3 * rms(&none),
            1e3 * rms(&|i| position_miss(&residual, rows, &targets, i)),
        ),
        valid_angle_rms_deg: (
            rms(&none_angle).to_degrees(),
            rms(&|i| miss(&residual, rows, &targets, i, 3..6)).to_degrees(),
        ),
    };
    Ok((residual, report))
}

/// (p_meas − p_model, log(q_meas q_model⁻¹)).
fn residual_of(measured: &[f64; 7], model: &[f64; 7]) -> [f64; 6] {
    let q = |p: &[f64; 7]| UnitQuaternion::from_quaternion(Quaternion::new(p[3], p[4], p[5], p[6]));
    let w = (q(measured) * q(model).inverse()).scaled_axis();
    [
        measured[0] - model[0],
        measured[1] - model[1],
        measured[2] - model[2],
        w.x,
        w.y,
        w.z,
    ]
}

fn predicted(r: &Residual, rows: &Dataset, i: usize) -> [f64; 6] {
    let t: Vec<f64> = rows.tensions.row(i).iter().copied().collect();
    r.at(&t)
}

/// How far the residual at row `i` misses its target: the position
/// (`0..3`, m) or the rotation vector (`3..6`, rad).
fn miss(
    r: &Residual,
    rows: &Dataset,
    targets: &[[f64; 6]],
    i: usize,
    part: std::ops::Range<usize>,
) -> f64 {
    let p = predicted(r, rows, i);
    part.map(|k| (targets[i][k] - p[k]).powi(2))
        .sum::<f64>()
        .sqrt()
}

fn position_miss(r: &Residual, rows: &Dataset, targets: &[[f64; 6]], i: usize) -> f64 {
    miss(r, rows, targets, i, 0..3)
}

/// The degree and λ with the lowest validation position RMS, fitted on
/// `fit` rows.
fn choose(
    centre: &[f64],
    half_width: &[f64],
    rows: &Dataset,
    targets: &[[f64; 6]],
    fit: &[usize],
    valid: &[usize],
) -> Option<(Residual, f64)> {
    let n = centre.len();
    let mut best: Option<(f64, Residual, f64)> = None;
    for degree in DEGREES {
        let mut r = Residual {
            degree,
            centre: centre.to_vec(),
            half_width: half_width.to_vec(),
            exponents: exponents(n, degree),
            weights: DMatrix::zeros(0, 6),
        };
        let m = r.exponents.len();
        if m >= fit.len() {
            continue;
        }
        let mut f = DMatrix::zeros(fit.len(), m);
        for (a, &i) in fit.iter().enumerate() {
            let t: Vec<f64> = rows.tensions.row(i).iter().copied().collect();
            for (b, v) in r.features(&t).into_iter().enumerate() {
                f[(a, b)] = v;
            }
        }
        let y = DMatrix::from_fn(fit.len(), 6, |a, k| targets[fit[a]][k]);
        let (gram, cross) = (f.tr_mul(&f), f.tr_mul(&y));
        for lam in LAMBDAS {
            // A λ too small for the Gram matrix's conditioning is skipped.
            let Ok(w) = ridge_solve(&gram, &cross, lam) else {
                continue;
            };
            r.weights = w;
            let e: f64 = valid
                .iter()
                .map(|&i| position_miss(&r, rows, targets, i).powi(2))
                .sum();
            if best.as_ref().is_none_or(|(b, _, _)| e < *b) {
                best = Some((e, r.clone(), lam));
            }
        }
    }
    best.map(|(_, r, lam)| (r, lam))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::repo_robot;
    use crate::statics::SolverSettings;

    #[test]
    fn exponents_count_the_monomials_once() {
        // C(n + d, d) monomials of n variables up to degree d.
        for (n, d, count) in [(1, 3, 4), (4, 1, 5), (4, 2, 15), (6, 3, 84)] {
            let e = exponents(n, d);
            assert_eq!(e.len(), count, "n {n}, d {d}");
            let mut u = e.clone();
            u.dedup();
            assert_eq!(u.len(), e.len());
        }
    }

    /// Rows of a robot 8 % softer than its file: the file's model misses
    /// them by millimetres; the residual fitted on 300 of them takes a
    /// held-out row's miss (a tension the fit never saw) to a small part of
    /// it, and a residual of the model's own rows is (nearly) zero.
    #[test]
    fn a_softer_robots_rows_are_explained_by_the_files_model_plus_its_residual() {
        let file = repo_robot("seed-4t.toml");
        let mut real = file.clone();
        real.youngs_modulus *= 0.92;
        let (model, truth) = (
            Statics::new(&file, SolverSettings::default()),
            Statics::new(&real, SolverSettings::default()),
        );
        let draw = |seed: u64, n: usize| {
            let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
            let t = DMatrix::from_fn(n, 4, |_, _| rand::Rng::random_range(&mut rng, 0.0..4.0));
            let poses = DMatrix::from_fn(n, 7, |_, _| 0.0);
            let mut d = Dataset {
                n_tendons: 4,
                tensions: t,
                poses,
            };
            for i in 0..n {
                let tau: Vec<f64> = d.tensions.row(i).iter().copied().collect();
                let p = truth.solve(&tau, None).unwrap().pose();
                for (c, v) in p.into_iter().enumerate() {
                    d.poses[(i, c)] = v;
                }
            }
            d
        };
        let (rows, held) = (draw(1, 300), draw(2, 20));
        let (r, report) = fit(&model, &rows, "rows.csv", 7).unwrap();
        let mut before = 0.0f64;
        let mut after = 0.0f64;
        for i in 0..held.len() {
            let tau: Vec<f64> = held.tensions.row(i).iter().copied().collect();
            let mut p = model.solve(&tau, None).unwrap().pose();
            let miss = |p: &[f64; 7]| {
                (0..3)
                    .map(|k| (p[k] - held.poses[(i, k)]).powi(2))
                    .sum::<f64>()
                    .sqrt()
            };
            before = before.max(miss(&p));
            r.apply(&tau, &mut p);
            after = after.max(miss(&p));
        }
        eprintln!(
            "held-out worst miss {:.3} → {:.3} mm; {report:?}",
            before * 1e3,
            after * 1e3
        );
        assert!(
            before > 1e-3,
            "the softer robot is only {before} m off its file"
        );
        assert!(
            after < 0.1 * before,
            "{after} m after against {before} m before"
        );
        assert!(report.valid_position_rms_mm.1 < 0.1 * report.valid_position_rms_mm.0);
        assert_eq!(report.outliers, 0);
    }
}

//! Fine-tuning a trained net on other rows (`docs/design.md` §4, "Fine-tune
//! on measured rows"): the net a robot file gave, moved to the real robot's
//! own measurements. No unit is grown and the normalisation stays the
//! starting net's, so the result is the same shape of net: first the output
//! layer takes the residual the start leaves, fitted on the start's own
//! features by ridge regression towards its weights; then the polish
//! (L-BFGS over every weight, the tip loss, the best validation step kept)
//! runs from there instead of from a freshly grown net. Its validation rows
//! are measured too, so what is kept is where the measured rows stop
//! agreeing, not where synthetic ones would.

use std::sync::atomic::AtomicBool;
use std::time::Instant;

use nalgebra::DMatrix;
use tendril_shared::{Activation, McuNet, POSE_DIM};

use super::export::Ranges;
use super::net::{GrowingNet, OutputKind};
use super::outputs::Data;
use super::train::{polish_net, CascorOptions, Metrics, OutputSolver, TrainReport};
use super::unit_log::UnitLog;
use crate::learn::linalg::ridge_solve;
use crate::learn::LearnError;

/// A decoded `.tnet` as the trainer's net (normalised in, normalised out;
/// inputs in [0, 1]) and its ranges. Refuses activations the trainer does
/// not make.
pub fn from_tnet(net: &McuNet) -> Result<(GrowingNet, Ranges), LearnError> {
    if net.hidden_activation() != Activation::SymmetricSigmoid {
        return Err(LearnError::BadData(format!(
            "the starting net's hidden units are {:?}, not the symmetric sigmoid cascade \
             correlation trains",
            net.hidden_activation()
        )));
    }
    let output_kind = match net.output_activation() {
        Activation::Linear => OutputKind::Linear,
        Activation::Sigmoid => OutputKind::Sigmoid,
        other => {
            return Err(LearnError::BadData(format!(
                "the starting net's outputs are {other:?}, not linear or sigmoid"
            )))
        }
    };
    let shape = net.shape();
    let f64s = |v: &[f32]| v.iter().map(|&x| f64::from(x)).collect::<Vec<f64>>();
    // The decoder's rows have room for every pose input (`POSE_DIM`); a
    // net of fewer inputs leaves the rest empty.
    let row = |r: &[f32]| -> Option<Vec<f64>> {
        let (bias, rest) = r.split_first()?;
        let inputs = rest.get(..shape.inputs)?;
        let hidden = rest.get(POSE_DIM..)?;
        Some(f64s(&[&[*bias], inputs, hidden].concat()))
    };
    let hidden = (0..shape.hidden)
        .map(|k| net.hidden_row(k).and_then(row))
        .collect::<Option<Vec<_>>>();
    let outputs = (0..shape.outputs)
        .map(|o| net.output_row(o).and_then(row))
        .collect::<Option<Vec<_>>>();
    let (Some(hidden), Some(outputs)) = (hidden, outputs) else {
        return Err(LearnError::BadData(
            "the starting net's weights are shorter than its shape".into(),
        ));
    };
    Ok((
        GrowingNet {
            n_inputs: shape.inputs,
            n_outputs: shape.outputs,
            hidden,
            outputs,
            output_kind,
        },
        Ranges {
            input_lo: f64s(net.input_lo()),
            input_hi: f64s(net.input_hi()),
            output_lo: f64s(net.output_lo()),
            output_hi: f64s(net.output_hi()),
        },
    ))
}

/// Polish `start` (inputs in [0, 1], as [`from_tnet`] gives it) on the rows
/// `x → y`, keeping the step with the lowest error on `vx → vy`; the rows are
/// normalised with the starting net's ranges. `stop` ends it early with the
/// best step so far. The report has one row in its history, the starting
/// net, and the polish's record.
#[allow(clippy::too_many_arguments)]
pub fn fine_tune_with_stop(
    start: &GrowingNet,
    x: &DMatrix<f64>,
    y: &DMatrix<f64>,
    vx: &DMatrix<f64>,
    vy: &DMatrix<f64>,
    opts: &CascorOptions,
    stop: &AtomicBool,
    metrics: Metrics<'_>,
) -> Result<(GrowingNet, TrainReport), LearnError> {
    if x.ncols() != start.n_inputs || y.ncols() != start.n_outputs {
        return Err(LearnError::BadData(format!(
            "the starting net is {}→{} but the rows are {}→{}",
            start.n_inputs,
            start.n_outputs,
            x.ncols(),
            y.ncols()
        )));
    }
    if x.nrows() < 2 || vx.nrows() == 0 {
        return Err(LearnError::BadData(format!(
            "fine-tuning needs training and validation rows: {} and {}",
            x.nrows(),
            vx.nrows()
        )));
    }
    opts.polish.check()?;
    let d = Data {
        y,
        vy,
        opts,
        seed: 0,
        start: Instant::now(),
        stop,
    };
    let rmse = |net: &GrowingNet, x: &DMatrix<f64>, y: &DMatrix<f64>| {
        ((net.predict(x) - y).norm_squared() / y.len().max(1) as f64).sqrt()
    };
    let before = UnitLog {
        hidden: start.n_hidden(),
        train_rmse: rmse(start, x, y),
        valid_rmse: rmse(start, vx, vy),
        score: f64::NAN,
        reduction: f64::NAN,
        objective: None,
        candidate_epochs: 0,
        output_epochs: 0,
        seconds: 0.0,
    };
    let mut net = start.clone();
    let lambda = residual_outputs(&mut net, x, y, vx, vy);
    let after_residual = UnitLog {
        train_rmse: rmse(&net, x, y),
        valid_rmse: rmse(&net, vx, vy),
        seconds: d.start.elapsed().as_secs_f64(),
        ..before.clone()
    };
    log::info!(
        "fine-tune: the output layer's residual fit (ridge λ {}) took the validation RMSE ×100 \
         from {:.4} to {:.4}",
        lambda.map_or("none: no λ helped".to_string(), |l| format!("{l:.0e}")),
        100.0 * before.valid_rmse,
        100.0 * after_residual.valid_rmse
    );
    // The polish works on centred inputs c = 2x − 1: the net that takes c
    // is the one that took x = c/2 + 1/2.
    let n = net.n_inputs;
    net.fold_input_affine(&vec![0.5; n], &vec![0.5; n]);
    let polish = (opts.polish.max_iterations > 0).then(|| polish_net(&mut net, x, vx, &d, metrics));
    net.fold_input_affine(&vec![2.0; n], &vec![-1.0; n]);
    let report = TrainReport {
        output_kind: net.output_kind,
        // No output phase ran: the solver is the one of the starting net,
        // which its file does not record.
        output_solver: OutputSolver::Ridge,
        pilot: Vec::new(),
        best_hidden: net.n_hidden(),
        best_valid_rmse: rmse(&net, vx, vy),
        history: vec![before, after_residual],
        objective_wins: (0, 0),
        polish,
        seconds: d.start.elapsed().as_secs_f64(),
    };
    Ok((net, report))
}

/// The ridge strengths tried for the residual, relative to the mean
/// diagonal of the features' Gram matrix.
const RESIDUAL_LAMBDAS: [f64; 10] = [1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 1.0, 10.0, 100.0, 1e3];

/// The residual the start net leaves on `x → y`, fitted on its own
/// features (bias, inputs, every hidden unit's activation) by ridge
/// regression and added to its output weights: W = W₀ + Δ, Δ =
/// argmin ‖F Δ − (Y − F W₀)‖² + λ‖Δ‖², so the shrinkage is towards the
/// start net, not towards zero. λ is the one of [`RESIDUAL_LAMBDAS`] with
/// the lowest error on `vx → vy`, and none (Δ = 0) when no λ beats the
/// start there. Linear outputs only (a sigmoid output is left alone).
/// Returns the λ taken.
fn residual_outputs(
    net: &mut GrowingNet,
    x: &DMatrix<f64>,
    y: &DMatrix<f64>,
    vx: &DMatrix<f64>,
    vy: &DMatrix<f64>,
) -> Option<f64> {
    if net.output_kind != OutputKind::Linear {
        return None;
    }
    let features = |x: &DMatrix<f64>| {
        let m = 1 + net.n_inputs + net.n_hidden();
        let mut f = DMatrix::zeros(x.nrows(), m);
        let (mut scratch, mut out) = (Vec::with_capacity(m), vec![0.0; net.n_outputs]);
        for r in 0..x.nrows() {
            let xr: Vec<f64> = x.row(r).iter().copied().collect();
            net.forward_into(&xr, &mut scratch, &mut out);
            for (c, v) in scratch.iter().enumerate() {
                f[(r, c)] = *v;
            }
        }
        f
    };
    let (f, fv) = (features(x), features(vx));
    let m = f.ncols();
    let w0 = DMatrix::from_fn(m, net.n_outputs, |r, o| net.outputs[o][r]);
    let (resid, resid_v) = (y - &f * &w0, vy - &fv * &w0);
    let (gram, cross) = (f.tr_mul(&f), f.tr_mul(&resid));
    let err = |d: &DMatrix<f64>| (&resid_v - &fv * d).norm_squared();
    let mut best: (f64, Option<(f64, DMatrix<f64>)>) = (resid_v.norm_squared(), None);
    for lam in RESIDUAL_LAMBDAS {
        // A λ too small for the features' conditioning is skipped.
        let Ok(delta) = ridge_solve(&gram, &cross, lam) else {
            continue;
        };
        let e = err(&delta);
        if e < best.0 {
            best = (e, Some((lam, delta)));
        }
    }
    let (lam, delta) = best.1?;
    for (o, w) in net.outputs.iter_mut().enumerate() {
        for (r, v) in w.iter_mut().enumerate() {
            *v += delta[(r, o)];
        }
    }
    Some(lam)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::cascor::export::to_bytes;

    fn net() -> GrowingNet {
        GrowingNet {
            n_inputs: 2,
            n_outputs: 1,
            hidden: vec![vec![0.1, 0.5, -0.3], vec![-0.2, 0.4, 0.9, 1.5]],
            outputs: vec![vec![0.3, -0.7, 0.2, 1.1, -0.6]],
            output_kind: OutputKind::Linear,
        }
    }

    fn ranges() -> Ranges {
        Ranges {
            input_lo: vec![-1.0, 0.0],
            input_hi: vec![1.0, 2.0],
            output_lo: vec![0.0],
            output_hi: vec![5.0],
        }
    }

    #[test]
    fn a_written_net_reads_back_as_the_same_net_to_f32() {
        let bytes = to_bytes(&net(), &ranges()).unwrap();
        let mut decoded = Box::<McuNet>::default();
        decoded.decode_into(&bytes).unwrap();
        let (back, r) = from_tnet(&decoded).unwrap();
        assert_eq!(r, ranges());
        let x = DMatrix::from_row_slice(3, 2, &[0.2, 0.9, 0.6, 0.1, 1.0, 0.0]);
        let d = (net().predict(&x) - back.predict(&x)).abs().max();
        assert!(d < 1e-6, "{d}");
        assert_eq!(back.n_hidden(), 2);
    }

    /// Rows of a function the starting net misses by a smooth offset: the
    /// fine-tuned net is closer on held-out rows than the start, and a
    /// net already at the rows' function is left where it is (the kept
    /// step is the starting one when no step is better on validation).
    #[test]
    fn fine_tuning_moves_a_net_towards_its_rows_and_keeps_the_best_validation_step() {
        let start = net();
        let grid = |n: usize, off: f64| {
            DMatrix::from_fn(n, 2, |r, c| {
                ((r as f64 * (0.37 + 0.21 * c as f64) + off) * 1.618).fract()
            })
        };
        let (x, vx, tx) = (grid(200, 0.0), grid(60, 0.11), grid(60, 0.53));
        // The truth: the start plus 0.05 + 0.1·x₀.
        let truth = |x: &DMatrix<f64>| {
            let p = start.predict(x);
            DMatrix::from_fn(x.nrows(), 1, |r, _| p[(r, 0)] + 0.05 + 0.1 * x[(r, 0)])
        };
        let (y, vy, ty) = (truth(&x), truth(&vx), truth(&tx));
        let mut opts = CascorOptions {
            progress: false,
            ..CascorOptions::default()
        };
        opts.polish.max_iterations = 300;
        let stop = AtomicBool::new(false);
        let (tuned, report) =
            fine_tune_with_stop(&start, &x, &y, &vx, &vy, &opts, &stop, Metrics::default())
                .unwrap();
        let err = |n: &GrowingNet| ((n.predict(&tx) - &ty).norm_squared() / 60.0).sqrt();
        let (e0, e1) = (err(&start), err(&tuned));
        assert!(e1 < 0.2 * e0, "held-out RMSE {e0} → {e1}");
        assert_eq!(report.history.len(), 2);
        assert!(report.polish.as_ref().unwrap().iterations > 0);
        assert_eq!(tuned.n_hidden(), start.n_hidden());

        // Rows the start already fits: nothing to learn, the start kept
        // to rounding.
        let (y0, vy0) = (start.predict(&x), start.predict(&vx));
        let (same, _) =
            fine_tune_with_stop(&start, &x, &y0, &vx, &vy0, &opts, &stop, Metrics::default())
                .unwrap();
        assert!((same.predict(&tx) - start.predict(&tx)).abs().max() < 1e-9);
    }

    #[test]
    fn a_net_of_another_shape_or_too_few_rows_is_refused() {
        let x = DMatrix::zeros(10, 3);
        let y = DMatrix::zeros(10, 1);
        let opts = CascorOptions::default();
        let stop = AtomicBool::new(false);
        let e = fine_tune_with_stop(&net(), &x, &y, &x, &y, &opts, &stop, Metrics::default())
            .unwrap_err();
        assert!(e.to_string().contains("2→1 but the rows are 3→1"), "{e}");
        let x = DMatrix::zeros(1, 2);
        let e = fine_tune_with_stop(&net(), &x, &y, &x, &y, &opts, &stop, Metrics::default())
            .unwrap_err();
        assert!(
            e.to_string().contains("training and validation rows"),
            "{e}"
        );
    }
}

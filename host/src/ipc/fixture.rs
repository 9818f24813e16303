//! A quickly fitted IK net for exercising the loop when no trained model is
//! at hand (HIL tests, benchmarks): random symmetric-sigmoid hidden units
//! (an extreme-learning-machine layer, stored as a cascade net whose hidden
//! units ignore each other) with ridge-fitted linear outputs, trained on
//! statics samples from the same two-adjacent-tendon family the planner
//! plans with. Under a second of work; millimetre-class accuracy, which is
//! what the correction loop is there to remove. The real model comes from
//! `tendril train`.

use nalgebra::{DMatrix, Vector2};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tendril_shared::{encode_to_vec, Activation, Shape, TnetView};

use super::IpcError;
use crate::kinematics::bend_tensions;
use crate::statics::Statics;

/// Jittered copies of each training pose (see [`quick_net`]).
const JITTER_COPIES: usize = 3;

/// Fit a `.tnet` with `hidden` random units on `samples` poses whose bends
/// cover a disc of `max_bend` newtons. Deterministic for a given seed.
pub fn quick_net(
    statics: &Statics,
    samples: usize,
    hidden: usize,
    max_bend: f64,
    seed: u64,
) -> Result<Vec<u8>, IpcError> {
    let n = statics.robot().n_tendons();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    // Samples on a spiral-ordered grid of bends so each solve warm-starts from a neighbour.
    let mut xs: Vec<[f64; 7]> = Vec::with_capacity(samples * (1 + JITTER_COPIES));
    let mut ys: Vec<Vec<f64>> = Vec::with_capacity(samples * (1 + JITTER_COPIES));
    let mut warm = None;
    for i in 0..samples {
        let r = max_bend * ((i as f64 + 0.5) / samples as f64).sqrt();
        let a = i as f64 * 2.399_963_229_728_653; // golden angle: even coverage of the disc
        let bend = Vector2::new(r * a.cos(), r * a.sin());
        let tau = bend_tensions(statics, &bend);
        let sol = statics
            .solve(&tau, warm.as_ref())
            .or_else(|_| statics.solve(&tau, None))
            .map_err(|e| IpcError::Other(format!("fixture statics: {e}")))?;
        warm = Some(sol.warm.clone());
        let pose = sol.pose();
        // The pose has 7 numbers but the robot only 2 degrees of freedom, so
        // the data lie on a surface and a plain fit is free to do anything
        // off it — where the correction loop's shifted setpoints land (it
        // moves the position and keeps the orientation). Jittered copies,
        // with the orientation far noisier than the position, make the net
        // vary smoothly off the surface and key on the position.
        xs.push(pose);
        ys.push(tau.clone());
        for _ in 0..JITTER_COPIES {
            let mut p = pose;
            for (k, v) in p.iter_mut().enumerate() {
                let sd = if k < 3 { 2e-4 } else { 1e-2 };
                *v += sd * (rng.random::<f64>() * 2.0 - 1.0) * 3f64.sqrt();
            }
            xs.push(p);
            ys.push(tau.clone());
        }
    }
    let samples = xs.len();
    let lo: Vec<f64> = (0..7)
        .map(|k| xs.iter().map(|x| x[k]).fold(f64::INFINITY, f64::min))
        .collect();
    let hi: Vec<f64> = (0..7)
        .map(|k| {
            let h = xs.iter().map(|x| x[k]).fold(f64::NEG_INFINITY, f64::max);
            if h - lo[k] < 1e-9 {
                lo[k] + 1.0
            } else {
                h
            }
        })
        .collect();
    let out_hi: Vec<f64> = statics.robot().max_tensions();
    let shape = Shape {
        inputs: 7,
        hidden,
        outputs: n,
    };
    // Hidden rows: bias + 7 inputs + (k earlier units, zero).
    let mut hidden_w = vec![0.0f32; shape.hidden_weight_count()];
    let mut w_in = DMatrix::<f64>::zeros(hidden, 8);
    for k in 0..hidden {
        for j in 0..8 {
            w_in[(k, j)] = rng.random_range(-4.0..4.0);
        }
        let off = shape.hidden_row_offset(k);
        for j in 0..8 {
            hidden_w[off + j] = w_in[(k, j)] as f32;
        }
    }
    // Features: [1, x̂, h(x̂)] as the f32 inference will see them.
    let cols = 1 + 7 + hidden;
    let mut f = DMatrix::<f64>::zeros(samples, cols);
    for (i, x) in xs.iter().enumerate() {
        let xn: Vec<f64> = (0..7)
            .map(|k| ((x[k] - lo[k]) / (hi[k] - lo[k])) as f32 as f64)
            .collect();
        f[(i, 0)] = 1.0;
        for k in 0..7 {
            f[(i, 1 + k)] = xn[k];
        }
        for k in 0..hidden {
            let s = w_in[(k, 0)] + (0..7).map(|j| w_in[(k, 1 + j)] * xn[j]).sum::<f64>();
            f[(i, 8 + k)] = Activation::SymmetricSigmoid.apply(s as f32) as f64;
        }
    }
    let y = DMatrix::from_fn(samples, n, |i, o| ys[i][o] / out_hi[o]);
    let mut gram = f.transpose() * &f;
    for d in 0..cols {
        gram[(d, d)] += 1e-6 * samples as f64;
    }
    let rhs = f.transpose() * y;
    let w = gram
        .cholesky()
        .ok_or_else(|| IpcError::Other("fixture: singular ridge system".into()))?
        .solve(&rhs);
    let mut output_w = vec![0.0f32; shape.output_weight_count()];
    for o in 0..n {
        for c in 0..cols {
            output_w[o * cols + c] = w[(c, o)] as f32;
        }
    }
    let f32s = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<f32>>();
    let (ilo, ihi, olo, ohi) = (f32s(&lo), f32s(&hi), vec![0.0f32; n], f32s(&out_hi));
    let view = TnetView {
        shape,
        hidden_activation: Activation::SymmetricSigmoid,
        output_activation: Activation::Linear,
        input_lo: &ilo,
        input_hi: &ihi,
        output_lo: &olo,
        output_hi: &ohi,
        hidden_weights: &hidden_w,
        output_weights: &output_w,
    };
    encode_to_vec(&view).map_err(|e| IpcError::Other(format!("fixture: encoding the net: {e:?}")))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::Robot;
    use crate::statics::SolverSettings;
    use std::path::Path;

    #[test]
    fn quick_net_inverts_held_out_statics_to_a_few_millimetres() {
        let robot =
            Robot::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../robots/seed-4t.toml"))
                .unwrap();
        let s = Statics::new(&robot, SolverSettings::default());
        let blob = quick_net(&s, 1500, 48, 6.0, 3).unwrap();
        let net = tendril_shared::IkNet::decode(&blob).unwrap();
        // Held-out bends (not on the training spiral): predicted tensions,
        // run forward through the statics, must land near the pose's tip.
        let mut worst: f64 = 0.0;
        for (bx, by) in [(1.3, 0.4), (-2.2, 1.7), (0.3, -3.1), (-1.0, -1.0)] {
            let tau = bend_tensions(&s, &Vector2::new(bx, by));
            let pose = s.solve(&tau, None).unwrap().pose().map(|v| v as f32);
            let pred = tendril_firmware::infer(&net, &pose);
            let pred: Vec<f64> = pred[..4]
                .iter()
                .map(|&v| (v as f64).clamp(0.0, 10.0))
                .collect();
            let tip = s.solve(&pred, None).unwrap().position;
            let err = ((tip.x - pose[0] as f64).powi(2) + (tip.y - pose[1] as f64).powi(2)).sqrt();
            worst = worst.max(err);
        }
        assert!(worst < 3e-3, "worst task-space error {worst} m");
        // A 2 mm sideways shift of the pose alone (z and orientation kept, as
        // the correction loop does) must move the predicted tip by roughly
        // 2 mm in that direction, not anywhere.
        let tau = bend_tensions(&s, &Vector2::new(-1.0, 0.5));
        let pose = s.solve(&tau, None).unwrap().pose().map(|v| v as f32);
        let mut shifted = pose;
        shifted[0] -= 0.002;
        let pred = tendril_firmware::infer(&net, &shifted);
        let pred: Vec<f64> = pred[..4]
            .iter()
            .map(|&v| (v as f64).clamp(0.0, 10.0))
            .collect();
        let tip = s.solve(&pred, None).unwrap().position;
        let dx = tip.x - pose[0] as f64;
        assert!(
            (dx + 0.002).abs() < 1e-3 && (tip.y - pose[1] as f64).abs() < 1e-3,
            "moved by {dx}, {}",
            tip.y - pose[1] as f64
        );
    }
}

//! Nets, poses and the exact evaluation the host inference paths' tests
//! share (`fast`, `relaxed`).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tendril_shared::{Activation, McuNet, NetShape, TnetView, POSE_DIM};

/// A shipped net from `firmware/vectors`.
pub(crate) fn shipped(name: &str) -> Box<McuNet> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../firmware/vectors")
        .join(name);
    crate::net::read_tnet(&path).unwrap()
}

/// A random net of the given shape and activations, weights uniform in
/// ±`scale`, through the format's encoder and the decoder every consumer
/// uses.
pub(crate) fn random(
    shape: NetShape,
    hidden_activation: Activation,
    output_activation: Activation,
    scale: f32,
    seed: u64,
) -> Box<McuNet> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut w =
        |n: usize| -> Vec<f32> { (0..n).map(|_| rng.random_range(-scale..scale)).collect() };
    let hidden = w(shape.hidden_weight_count());
    let outputs = w(shape.output_weight_count());
    let lo = [-0.1, -0.1, 0.2, 0.8, -0.3, -0.3, -0.01];
    let hi = [0.1, 0.1, 0.4, 1.0, 0.3, 0.3, 0.01];
    let out_lo: Vec<f32> = (0..shape.outputs).map(|o| o as f32 * 0.5).collect();
    let out_hi: Vec<f32> = out_lo.iter().map(|l| l + 10.0).collect();
    let view = TnetView {
        shape,
        hidden_activation,
        output_activation,
        input_lo: &lo[..shape.inputs],
        input_hi: &hi[..shape.inputs],
        output_lo: &out_lo,
        output_hi: &out_hi,
        hidden_weights: &hidden,
        output_weights: &outputs,
    };
    let bytes = tendril_shared::encode_to_vec(&view).unwrap();
    crate::net::decode(&bytes).unwrap()
}

/// A random 7-64-4 net (the benchmark's size): symmetric-sigmoid hidden
/// units and logistic outputs, as cascade correlation exports them.
pub(crate) fn random_64() -> Box<McuNet> {
    let shape = NetShape {
        inputs: 7,
        hidden: 64,
        outputs: 4,
    };
    random(
        shape,
        Activation::SymmetricSigmoid,
        Activation::Sigmoid,
        1.0,
        5,
    )
}

/// Poses spread a little past the net's input box (extrapolation too).
pub(crate) fn poses(net: &McuNet, n: usize, seed: u64) -> Vec<[f32; POSE_DIM]> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (lo, hi) = (net.input_lo(), net.input_hi());
    (0..n)
        .map(|_| {
            std::array::from_fn(|i| match (lo.get(i), hi.get(i)) {
                (Some(&l), Some(&h)) => l + (h - l) * rng.random_range(-0.2f32..1.2),
                _ => rng.random_range(-1.0..1.0),
            })
        })
        .collect()
}

/// The net's own weights evaluated in `f64` with the exact sigmoids:
/// what both `f32` paths approximate.
pub(crate) fn exact(net: &McuNet, pose: &[f32; POSE_DIM]) -> Vec<f64> {
    let act = |a: Activation, s: f64| match a {
        Activation::Linear => s,
        Activation::Sigmoid => 1.0 / (1.0 + (-s).exp()),
        Activation::SymmetricSigmoid => 1.0 / (1.0 + (-s).exp()) - 0.5,
    };
    let sh = net.shape();
    let mut f = vec![1.0f64];
    for (i, &x) in pose.iter().enumerate() {
        f.push(match (net.input_lo().get(i), net.input_hi().get(i)) {
            (Some(&lo), Some(&hi)) if i < sh.inputs => {
                (f64::from(x) - f64::from(lo)) / f64::from(hi - lo)
            }
            _ => 0.0,
        });
    }
    let dot =
        |w: &[f32], f: &[f64]| -> f64 { w.iter().zip(f).map(|(&w, &x)| f64::from(w) * x).sum() };
    for k in 0..sh.hidden {
        let s = dot(net.hidden_row(k).unwrap(), &f);
        f.push(act(net.hidden_activation(), s));
    }
    (0..sh.outputs)
        .map(|o| {
            let (lo, hi) = (f64::from(net.output_lo()[o]), f64::from(net.output_hi()[o]));
            lo + act(net.output_activation(), dot(net.output_row(o).unwrap(), &f)) * (hi - lo)
        })
        .collect()
}

use tendril_shared::{Activation, NetShape, MAX_TENDONS};

use super::*;
use crate::net::test_nets::{exact, poses, random};

const ACTIVATIONS: [Activation; 3] = [
    Activation::Linear,
    Activation::Sigmoid,
    Activation::SymmetricSigmoid,
];

/// Every shape the kernels treat apart: no hidden unit, a partial and a
/// whole first register, several registers, the full 64; one, a register
/// and more than a register of outputs; a missing input. (The format's
/// weight capacity holds 63 units with nine outputs, not 64.)
fn shapes() -> impl Iterator<Item = NetShape> {
    [0, 1, 7, 8, 9, 33, 63, 64].into_iter().flat_map(|hidden| {
        [(7, 1), (7, 4), (5, 8), (7, MAX_TENDONS)]
            .into_iter()
            .map(move |(inputs, outputs)| NetShape {
                inputs,
                hidden,
                outputs,
            })
            .filter(|s| s.hidden < 64 || s.outputs <= 8)
    })
}

/// The rational against `f64`'s `tanh` over and past its range, evaluated
/// as the chain evaluates it: the bound the constants' documentation gives.
#[test]
fn tanh_within_its_documented_error() {
    let mut worst = 0.0f64;
    for i in -200_000..=200_000 {
        let t = i as f32 * 6e-5; // ±12, finer than the curvature
        let e = (f64::from(tanh(t)) - f64::from(t).tanh()).abs();
        worst = worst.max(e);
    }
    eprintln!("worst |tanh error| {worst:.2e}");
    assert!(worst <= 3.6e-7, "worst |tanh error| {worst:e}");
    assert_eq!(tanh(0.0), 0.0);
    assert!(tanh(f32::NAN).is_nan());
    assert!((tanh(f32::INFINITY) - 1.0).abs() <= 3.6e-7);
    // The split's second part is the next unit's weight times the first.
    let (tp, wtp, r) = tanh_parts(0.7, -1.5);
    assert_eq!(wtp, -1.5 * 0.7 * (tp / 0.7));
    assert!((tp * r - 0.7f32.tanh()).abs() <= 3.6e-7);
}

/// The AVX2 kernel is the reference kernel, bit for bit, on every shape
/// and activation: a wrong lane, column offset or order shows in the bits.
/// On a CPU without AVX2 and FMA the kernel cannot run; what is checked
/// there instead is that nothing can reach it (no relaxed net is built).
#[test]
fn the_avx2_kernel_is_the_reference_bit_for_bit() {
    if !cpu_has_fma() {
        let net = crate::net::test_nets::random_64();
        assert!(RelaxedNet::new(&net).is_none());
        assert!(!crate::net::HostNet::new(&net).has_relaxed_kernel());
        eprintln!(
            "NOT RUN: the AVX2 kernel (this CPU has no AVX2 and FMA); checked instead that \
             no relaxed net is built here"
        );
        return;
    }
    #[cfg(target_arch = "x86_64")]
    for (n, shape) in shapes().enumerate() {
        for (a, (&hidden_act, &output_act)) in ACTIVATIONS
            .iter()
            .flat_map(|h| ACTIVATIONS.iter().map(move |o| (h, o)))
            .enumerate()
        {
            let net = random(shape, hidden_act, output_act, 0.5, (n * 9 + a) as u64);
            let relaxed = RelaxedNet::new(&net).unwrap();
            for p in poses(&net, 20, n as u64) {
                let x = relaxed.normalised(&p);
                let want = reference::pre_outputs(&relaxed, &x);
                // SAFETY: the CPU has AVX2 and FMA (checked above).
                let got = unsafe { avx2::pre_outputs(&relaxed, &x) };
                for (o, (g, w)) in got.iter().zip(&want).enumerate() {
                    assert_eq!(
                        g.to_bits(),
                        w.to_bits(),
                        "{shape:?} {hidden_act:?}/{output_act:?}, output lane {o}: {g} vs {w}"
                    );
                }
            }
        }
    }
}

/// The folding and the transposition against the net's own weights
/// evaluated exactly, on every shape and activation: within 2e-6 of each
/// output's range (random weights amplify `f32` rounding little; the
/// trained nets' bound, relative to the firmware's, is `net::fast`'s).
#[test]
fn the_reference_kernel_is_the_net() {
    let mut worst = 0.0f64;
    for (n, shape) in shapes().enumerate() {
        for &hidden_act in &ACTIVATIONS {
            for &output_act in &ACTIVATIONS {
                let net = random(shape, hidden_act, output_act, 0.3, 100 + n as u64);
                let relaxed = RelaxedNet::folded(&net);
                let (lo, hi) = (net.output_lo(), net.output_hi());
                for p in poses(&net, 20, 7 + n as u64) {
                    let mut got = [f32::NAN; OUT_LANES];
                    relaxed.finish(
                        &reference::pre_outputs(&relaxed, &relaxed.normalised(&p)),
                        &mut got,
                    );
                    let e = exact(&net, &p);
                    for (o, e) in e.iter().enumerate() {
                        let d = (f64::from(got[o]) - e).abs() / f64::from(hi[o] - lo[o]);
                        assert!(
                            d <= 2e-6,
                            "{shape:?} {hidden_act:?}/{output_act:?}, output {o}: {} vs {e}",
                            got[o]
                        );
                        worst = worst.max(d);
                    }
                }
            }
        }
    }
    eprintln!("worst distance from the exact net: {worst:.2e} of the range");
}

/// A pose the net cannot answer gives NaN, not a number: NaN in an input
/// the net has reaches every output.
#[test]
fn a_nan_pose_gives_nan() {
    let shape = NetShape {
        inputs: 7,
        hidden: 12,
        outputs: 4,
    };
    let net = random(
        shape,
        Activation::SymmetricSigmoid,
        Activation::Sigmoid,
        0.5,
        3,
    );
    let relaxed = RelaxedNet::folded(&net);
    let mut pose = poses(&net, 1, 1)[0];
    pose[2] = f32::NAN;
    let mut out = [0.0f32; 4];
    relaxed.finish(
        &reference::pre_outputs(&relaxed, &relaxed.normalised(&pose)),
        &mut out,
    );
    assert!(out.iter().all(|v| v.is_nan()), "{out:?}");
}

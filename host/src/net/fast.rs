//! Host inference laid out for the CPU (issue 29, item 2): [`HostNet`], built
//! once from a decoded [`McuNet`], runs poses through the net several at a
//! time and allocates nothing per query.
//!
//! # Parity
//! The results are **bit-identical** to the firmware's
//! [`tendril_firmware::infer`] (`docs/design.md` §5), so every caller that
//! claims parity may use this path. Batching changes which queries share a
//! loop, never the operations one query sees:
//!
//! - each unit's dot product keeps the firmware's order: four partial sums,
//!   `s[i mod 4] += w_i a_i` in index order, reduced as `(s0 + s1) + (s2 +
//!   s3)`; the batch puts *queries* side by side in the SIMD lanes
//!   (`LANES` of them share one broadcast weight), so no query's sum is
//!   reassociated;
//! - Rust never contracts `a * b + c` into an FMA, so the product is rounded
//!   before the add, as in the firmware (and the M4's `vmla.f32`);
//! - the activations are `Activation::apply`, the firmware's own `f32` code;
//!   normalisation and de-normalisation are the same expressions (the range
//!   widths `hi − lo` are computed once here, the same rounded value);
//! - the firmware pads every row to a multiple of 8 products whose features
//!   are 0. This path skips them, which is exact: a partial sum starts at
//!   +0 and, in round-to-nearest, a sum is −0 only if both addends are −0,
//!   so no partial sum is ever −0, and `s + (±0) = s` for every other `s`
//!   (NaN and ±∞ included).
//!
//! The test below checks the bits against the firmware over thousands of
//! random poses on the shipped nets and on a random 64-unit net.

use tendril_shared::{Activation, McuNet, MAX_HIDDEN, MAX_TENDONS, POSE_DIM};

use super::ranges::Ranges;
use super::relaxed::RelaxedNet;

/// Queries pushed through each unit together. Eight `f32` lanes are two SSE
/// registers per partial sum (four sums: eight of the sixteen registers),
/// enough independent add chains to hide the add latency.
pub const LANES: usize = 8;

/// Queries per block on CPUs with AVX2 (detected at run time, the build
/// stays SSE2): sixteen lanes are two 256-bit registers per partial sum,
/// the same register use as [`LANES`] on SSE2 for twice the queries. Only
/// the instructions change, never an operation a query sees (no FMA: the
/// kernel is compiled with AVX2 alone), so the bits are the same.
pub const WIDE_LANES: usize = 16;

/// Most features a unit reads: the bias, the inputs, the hidden units.
const MAX_FEATURES: usize = 1 + POSE_DIM + MAX_HIDDEN;

/// A decoded net ready for fast host inference: its rows packed without the
/// firmware's padding, its ranges as `lo` and width. Built once per net.
#[derive(Clone, Debug)]
pub struct HostNet {
    inputs: usize,
    hidden: usize,
    outputs: usize,
    hidden_act: Activation,
    output_act: Activation,
    ranges: Ranges,
    /// Hidden row `k` (`1 + POSE_DIM + k` weights), then the output rows
    /// (`1 + POSE_DIM + hidden` each): the firmware's packed order.
    weights: Box<[f32]>,
    /// Whether this CPU runs the [`WIDE_LANES`] kernel.
    avx2: bool,
    /// The relaxed single-query path, where the CPU has FMA.
    relaxed: Option<RelaxedNet>,
}

impl HostNet {
    /// The net of `net`, laid out for the host.
    pub fn new(net: &McuNet) -> HostNet {
        let s = net.shape();
        let weights: Vec<f32> = (0..s.hidden)
            .filter_map(|k| net.hidden_row(k))
            .chain((0..s.outputs).filter_map(|o| net.output_row(o)))
            .flatten()
            .copied()
            .collect();
        HostNet {
            inputs: s.inputs,
            hidden: s.hidden,
            outputs: s.outputs,
            hidden_act: net.hidden_activation(),
            output_act: net.output_activation(),
            ranges: Ranges::of(net),
            weights: weights.into_boxed_slice(),
            avx2: cpu_has_avx2(),
            relaxed: RelaxedNet::new(net),
        }
    }

    /// Number of outputs (tensions per query).
    pub fn outputs(&self) -> usize {
        self.outputs
    }

    /// Tensions (N) for one pose into `out[..outputs()]` (shorter `out`:
    /// the first `out.len()`), bit-identical to the firmware's `infer`.
    pub fn infer_one(&self, pose: &[f32; POSE_DIM], out: &mut [f32]) {
        let y = self.block::<1>(std::slice::from_ref(pose));
        for (d, s) in out.iter_mut().zip(&y[..self.outputs]) {
            *d = s[0];
        }
    }

    /// Tensions (N) for one pose into `out[..outputs()]`, **not**
    /// bit-identical to the firmware: relaxed arithmetic (a rational `tanh`,
    /// fused multiply-adds, another summation order; `net::relaxed`), no
    /// farther from an exact evaluation of the weights than three times the
    /// firmware's own `f32` result (tested), in about half the time of
    /// [`HostNet::infer_one`]. For single answers
    /// that claim no parity; on a CPU without AVX2 and FMA it is
    /// [`HostNet::infer_one`].
    pub fn infer_one_relaxed(&self, pose: &[f32; POSE_DIM], out: &mut [f32]) {
        match &self.relaxed {
            Some(r) => r.infer_one(pose, out),
            None => self.infer_one(pose, out),
        }
    }

    /// Whether [`HostNet::infer_one_relaxed`] runs the relaxed kernel here
    /// (the CPU has AVX2 and FMA).
    pub fn has_relaxed_kernel(&self) -> bool {
        self.relaxed.is_some()
    }

    /// Tensions for every pose in `poses` into `out`, row-major
    /// (`out[r·outputs() + o]`), [`LANES`] (with AVX2 [`WIDE_LANES`]) poses
    /// at a time; bit-identical
    /// to the firmware's `infer` row by row. Rows of `out` past the poses
    /// are left alone.
    ///
    /// # Panics
    /// If `out` holds fewer than `poses.len() · outputs()` values.
    pub fn infer_rows(&self, poses: &[[f32; POSE_DIM]], out: &mut [f32]) {
        let no = self.outputs;
        assert!(
            out.len() >= poses.len() * no,
            "output buffer of {} for {} rows of {no}",
            out.len(),
            poses.len()
        );
        if no == 0 {
            return;
        }
        #[cfg(target_arch = "x86_64")]
        if self.avx2 && poses.len() > 1 {
            // SAFETY: `avx2` is `cpu_has_avx2()`, checked on this CPU.
            unsafe { self.rows_avx2(poses, out) };
            return;
        }
        self.rows::<LANES>(poses, out);
    }

    /// [`HostNet::rows`] in [`WIDE_LANES`], compiled for AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn rows_avx2(&self, poses: &[[f32; POSE_DIM]], out: &mut [f32]) {
        self.rows::<WIDE_LANES>(poses, out)
    }

    /// [`HostNet::infer_rows`] `L` poses at a time (`out` checked).
    #[inline(always)]
    fn rows<const L: usize>(&self, poses: &[[f32; POSE_DIM]], out: &mut [f32]) {
        let no = self.outputs;
        let mut rows = out.chunks_exact_mut(no);
        let mut blocks = poses.chunks_exact(L);
        for b in blocks.by_ref() {
            let y = self.block::<L>(b);
            for (q, row) in rows.by_ref().take(L).enumerate() {
                for (d, s) in row.iter_mut().zip(&y) {
                    *d = s[q];
                }
            }
        }
        // The last partial block. One pose alone (a single query through
        // this API) runs the one-lane kernel: the L-lane one would do L
        // queries' work for it. More: padded with copies of the first pose
        // (results dropped), the L-lane kernel.
        let rest = blocks.remainder();
        if let [pose] = rest {
            let y = self.block::<1>(std::slice::from_ref(pose));
            for (row, _) in rows.zip(rest) {
                for (d, s) in row.iter_mut().zip(&y) {
                    *d = s[0];
                }
            }
        } else if let Some(&first) = rest.first() {
            let mut b = [first; L];
            b[..rest.len()].copy_from_slice(rest);
            let y = self.block::<L>(&b);
            for (q, row) in rows.take(rest.len()).enumerate() {
                for (d, s) in row.iter_mut().zip(&y) {
                    *d = s[q];
                }
            }
        }
    }

    /// The net on `L` poses at once (`poses.len() == L`): features stored
    /// feature-major (`f[i][q]`, query `q` in lane `q`) so each weight is
    /// loaded once and multiplies `L` queries. Everything lives on the
    /// stack: 72 × `L` features.
    #[inline(always)]
    fn block<const L: usize>(&self, poses: &[[f32; POSE_DIM]]) -> [[f32; L]; MAX_TENDONS] {
        let mut f = [[0.0f32; L]; MAX_FEATURES];
        f[0] = [1.0; L];
        let ranges = self.ranges.in_lo.iter().zip(&self.ranges.in_width);
        for (i, (fi, (&lo, &width))) in f[1..].iter_mut().zip(ranges).enumerate() {
            if i >= self.inputs {
                break; // inputs the net does not have stay 0, as in the firmware
            }
            for (v, p) in fi.iter_mut().zip(poses) {
                *v = (p[i] - lo) / width;
            }
        }
        let nh = self.hidden.min(MAX_HIDDEN);
        // One loop per activation, as in the firmware: no dispatch per unit.
        let start = match self.hidden_act {
            Activation::Linear => self.hidden_layer(&mut f, nh, |s| s),
            Activation::Sigmoid => self.hidden_layer(&mut f, nh, |s| Activation::Sigmoid.apply(s)),
            Activation::SymmetricSigmoid => {
                self.hidden_layer(&mut f, nh, |s| Activation::SymmetricSigmoid.apply(s))
            }
        };
        let len = 1 + POSE_DIM + nh;
        let mut y = [[0.0f32; L]; MAX_TENDONS];
        let rows = self.weights.get(start..).unwrap_or(&[]).chunks_exact(len);
        for (o, (yo, w)) in y.iter_mut().zip(rows).take(self.outputs).enumerate() {
            let s = dot(w, &f[..len]);
            let (lo, width) = (self.ranges.out_lo[o], self.ranges.out_width[o]);
            for (d, s) in yo.iter_mut().zip(s) {
                *d = lo + self.output_act.apply(s) * width;
            }
        }
        y
    }

    /// Hidden units `0..nh` into `f[1 + POSE_DIM + k]`; returns the offset
    /// of the first output row.
    #[inline(always)]
    fn hidden_layer<const L: usize>(
        &self,
        f: &mut [[f32; L]; MAX_FEATURES],
        nh: usize,
        act: impl Fn(f32) -> f32,
    ) -> usize {
        let mut start = 0;
        for k in 0..nh {
            let len = 1 + POSE_DIM + k;
            let Some(w) = self.weights.get(start..start + len) else {
                break;
            };
            start += len;
            let s = dot(w, &f[..len]);
            for (h, s) in f[len].iter_mut().zip(s) {
                *h = act(s);
            }
        }
        start
    }
}

/// Whether this CPU runs AVX2 instructions.
fn cpu_has_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// `w · f` for `L` queries at once, in the firmware's order for each query
/// (`s[i mod 4] += w_i f_i[q]`, then `(s0 + s1) + (s2 + s3)`); `f` as long
/// as `w`. The inner loops over the lanes are what LLVM vectorises.
#[inline(always)]
fn dot<const L: usize>(w: &[f32], f: &[[f32; L]]) -> [f32; L] {
    let mut s = [[0.0f32; L]; 4];
    let (w4, f4) = (w.chunks_exact(4), f.chunks_exact(4));
    let (wr, fr) = (w4.remainder(), f4.remainder());
    for (wc, fc) in w4.zip(f4) {
        for ((sj, &wj), fj) in s.iter_mut().zip(wc).zip(fc) {
            for (a, &x) in sj.iter_mut().zip(fj) {
                *a += wj * x;
            }
        }
    }
    for ((sj, &wj), fj) in s.iter_mut().zip(wr).zip(fr) {
        for (a, &x) in sj.iter_mut().zip(fj) {
            *a += wj * x;
        }
    }
    let [s0, s1, s2, s3] = s;
    let mut out = [0.0f32; L];
    for (q, o) in out.iter_mut().enumerate() {
        *o = (s0[q] + s1[q]) + (s2[q] + s3[q]);
    }
    out
}

#[cfg(test)]
mod tests {
    //! The fast path against the firmware's `infer`, bit for bit: a wrong
    //! weight index, a dropped or reordered product changes the bits of
    //! nearly every query.
    use super::*;
    use crate::net::test_nets::{exact, poses, random_64, shipped as tnet};

    fn check_bits(net: &McuNet, seed: u64) {
        let fast = HostNet::new(net);
        let no = net.shape().outputs;
        assert!(no > 0 && net.shape().hidden > 0);
        // Lengths around the block size exercise the partial last block.
        for n in [1, 7, 8, 9, 17, 3001] {
            let x = poses(net, n, seed + n as u64);
            let mut out = vec![f32::NAN; n * no];
            fast.infer_rows(&x, &mut out);
            let mut one = [f32::NAN; MAX_TENDONS];
            for (r, p) in x.iter().enumerate() {
                let want = tendril_firmware::infer(net, p);
                fast.infer_one(p, &mut one);
                let got = &out[r * no..(r + 1) * no];
                for (o, ((g, s), w)) in got.iter().zip(&one).zip(&want).enumerate() {
                    assert_eq!(
                        g.to_bits(),
                        w.to_bits(),
                        "batch of {n}, row {r}, output {o}: {g} vs firmware {w}"
                    );
                    assert_eq!(s.to_bits(), w.to_bits(), "single, row {r}, output {o}");
                }
            }
        }
    }

    /// The SSE2 kernel too, where the CPU would pick the AVX2 one.
    #[test]
    fn the_eight_lane_kernel_is_bit_identical_too() {
        let net = random_64();
        let fast = HostNet::new(&net);
        let x = poses(&net, 1001, 9);
        let mut out = vec![f32::NAN; x.len() * 4];
        fast.rows::<LANES>(&x, &mut out);
        for (r, p) in x.iter().enumerate() {
            let want = tendril_firmware::infer(&net, p);
            for (g, w) in out[r * 4..(r + 1) * 4].iter().zip(&want) {
                assert_eq!(g.to_bits(), w.to_bits(), "row {r}: {g} vs firmware {w}");
            }
        }
    }

    /// The largest distance from the exact evaluation over random poses, as
    /// a fraction of each output's range: (firmware, relaxed).
    fn distances(net: &McuNet, seed: u64) -> (f64, f64) {
        let fast = HostNet::new(net);
        let (lo, hi) = (net.output_lo(), net.output_hi());
        let (mut firmware, mut relaxed) = (0.0f64, 0.0f64);
        let mut got = [f32::NAN; MAX_TENDONS];
        for p in poses(net, 3000, seed) {
            let fw = tendril_firmware::infer(net, &p);
            fast.infer_one_relaxed(&p, &mut got);
            for (o, e) in exact(net, &p).into_iter().enumerate() {
                let width = f64::from(hi[o] - lo[o]);
                assert!(got[o].is_finite(), "output {o}: {} vs {e}", got[o]);
                firmware = firmware.max((f64::from(fw[o]) - e).abs() / width);
                relaxed = relaxed.max((f64::from(got[o]) - e).abs() / width);
            }
        }
        (firmware, relaxed)
    }

    /// Trained nets amplify a sigmoid's last bits (their hidden-to-output
    /// weights are large and cancel: the firmware's own `f32` arithmetic
    /// sits ~1e-4 of the range from the exact evaluation on the default
    /// net), so the bound is relative to the firmware's distance. The
    /// relaxed activation's error (≤ 1.8e-7 on the sigmoid's scale,
    /// `relaxed` tests) is about twice the firmware sigmoid's measured 1e-7
    /// (`tendril_shared::Activation`), and both pass through the same
    /// amplification: hence three times.
    #[test]
    fn relaxed_single_queries_are_as_close_to_the_exact_net_as_the_firmware() {
        for (name, net) in [
            ("default", tnet("default.tnet")),
            ("tdcr-2seg", tnet("tdcr-2seg.tnet")),
            ("random 7-64-4", random_64()),
        ] {
            let (firmware, relaxed) = distances(&net, 4);
            eprintln!("{name}: from the exact net, firmware {firmware:.2e}, relaxed {relaxed:.2e} of the range");
            assert!(
                relaxed <= 3.0 * firmware.max(1e-7),
                "{name}: relaxed {relaxed:e} of the range from the exact net, firmware {firmware:e}"
            );
        }
    }

    #[test]
    fn bit_identical_to_the_firmware_on_the_default_net() {
        check_bits(&tnet("default.tnet"), 1);
    }

    #[test]
    fn bit_identical_to_the_firmware_on_the_two_segment_net() {
        check_bits(&tnet("tdcr-2seg.tnet"), 2);
    }

    #[test]
    fn bit_identical_to_the_firmware_on_a_random_64_unit_net() {
        check_bits(&random_64(), 3);
    }

    #[test]
    fn short_output_buffer_panics() {
        let net = HostNet::new(&tnet("default.tnet"));
        let x = [[0.0f32; POSE_DIM]; 2];
        let mut out = vec![0.0; 2 * net.outputs() - 1];
        let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            net.infer_rows(&x, &mut out)
        }));
        assert!(r.is_err());
    }
}

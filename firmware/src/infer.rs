//! Cascade-correlation inference in `f32`: normalise the pose, run the
//! cascade, de-normalise to newtons. One code path for host and MCU, so the
//! two builds agree bit for bit (IEEE-754 `+`, `*`, `/` are exactly rounded
//! everywhere and `libm::expf` is plain Rust).

use tendril_shared::CascadeNet;

/// The first `n` entries of `a`, or all of it (capacities are checked by the
/// decoder; this keeps indexing panic-free).
#[inline]
fn prefix(a: &[f32], n: usize) -> &[f32] {
    a.get(..n).unwrap_or(a)
}

/// Dot product with four interleaved partial sums, combined as
/// `(s0 + s1) + (s2 + s3)`.
///
/// Four independent accumulators break the add latency chain (the host build
/// runs ~4× faster) and let the M4 load four weights with one `vldmia`; the
/// summation order is fixed by this code, not by the compiler, so it is the
/// same on every target. Extra trailing entries of the longer slice are
/// ignored.
#[inline]
pub fn dot(w: &[f32], a: &[f32]) -> f32 {
    let n = w.len().min(a.len());
    let (w, a) = (prefix(w, n), prefix(a, n));
    let mut s0 = 0.0f32;
    let mut s1 = 0.0f32;
    let mut s2 = 0.0f32;
    let mut s3 = 0.0f32;
    let wc = w.chunks_exact(4);
    let ac = a.chunks_exact(4);
    let (wr, ar) = (wc.remainder(), ac.remainder());
    for (wq, aq) in wc.zip(ac) {
        if let ([w0, w1, w2, w3], [a0, a1, a2, a3]) = (wq, aq) {
            s0 += w0 * a0;
            s1 += w1 * a1;
            s2 += w2 * a2;
            s3 += w3 * a3;
        }
    }
    let mut tail = 0.0f32;
    for (x, y) in wr.iter().zip(ar) {
        tail += x * y;
    }
    ((s0 + s1) + (s2 + s3)) + tail
}

/// Normalise `x` into the net's input box: `(x − lo) / (hi − lo)`, entries
/// past the net's input count set to 0.
#[inline]
pub fn normalise<const IN: usize, const H: usize, const OUT: usize>(
    net: &CascadeNet<IN, H, OUT>,
    x: &[f32; IN],
) -> [f32; IN] {
    let mut xn = [0.0f32; IN];
    let ranges = net.input_lo().iter().zip(net.input_hi());
    for ((v, &xi), (&lo, &hi)) in xn.iter_mut().zip(x).zip(ranges) {
        *v = (xi - lo) / (hi - lo);
    }
    xn
}

/// Tensions (newtons) the net predicts for pose `x` (`px, py, pz` in m,
/// `qw, qx, qy, qz`); outputs past the net's output count are 0.
///
/// No checks on `x`: a NaN or huge pose gives NaN or extrapolated tensions,
/// which the control step filters. An empty net gives all zeros.
pub fn infer<const IN: usize, const H: usize, const OUT: usize>(
    net: &CascadeNet<IN, H, OUT>,
    x: &[f32; IN],
) -> [f32; OUT] {
    let xn = normalise(net, x);
    let mut h = [0.0f32; H];
    let hidden_act = net.hidden_activation();
    for (k, unit) in net.hidden_units().iter().enumerate() {
        let s = unit.bias + dot(&unit.inputs, &xn) + dot(prefix(&unit.hidden, k), prefix(&h, k));
        if let Some(slot) = h.get_mut(k) {
            *slot = hidden_act.apply(s);
        }
    }
    let nh = net.shape().hidden;
    let hs = prefix(&h, nh);
    let out_act = net.output_activation();
    let mut y = [0.0f32; OUT];
    let ranges = net.output_lo().iter().zip(net.output_hi());
    for ((yo, unit), (&lo, &hi)) in y.iter_mut().zip(net.output_units()).zip(ranges) {
        let s = unit.bias + dot(&unit.inputs, &xn) + dot(prefix(&unit.hidden, nh), hs);
        *yo = lo + out_act.apply(s) * (hi - lo);
    }
    y
}

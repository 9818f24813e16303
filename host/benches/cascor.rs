//! Cascade-correlation speed: f32 inference per query (the firmware's code
//! path, via the host's decoded net), the host layout ([`HostNet`]: one
//! query, and batches per row, against the per-row firmware loop it
//! replaced), the polish's loss and gradient (issue 48 item 1: the
//! batched kernel against the per-row reference) and a small training
//! run. The full
//! training figure (default dataset, 20,000 rows) is a `tendril train` wall
//! time; BENCHMARKS.md gives the command.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use nalgebra::DMatrix;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tendril::learn::cascor::export::{to_bytes, Ranges};
use tendril::learn::cascor::polish::{
    loss_and_gradient, loss_and_gradient_per_row, RowMetrics, Rows,
};
use tendril::learn::cascor::{train, CascorOptions, GrowingNet, OutputKind};
use tendril::net::{decode, infer, pose_rows, HostNet};

fn random_net(hidden: usize) -> GrowingNet {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    GrowingNet {
        n_inputs: 7,
        n_outputs: 4,
        hidden: (0..hidden)
            .map(|k| (0..8 + k).map(|_| rng.random_range(-1.0..1.0)).collect())
            .collect(),
        outputs: (0..4)
            .map(|_| {
                (0..8 + hidden)
                    .map(|_| rng.random_range(-1.0..1.0))
                    .collect()
            })
            .collect(),
        output_kind: OutputKind::Linear,
    }
}

fn inference(c: &mut Criterion) {
    let ranges = Ranges {
        input_lo: vec![-0.11, -0.11, 0.2, 0.9, -0.3, -0.3, -0.01],
        input_hi: vec![0.16, 0.11, 0.4, 1.0, 0.3, 0.3, 0.01],
        output_lo: vec![0.0; 4],
        output_hi: vec![10.0; 4],
    };
    let pose = [0.03, -0.02, 0.37, 0.97, 0.05, 0.1, 0.001];
    for hidden in [40, 64] {
        let net = decode(&to_bytes(&random_net(hidden), &ranges).unwrap()).unwrap();
        c.bench_function(&format!("cascor_infer_f32_{hidden}_hidden"), |b| {
            b.iter(|| infer(&net, std::hint::black_box(&pose)))
        });
    }
    host_inference(c, &ranges);
}

/// Issue 29 item 2, the 7-64-4 net: single queries and 600-row batches
/// (a test split's size) through [`HostNet`], and the same through the
/// firmware's `infer` row by row (what `net::infer_batch` did before).
fn host_inference(c: &mut Criterion, ranges: &Ranges) {
    let net = decode(&to_bytes(&random_net(64), ranges).unwrap()).unwrap();
    let fast = HostNet::new(&net);
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let rows = 600;
    let poses = DMatrix::from_fn(rows, 7, |_, c| {
        let (lo, hi) = (ranges.input_lo[c], ranges.input_hi[c]);
        lo + (hi - lo) * rng.random_range(0.0..1.0)
    });
    let x = pose_rows(&poses);
    let pose = x[0];
    let mut one = [0.0f32; 8];
    c.bench_function("host_infer_64_single/firmware_infer", |b| {
        b.iter(|| tendril_firmware::infer(&net, std::hint::black_box(&pose)))
    });
    c.bench_function("host_infer_64_single/host_net", |b| {
        b.iter(|| fast.infer_one(std::hint::black_box(&pose), &mut one))
    });
    c.bench_function("host_infer_64_single/host_net_relaxed", |b| {
        b.iter(|| fast.infer_one_relaxed(std::hint::black_box(&pose), &mut one))
    });
    let mut g = c.benchmark_group("host_infer_64_batch_600");
    g.throughput(Throughput::Elements(rows as u64));
    let mut y = vec![0.0f32; rows * 4];
    g.bench_function("firmware_infer_per_row", |b| {
        b.iter(|| {
            for (p, out) in std::hint::black_box(&x).iter().zip(y.chunks_exact_mut(4)) {
                out.copy_from_slice(&tendril_firmware::infer(&net, p)[..4]);
            }
        })
    });
    g.bench_function("host_net_infer_rows", |b| {
        b.iter(|| fast.infer_rows(std::hint::black_box(&x), &mut y))
    });
    g.finish();
}

/// One evaluation of the polish's loss and gradient (tip metric on) on the
/// two-segment robot's shape: a 7-64-4 net and its 17,460 fitting rows.
fn polish(c: &mut Criterion) {
    let net = random_net(64);
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    let n = 17_460;
    let x = DMatrix::from_fn(n, 7, |_, _| rng.random_range(-0.5..0.5));
    let y = DMatrix::from_fn(n, 4, |_, _| rng.random_range(0.0..1.0));
    // Each row's metric a symmetric positive definite 4×4, as the tip metric's.
    let mut m = Vec::with_capacity(n * 16);
    for _ in 0..n {
        let a: Vec<f64> = (0..16).map(|_| rng.random_range(-1.0..1.0)).collect();
        for i in 0..4 {
            for j in 0..4 {
                let aat: f64 = (0..4).map(|k| a[i * 4 + k] * a[j * 4 + k]).sum();
                m.push(aat + if i == j { 0.1 } else { 0.0 });
            }
        }
    }
    let metric = RowMetrics { outputs: 4, m };
    let rows = Rows {
        metric: Some(&metric),
        ..Rows::plain(&x, &y)
    };
    let mut g = c.benchmark_group("polish_loss_gradient_7_64_4_17460_rows");
    g.sample_size(20);
    g.throughput(Throughput::Elements(n as u64));
    g.bench_function("per_row", |b| {
        b.iter(|| loss_and_gradient_per_row(&net, std::hint::black_box(rows), true))
    });
    g.bench_function("batched", |b| {
        b.iter(|| loss_and_gradient(&net, std::hint::black_box(rows), true))
    });
    g.bench_function("batched_loss_only", |b| {
        b.iter(|| loss_and_gradient(&net, std::hint::black_box(rows), false))
    });
    g.finish();
}

fn training(c: &mut Criterion) {
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let n = 2000;
    let x = DMatrix::from_fn(n, 2, |_, _| rng.random_range(0.0..1.0));
    let y = DMatrix::from_fn(n, 1, |r, _| {
        0.5 + 0.3 * (3.0f64 * x[(r, 0)]).sin() * (2.0f64 * x[(r, 1)]).cos()
    });
    let (vx, vy) = (x.rows(0, 200).into_owned(), y.rows(0, 200).into_owned());
    let o = CascorOptions {
        max_hidden: 8,
        progress: false,
        output_kinds: vec![OutputKind::Linear],
        ..CascorOptions::default()
    };
    let mut g = c.benchmark_group("cascor_train");
    g.sample_size(10);
    g.bench_function("2000_rows_8_units", |b| {
        b.iter(|| train(&x, &y, &vx, &vy, &o, 1).unwrap())
    });
    g.finish();
}

criterion_group!(benches, inference, polish, training);
criterion_main!(benches);

//! Dataset generation: draw tensions, solve the statics for each in parallel,
//! warm-started along a path through tension space, check every row.
//!
//! Determinism whatever the thread count: the samples are ordered by a snake
//! walk and cut into fixed-size chunks; each chunk is solved sequentially
//! (first sample cold, the rest warm-started from their predecessor), and
//! chunks are independent. So a row's value never depends on which thread or
//! in what order the chunks ran.
//!
//! Bounded memory whatever the count: samples are drawn, ordered and solved
//! one block of [`BLOCK`] at a time, and each block's rows go to a sink (the
//! CSV being written) before the next block is drawn (docs/design.md §3).

use std::sync::atomic::{AtomicBool, Ordering};

use indicatif::ProgressBar;
use rayon::prelude::*;

use super::io::{ColumnRange, Sidecar};
use super::sample::{snake_order, Sampler};
use super::{Dataset, Resolve};
use crate::inverse::{ExactIk, IkSettings, Target};
use crate::robot::anchor_groups;
use crate::statics::{Solution, SolveError, Statics, WarmStart};

/// Samples per warm-started chain. Small enough to balance two cores, large
/// enough that the one cold start per chunk is negligible.
pub const CHUNK: usize = 128;
/// Grid cells per tension axis for the snake ordering.
const SNAKE_CELLS: usize = 24;

/// What to generate.
#[derive(Clone, Debug)]
pub struct GenerateOptions {
    /// Samples to draw.
    pub samples: usize,
    /// Random seed of the sampler.
    pub seed: u64,
    /// Sampler.
    pub sampler: Sampler,
    /// Which tensions each row keeps.
    pub resolve: Resolve,
    /// Show a progress bar on stderr.
    pub progress: bool,
}

/// What a streamed generation run counted (the rows themselves went to the sink).
#[derive(Clone, Debug, Default)]
pub struct Tally {
    /// Rows that solved and were handed to the sink.
    pub kept: usize,
    /// Warm-started solves that failed and were re-solved cold.
    pub resolved_cold: usize,
    /// Samples dropped because the cold solve also failed.
    pub dropped: usize,
    /// The first few failures (drawn tensions, why), for the log.
    pub failures: Vec<(Vec<f64>, String)>,
    /// Per-column minima and maxima of the kept rows (tensions, then pose).
    pub lo: Vec<f64>,
    /// See `lo`.
    pub hi: Vec<f64>,
}

/// Failures kept in [`Tally::failures`] for the log.
const FAILURES_KEPT: usize = 10;

/// Why a streamed generation run stopped.
#[derive(Debug, thiserror::Error)]
pub enum StreamError {
    /// Ctrl-C or another stop request.
    #[error("interrupted; nothing was written")]
    Interrupted,
    /// The sink failed to take a row.
    #[error("writing a row")]
    Sink(#[source] std::io::Error),
}

/// Samples drawn, ordered and solved at a time: bounds memory (≈ 10 MB)
/// whatever the count. A count up to one block draws and orders
/// exactly as an unblocked run would, so the default 20,000-sample dataset is
/// the one it always was.
pub const BLOCK: usize = 32_768;

/// Seed of block `b`: the run's seed for the first block, a splitmix64 mix of
/// the seed and the block index after it (independent streams per block).
fn block_seed(seed: u64, b: usize) -> u64 {
    if b == 0 {
        return seed;
    }
    let mut z = seed ^ (b as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Generate `opts.samples` rows, handing each solved row (tensions, pose) to
/// `sink` in sample order as its block completes; memory stays bounded by
/// [`BLOCK`]. `stop` is polled between chunks of [`CHUNK`] solves; when it is
/// set, returns [`StreamError::Interrupted`] and the caller discards what the
/// sink got.
pub fn generate_rows<F>(
    statics: &Statics,
    opts: &GenerateOptions,
    stop: &AtomicBool,
    mut sink: F,
) -> Result<Tally, StreamError>
where
    F: FnMut(&[f64], &[f64; 7]) -> std::io::Result<()>,
{
    let max = statics.robot().max_tensions();
    let min = statics.robot().min_tensions();
    let groups = anchor_groups(statics.robot());
    let width = max.len() + 7;
    let mut tally = Tally {
        lo: vec![f64::INFINITY; width],
        hi: vec![f64::NEG_INFINITY; width],
        ..Tally::default()
    };
    // Resolving a row costs one exact IK run, ~50 statics solves: the bar
    // counts both passes.
    let passes = if opts.resolve == Resolve::Drawn { 1 } else { 2 };
    let bar = solve_bar(passes * opts.samples, opts.progress);
    let resolver = match opts.resolve {
        Resolve::Drawn => None,
        resolve => Some(ExactIk::new(
            statics.robot(),
            IkSettings {
                statics: *statics.settings(),
                redundancy: resolve.redundancy(),
                ..IkSettings::default()
            },
        )),
    };
    let mut done = 0;
    for b in 0.. {
        if done >= opts.samples {
            break;
        }
        if stop.load(Ordering::Relaxed) {
            return Err(StreamError::Interrupted);
        }
        let len = BLOCK.min(opts.samples - done);
        done += len;
        let tensions =
            opts.sampler
                .draw_grouped(len, &min, &max, &groups, block_seed(opts.seed, b));
        let order = snake_order(&tensions, &max, SNAKE_CELLS);
        let outcomes = solve_batch_with(statics, &tensions, &order, &bar, stop, |o| match o {
            Outcome::Solved(s) => Ok((s.pose(), false)),
            Outcome::ResolvedCold(s) => Ok((s.pose(), true)),
            Outcome::Failed(e) => Err(e),
        })
        .ok_or(StreamError::Interrupted)?;
        let outcomes = match &resolver {
            None => outcomes
                .into_iter()
                .zip(&tensions)
                .map(|(o, t)| o.map(|(pose, cold)| (t.clone(), pose, cold)))
                .map(|o| o.map_err(|e| e.to_string()))
                .collect(),
            Some(ik) => resolve_rows(statics, ik, &tensions, outcomes, &bar, stop)
                .ok_or(StreamError::Interrupted)?,
        };
        for (drawn, outcome) in tensions.into_iter().zip(outcomes) {
            let (t, pose) = match outcome {
                Ok((t, pose, resolved_cold)) => {
                    tally.resolved_cold += usize::from(resolved_cold);
                    (t, pose)
                }
                Err(e) => {
                    tally.dropped += 1;
                    if tally.failures.len() < FAILURES_KEPT {
                        tally.failures.push((drawn, e));
                    }
                    continue;
                }
            };
            for (k, &x) in t.iter().chain(&pose).enumerate() {
                tally.lo[k] = tally.lo[k].min(x);
                tally.hi[k] = tally.hi[k].max(x);
            }
            sink(&t, &pose).map_err(StreamError::Sink)?;
            tally.kept += 1;
        }
    }
    bar.finish_and_clear();
    Ok(tally)
}

/// A row as kept: tensions, pose, whether its statics was re-solved cold;
/// or why it was dropped.
type Row = Result<(Vec<f64>, [f64; 7], bool), String>;

/// Each solved row's tip position solved again by `ik` from the floors
/// (cold, so the answer depends on the position alone, not on the drawn
/// tensions), in parallel; a row keeps the tensions found, slackened
/// ([`super::resolve::slacken`]), and the pose they reach. `None` if `stop`
/// was set.
fn resolve_rows(
    statics: &Statics,
    ik: &ExactIk,
    tensions: &[Vec<f64>],
    solved: Vec<Result<([f64; 7], bool), SolveError>>,
    bar: &ProgressBar,
    stop: &AtomicBool,
) -> Option<Vec<Row>> {
    let rows: Vec<Option<Row>> = solved
        .into_par_iter()
        .zip(tensions.par_iter())
        .map(|(outcome, drawn)| {
            if stop.load(Ordering::Relaxed) {
                return None;
            }
            bar.inc(1);
            let (pose, cold) = match outcome {
                Ok(p) => p,
                Err(e) => return Some(Err(e.to_string())),
            };
            let target = Target::Position(nalgebra::Vector3::new(pose[0], pose[1], pose[2]));
            let found = ik.solve(&target, None, None).map_err(|e| {
                format!("its tip position, drawn from {drawn:?}, not reached again: {e}")
            });
            Some(found.and_then(|s| {
                let mut t = s.tensions;
                super::resolve::slacken(statics.robot(), &mut t);
                match statics.solve(&t, Some(&s.warm)) {
                    Ok(sol) => Ok((t, sol.pose(), cold)),
                    Err(e) => Err(format!("its slackened tensions {t:?}: {e}")),
                }
            }))
        })
        .collect();
    rows.into_iter().collect()
}

/// Outcome of one sample of a batch solve.
#[derive(Debug)]
pub enum Outcome {
    /// Solved warm (or cold, for the first of its chain).
    Solved(Solution),
    /// The warm-started solve failed; a cold re-solve succeeded.
    ResolvedCold(Solution),
    /// Even the cold solve failed.
    Failed(SolveError),
}

impl Outcome {
    /// The solution, if any.
    pub fn solution(&self) -> Option<&Solution> {
        match self {
            Outcome::Solved(s) | Outcome::ResolvedCold(s) => Some(s),
            Outcome::Failed(_) => None,
        }
    }
}

/// Solve every tension vector of `tensions`, visiting them in `order` in
/// chains of [`CHUNK`] warm-started solves; chains run in parallel. A
/// warm-started solve that fails is re-solved cold before it counts as
/// failed. `order` must be a permutation of `0..tensions.len()`. Returns
/// outcomes in the index order of `tensions`, or `None` if `stop` was set
/// before the end.
pub fn solve_batch(
    statics: &Statics,
    tensions: &[Vec<f64>],
    order: &[usize],
    bar: &ProgressBar,
    stop: &AtomicBool,
) -> Option<Vec<Outcome>> {
    solve_batch_with(statics, tensions, order, bar, stop, |o| o)
}

/// [`solve_batch`], keeping only `keep(outcome)` of each sample (a solution
/// carries its warm start, ~0.5 kB, that a caller may not need).
pub fn solve_batch_with<T, K>(
    statics: &Statics,
    tensions: &[Vec<f64>],
    order: &[usize],
    bar: &ProgressBar,
    stop: &AtomicBool,
    keep: K,
) -> Option<Vec<T>>
where
    T: Send,
    K: Fn(Outcome) -> T + Sync,
{
    assert_eq!(order.len(), tensions.len(), "order must be a permutation");
    let chunks: Vec<&[usize]> = order.chunks(CHUNK).collect();
    let solved: Vec<Option<Vec<(usize, T)>>> = chunks
        .par_iter()
        .map(|chunk| {
            if stop.load(Ordering::Relaxed) {
                return None;
            }
            let mut warm: Option<WarmStart> = None;
            let mut out = Vec::with_capacity(chunk.len());
            for &i in chunk.iter() {
                let t = &tensions[i];
                let outcome = match statics.solve(t, warm.as_ref()) {
                    Ok(sol) => Outcome::Solved(sol),
                    Err(_) if warm.is_some() => match statics.solve(t, None) {
                        Ok(sol) => Outcome::ResolvedCold(sol),
                        Err(e) => Outcome::Failed(e),
                    },
                    Err(e) => Outcome::Failed(e),
                };
                if let Some(sol) = outcome.solution() {
                    warm = Some(sol.warm.clone());
                }
                out.push((i, keep(outcome)));
            }
            bar.inc(chunk.len() as u64);
            Some(out)
        })
        .collect();
    if stop.load(Ordering::Relaxed) || solved.iter().any(Option::is_none) {
        return None;
    }
    let mut slots: Vec<Option<T>> = (0..tensions.len()).map(|_| None).collect();
    for (i, outcome) in solved.into_iter().flatten().flatten() {
        slots[i] = Some(outcome);
    }
    let outcomes: Vec<T> = slots.into_iter().flatten().collect();
    assert_eq!(
        outcomes.len(),
        tensions.len(),
        "order must be a permutation"
    );
    Some(outcomes)
}

/// A progress bar on stderr for `len` solves, or a hidden one.
pub fn solve_bar(len: usize, visible: bool) -> ProgressBar {
    crate::progress::bar(
        len as u64,
        visible,
        "{spinner} solving statics [{bar:30}] {pos}/{len} {per_sec} eta {eta}",
    )
}

/// Make `sidecar` describe `data` again after its rows changed (the same
/// count; `generate --residual-from`): the column ranges and the training
/// split's ranges.
pub fn describe_again(sidecar: &mut Sidecar, data: &Dataset) {
    let columns = (0..data.n_tendons)
        .map(|j| data.tensions.column(j))
        .chain((0..7).map(|k| data.poses.column(k)));
    let (lo, hi): (Vec<f64>, Vec<f64>) = columns.map(|c| (c.min(), c.max())).unzip();
    sidecar.ranges = column_ranges(data.n_tendons, &lo, &hi);
    sidecar.count = data.len();
    sidecar.train_ranges = Some(
        super::split::prepare(data, sidecar.test_fraction, 0.0, super::split::SPLIT_SEED).ranges(),
    );
}

/// Per-column value ranges, for the sidecar, from the minima `lo` and maxima
/// `hi` of the columns of a dataset with `n_tendons` tendons.
pub fn column_ranges(n_tendons: usize, lo: &[f64], hi: &[f64]) -> Vec<ColumnRange> {
    Dataset::header(n_tendons)
        .into_iter()
        .zip(lo.iter().zip(hi))
        .map(|(column, (&min, &max))| ColumnRange { column, min, max })
        .collect()
}

//! Dataset generation: draw tensions, solve the statics for each in parallel,
//! warm-started along a path through tension space, check every row.
//!
//! Determinism whatever the thread count: the samples are ordered by a snake
//! walk and cut into fixed-size chunks; each chunk is solved sequentially
//! (first sample cold, the rest warm-started from their predecessor), and
//! chunks are independent. So a row's value never depends on which thread or
//! in what order the chunks ran.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};
use nalgebra::DMatrix;
use rayon::prelude::*;

use super::io::ColumnRange;
use super::sample::{snake_order, Sampler};
use super::Dataset;
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
    /// Show a progress bar on stderr.
    pub progress: bool,
}

/// The outcome of a generation run.
#[derive(Clone, Debug)]
pub struct Generated {
    /// Rows that solved, in sample order.
    pub data: Dataset,
    /// Warm-started solves that failed and were re-solved cold.
    pub resolved_cold: usize,
    /// Samples dropped because the cold solve also failed.
    pub dropped: usize,
    /// The first few failures, for the log.
    pub failures: Vec<(Vec<f64>, SolveError)>,
    /// Wall time, s.
    pub seconds: f64,
}

/// Why generation stopped.
#[derive(Debug, thiserror::Error)]
pub enum GenerateError {
    /// Ctrl-C or another stop request.
    #[error("interrupted; nothing was written")]
    Interrupted,
    /// Nothing to generate.
    #[error("--samples must be at least 1")]
    NoSamples,
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
    assert_eq!(order.len(), tensions.len(), "order must be a permutation");
    let chunks: Vec<&[usize]> = order.chunks(CHUNK).collect();
    let solved: Vec<Option<Vec<(usize, Outcome)>>> = chunks
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
                out.push((i, outcome));
            }
            bar.inc(chunk.len() as u64);
            Some(out)
        })
        .collect();
    if stop.load(Ordering::Relaxed) || solved.iter().any(Option::is_none) {
        return None;
    }
    let mut slots: Vec<Option<Outcome>> = (0..tensions.len()).map(|_| None).collect();
    for (i, outcome) in solved.into_iter().flatten().flatten() {
        slots[i] = Some(outcome);
    }
    let outcomes: Vec<Outcome> = slots.into_iter().flatten().collect();
    assert_eq!(
        outcomes.len(),
        tensions.len(),
        "order must be a permutation"
    );
    Some(outcomes)
}

/// A progress bar on stderr for `len` solves, or a hidden one.
pub fn solve_bar(len: usize, visible: bool) -> ProgressBar {
    if !visible {
        return ProgressBar::hidden();
    }
    let b = ProgressBar::new(len as u64);
    b.set_style(
        ProgressStyle::with_template(
            "{spinner} solving statics [{bar:30}] {pos}/{len} {per_sec} eta {eta}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    b
}

/// Generate a dataset. `stop` is polled between chunks (set it from a Ctrl-C
/// handler); when it is set, returns [`GenerateError::Interrupted`].
pub fn generate(
    statics: &Statics,
    opts: &GenerateOptions,
    stop: &AtomicBool,
) -> Result<Generated, GenerateError> {
    if opts.samples == 0 {
        return Err(GenerateError::NoSamples);
    }
    let start = Instant::now();
    let max = statics.robot().max_tensions();
    let min = statics.robot().min_tensions();
    let tensions = opts
        .sampler
        .draw_between(opts.samples, &min, &max, opts.seed);
    let order = snake_order(&tensions, &max, SNAKE_CELLS);
    let bar = solve_bar(opts.samples, opts.progress);
    let outcomes =
        solve_batch(statics, &tensions, &order, &bar, stop).ok_or(GenerateError::Interrupted)?;
    bar.finish_and_clear();

    let (mut resolved_cold, mut dropped) = (0, 0);
    let mut failures = Vec::new();
    let mut kept_t = Vec::with_capacity(opts.samples * max.len());
    let mut kept_p = Vec::with_capacity(opts.samples * 7);
    for (t, outcome) in tensions.into_iter().zip(outcomes) {
        let sol = match outcome {
            Outcome::Solved(s) => s,
            Outcome::ResolvedCold(s) => {
                resolved_cold += 1;
                s
            }
            Outcome::Failed(e) => {
                dropped += 1;
                if failures.len() < 10 {
                    failures.push((t, e));
                }
                continue;
            }
        };
        kept_t.extend_from_slice(&t);
        kept_p.extend_from_slice(&sol.pose());
    }
    let n = kept_p.len() / 7;
    Ok(Generated {
        data: Dataset {
            n_tendons: max.len(),
            tensions: DMatrix::from_row_slice(n, max.len(), &kept_t),
            poses: DMatrix::from_row_slice(n, 7, &kept_p),
        },
        resolved_cold,
        dropped,
        failures,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// Per-column value ranges of a dataset, for the sidecar.
pub fn column_ranges(data: &Dataset) -> Vec<ColumnRange> {
    let names = Dataset::header(data.n_tendons);
    let columns = data.tensions.column_iter().chain(data.poses.column_iter());
    names
        .into_iter()
        .zip(columns)
        .map(|(column, c)| ColumnRange {
            column,
            min: c.min(),
            max: c.max(),
        })
        .collect()
}

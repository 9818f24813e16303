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

use super::sample::{snake_order, Sampler};
use super::{Dataset, POSE_COLUMNS};
use crate::statics::{SolveError, Statics, WarmStart};

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

/// Outcome of one sample.
enum Row {
    Ok([f64; 7]),
    ResolvedCold([f64; 7]),
    Failed(SolveError),
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
    let tensions = opts.sampler.draw(opts.samples, &max, opts.seed);
    let order = snake_order(&tensions, &max, SNAKE_CELLS);

    let bar = if opts.progress {
        let b = ProgressBar::new(opts.samples as u64);
        b.set_style(
            ProgressStyle::with_template(
                "{spinner} solving statics [{bar:30}] {pos}/{len} {per_sec} eta {eta}",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
        );
        b
    } else {
        ProgressBar::hidden()
    };

    let chunks: Vec<&[usize]> = order.chunks(CHUNK).collect();
    let solved: Vec<Option<Vec<(usize, Row)>>> = chunks
        .par_iter()
        .map(|chunk| {
            if stop.load(Ordering::Relaxed) {
                return None;
            }
            let mut warm: Option<WarmStart> = None;
            let mut out = Vec::with_capacity(chunk.len());
            for &i in chunk.iter() {
                let t = &tensions[i];
                let row = match statics.solve(t, warm.as_ref()) {
                    Ok(sol) => {
                        warm = Some(sol.warm.clone());
                        Row::Ok(sol.pose())
                    }
                    Err(_) if warm.is_some() => match statics.solve(t, None) {
                        Ok(sol) => {
                            warm = Some(sol.warm.clone());
                            Row::ResolvedCold(sol.pose())
                        }
                        Err(e) => Row::Failed(e),
                    },
                    Err(e) => Row::Failed(e),
                };
                out.push((i, row));
            }
            bar.inc(chunk.len() as u64);
            Some(out)
        })
        .collect();
    bar.finish_and_clear();
    if stop.load(Ordering::Relaxed) || solved.iter().any(Option::is_none) {
        return Err(GenerateError::Interrupted);
    }

    let mut rows: Vec<Option<Row>> = (0..opts.samples).map(|_| None).collect();
    for (i, row) in solved.into_iter().flatten().flatten() {
        rows[i] = Some(row);
    }
    let (mut resolved_cold, mut dropped) = (0, 0);
    let mut failures = Vec::new();
    let mut kept_t = Vec::with_capacity(opts.samples * max.len());
    let mut kept_p = Vec::with_capacity(opts.samples * 7);
    for (i, row) in rows.into_iter().enumerate() {
        let pose = match row {
            Some(Row::Ok(p)) => p,
            Some(Row::ResolvedCold(p)) => {
                resolved_cold += 1;
                p
            }
            Some(Row::Failed(e)) => {
                dropped += 1;
                if failures.len() < 10 {
                    failures.push((tensions[i].clone(), e));
                }
                continue;
            }
            None => unreachable!("every sample belongs to exactly one chunk"),
        };
        kept_t.extend_from_slice(&tensions[i]);
        kept_p.extend_from_slice(&pose);
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

/// Per-column (name, min, max) of a dataset, for the sidecar.
pub fn column_ranges(data: &Dataset) -> Vec<(String, f64, f64)> {
    let mut out = Vec::new();
    for (j, c) in data.tensions.column_iter().enumerate() {
        out.push((format!("t{j}"), c.min(), c.max()));
    }
    for (name, c) in POSE_COLUMNS.iter().zip(data.poses.column_iter()) {
        out.push((name.to_string(), c.min(), c.max()));
    }
    out
}

//! Sample statistics the processes report (lateness, latency, step times),
//! and the streaming CSV logs the launcher joins into its report.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::clock::percentile;
use super::IpcError;

/// Percentiles of a set of durations, in microseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// Number of samples.
    pub count: usize,
    /// Median.
    pub p50: f64,
    /// 90th percentile.
    pub p90: f64,
    /// 99th percentile.
    pub p99: f64,
    /// 99.9th percentile.
    pub p999: f64,
    /// Largest sample.
    pub max: f64,
    /// Mean.
    pub mean: f64,
}

impl Summary {
    /// Summarise durations given in nanoseconds (sorts `ns`).
    pub fn of_ns(ns: &mut [u64]) -> Summary {
        if ns.is_empty() {
            return Summary::default();
        }
        let us = |v: Option<u64>| v.unwrap_or(0) as f64 / 1e3;
        let mean = ns.iter().map(|&v| v as f64).sum::<f64>() / ns.len() as f64 / 1e3;
        Summary {
            count: ns.len(),
            p50: us(percentile(ns, 50.0)),
            p90: us(percentile(ns, 90.0)),
            p99: us(percentile(ns, 99.0)),
            p999: us(percentile(ns, 99.9)),
            max: us(ns.iter().max().copied()),
            mean,
        }
    }
}

/// A CSV log written as the process runs (buffered, flushed on `flush` and
/// on drop), so a process killed mid-run still leaves all but its last few
/// rows for the launcher. Not atomic by design: it is a log, not an output.
pub struct CsvLog {
    path: PathBuf,
    out: Option<BufWriter<File>>,
}

impl CsvLog {
    /// Start a log with `header` (comma-separated column names); `None`
    /// path gives a log that discards everything.
    pub fn create(path: Option<&Path>, header: &str) -> Result<CsvLog, IpcError> {
        let Some(path) = path else {
            return Ok(CsvLog {
                path: PathBuf::new(),
                out: None,
            });
        };
        let io = |source| IpcError::Io {
            path: path.to_path_buf(),
            source,
        };
        let mut out = BufWriter::with_capacity(64 * 1024, File::create(path).map_err(io)?);
        writeln!(out, "{header}").map_err(io)?;
        Ok(CsvLog {
            path: path.to_path_buf(),
            out: Some(out),
        })
    }

    /// Append one row of numbers.
    pub fn row(&mut self, values: &[f64]) -> Result<(), IpcError> {
        let Some(out) = self.out.as_mut() else {
            return Ok(());
        };
        let mut line = String::with_capacity(values.len() * 12);
        for (i, v) in values.iter().enumerate() {
            if i > 0 {
                line.push(',');
            }
            line.push_str(&format!("{v}"));
        }
        line.push('\n');
        out.write_all(line.as_bytes())
            .map_err(|source| IpcError::Io {
                path: self.path.clone(),
                source,
            })
    }

    /// Push buffered rows to the file.
    pub fn flush(&mut self) -> Result<(), IpcError> {
        if let Some(out) = self.out.as_mut() {
            out.flush().map_err(|source| IpcError::Io {
                path: self.path.clone(),
                source,
            })?;
        }
        Ok(())
    }
}

/// Read a numeric CSV log written by [`CsvLog`]: header names and rows.
/// A truncated last line (process killed mid-write) is skipped.
pub fn read_log(path: &Path) -> Result<(Vec<String>, Vec<Vec<f64>>), IpcError> {
    let text = std::fs::read_to_string(path).map_err(|source| IpcError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let mut lines = text.lines();
    let header: Vec<String> = lines
        .next()
        .unwrap_or("")
        .split(',')
        .map(str::to_string)
        .collect();
    let mut rows = Vec::new();
    for line in lines {
        let row: Result<Vec<f64>, _> = line.split(',').map(str::parse::<f64>).collect();
        match row {
            Ok(r) if r.len() == header.len() => rows.push(r),
            _ => continue,
        }
    }
    Ok((header, rows))
}

/// Column index by name, as a typed error if missing.
pub fn column(header: &[String], name: &str, path: &Path) -> Result<usize, IpcError> {
    header
        .iter()
        .position(|h| h == name)
        .ok_or_else(|| IpcError::Other(format!("{}: no column {name:?}", path.display())))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn summary_reports_microseconds() {
        let mut ns: Vec<u64> = (1..=1000).map(|i| i * 1000).collect();
        let s = Summary::of_ns(&mut ns);
        assert_eq!(s.count, 1000);
        assert_eq!(s.p50, 500.0);
        assert_eq!(s.p99, 990.0);
        assert_eq!(s.max, 1000.0);
        assert!((s.mean - 500.5).abs() < 1e-9);
    }

    #[test]
    fn csv_log_round_trips_and_skips_truncated_rows() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("log.csv");
        let mut log = CsvLog::create(Some(&path), "a,b").unwrap();
        log.row(&[1.0, 2.5]).unwrap();
        log.row(&[3.0, -4.0]).unwrap();
        log.flush().unwrap();
        drop(log);
        let mut text = std::fs::read_to_string(&path).unwrap();
        text.push_str("5,");
        std::fs::write(&path, text).unwrap();
        let (header, rows) = read_log(&path).unwrap();
        assert_eq!(header, vec!["a", "b"]);
        assert_eq!(rows, vec![vec![1.0, 2.5], vec![3.0, -4.0]]);
    }
}

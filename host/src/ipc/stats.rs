//! Sample statistics the processes report (lateness, latency, step times),
//! and the streaming CSV logs the launcher joins into its report.
//!
//! The controller's loop must not allocate (`docs/design.md` §6), so its
//! durations go into a fixed-size [`Histogram`] instead of a growing
//! sample vector, and [`CsvLog::row`] formats straight into a buffer that
//! a writer thread takes to the file (no I/O in the loop).

use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender, TrySendError};
use std::thread::JoinHandle;

use serde::{Deserialize, Serialize};

use super::IpcError;
use crate::numerics::percentile;

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
            p50: us(percentile::of_u64(ns, 50.0)),
            p90: us(percentile::of_u64(ns, 90.0)),
            p99: us(percentile::of_u64(ns, 99.0)),
            p999: us(percentile::of_u64(ns, 99.9)),
            max: us(ns.iter().max().copied()),
            mean,
        }
    }
}

/// Sub-buckets per power of two in a [`Histogram`]: relative resolution 1/32.
const SUB_BITS: u32 = 5;
const SUB: usize = 1 << SUB_BITS;
/// Buckets: values below `SUB` exactly, then `SUB` per octave up to 2⁶⁴.
const BUCKETS: usize = SUB + (64 - SUB_BITS as usize) * SUB;

/// Durations (ns) in log-linear buckets: a fixed 15 KiB, no allocation per
/// sample, percentiles within 1/32 (3 %) of the exact nearest-rank value;
/// count, mean and max exact.
#[derive(Clone, Debug)]
pub struct Histogram {
    buckets: Box<[u64; BUCKETS]>,
    count: u64,
    sum: u128,
    max: u64,
}

impl Default for Histogram {
    fn default() -> Self {
        Histogram {
            buckets: Box::new([0; BUCKETS]),
            count: 0,
            sum: 0,
            max: 0,
        }
    }
}

impl Histogram {
    fn index(v: u64) -> usize {
        if v < SUB as u64 {
            return v as usize;
        }
        let octave = 63 - v.leading_zeros(); // ≥ SUB_BITS
        let shift = octave - SUB_BITS;
        let sub = ((v >> shift) as usize) & (SUB - 1);
        SUB + shift as usize * SUB + sub
    }

    /// The middle of bucket `i`.
    fn value(i: usize) -> u64 {
        if i < SUB {
            return i as u64;
        }
        let shift = ((i - SUB) / SUB) as u32;
        let sub = ((i - SUB) % SUB) as u64;
        let low = (SUB as u64 + sub) << shift;
        low + ((1u64 << shift) >> 1)
    }

    /// Add one sample (ns).
    pub fn record(&mut self, ns: u64) {
        if let Some(b) = self.buckets.get_mut(Histogram::index(ns)) {
            *b += 1;
        }
        self.count += 1;
        self.sum += ns as u128;
        self.max = self.max.max(ns);
    }

    /// Number of samples.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// Nearest-rank percentile (0–100), ns, to bucket resolution (never
    /// above the exact maximum); `None` if empty. The rank is
    /// [`crate::numerics::percentile::nearest_rank`], as for a sorted
    /// slice: only the bucket's width separates the two.
    pub fn percentile(&self, p: f64) -> Option<u64> {
        if self.count == 0 {
            return None;
        }
        let rank = percentile::nearest_rank(p, self.count);
        let mut seen = 0;
        for (i, &n) in self.buckets.iter().enumerate() {
            seen += n;
            if seen >= rank {
                return Some(Histogram::value(i).min(self.max));
            }
        }
        Some(self.max)
    }

    /// The percentiles in microseconds.
    pub fn summary(&self) -> Summary {
        if self.count == 0 {
            return Summary::default();
        }
        let us = |p: f64| self.percentile(p).unwrap_or(0) as f64 / 1e3;
        Summary {
            count: self.count as usize,
            p50: us(50.0),
            p90: us(90.0),
            p99: us(99.0),
            p999: us(99.9),
            max: self.max as f64 / 1e3,
            mean: self.sum as f64 / self.count as f64 / 1e3,
        }
    }
}

/// A CSV log written as the process runs, so a process killed mid-run
/// still leaves all but its last ~100 ms of rows for the launcher. Not
/// atomic by design: it is a log, not an output. Under `tendril sim` it is
/// a scratch file in the run's work directory, moved into `--out` only
/// when the run completes; a standalone process's `--log` is opened in
/// place (`File::create`), so a symlink is followed and a device or FIFO
/// written through, never replaced (issue 31).
///
/// Rows are formatted into an in-memory buffer and the file is written by
/// a writer thread, never by the caller: a `write(2)` can block for tens
/// of milliseconds when the kernel throttles a process with dirty pages
/// (a CI machine right after a build), and the caller is a 1 kHz loop.
/// Create the log *before* switching the caller to `SCHED_FIFO` or pinning
/// it, so the writer stays an ordinary thread on any CPU.
pub struct CsvLog {
    path: PathBuf,
    inner: Option<Writer>,
}

/// Bytes of rows after which a buffer goes to the writer thread.
const HAND_OFF_BYTES: usize = 32 * 1024;
/// Capacity of each buffer: a hand-off threshold plus room for rows.
const BUFFER_BYTES: usize = 64 * 1024;
/// Buffers in circulation (caller, queue, writer): ~1 s of the
/// controller's log in flight before a buffer has to grow.
const BUFFERS: usize = 16;

/// The caller's end of a log: the buffer being filled, the queue to the
/// writer thread and the queue of emptied buffers back from it.
struct Writer {
    buf: Vec<u8>,
    full: Option<SyncSender<Vec<u8>>>,
    empty: Receiver<Vec<u8>>,
    thread: Option<JoinHandle<std::io::Result<()>>>,
}

impl Writer {
    fn start(file: File, header: &str) -> std::io::Result<Writer> {
        let (full_tx, full_rx) = sync_channel::<Vec<u8>>(BUFFERS);
        let (empty_tx, empty_rx) = std::sync::mpsc::channel::<Vec<u8>>();
        for _ in 1..BUFFERS {
            let _ = empty_tx.send(Vec::with_capacity(BUFFER_BYTES));
        }
        let thread = std::thread::Builder::new().name("csv-log".into()).spawn(
            move || -> std::io::Result<()> {
                let mut file = file;
                for mut buf in full_rx {
                    file.write_all(&buf)?;
                    buf.clear();
                    // The caller may be gone (closing): nothing to return to.
                    let _ = empty_tx.send(buf);
                }
                file.flush()
            },
        )?;
        let mut buf = Vec::with_capacity(BUFFER_BYTES);
        buf.extend_from_slice(header.as_bytes());
        buf.push(b'\n');
        Ok(Writer {
            buf,
            full: Some(full_tx),
            empty: empty_rx,
            thread: Some(thread),
        })
    }

    /// Give the filled buffer to the writer if an empty one is back;
    /// otherwise keep filling this one (the writer is behind: the buffer
    /// grows, nothing blocks).
    fn hand_off(&mut self) -> std::io::Result<()> {
        if self.buf.is_empty() {
            return Ok(());
        }
        let Ok(spare) = self.empty.try_recv() else {
            return self.check_alive();
        };
        let filled = std::mem::replace(&mut self.buf, spare);
        match self.full.as_ref().map(|tx| tx.try_send(filled)) {
            Some(Ok(())) => Ok(()),
            // Cannot happen (the queue holds every buffer there is), but
            // if it did, keep the rows and drop the spare.
            Some(Err(TrySendError::Full(filled))) => {
                self.buf = filled;
                Ok(())
            }
            Some(Err(TrySendError::Disconnected(_))) | None => self.check_alive(),
        }
    }

    /// The writer thread's error, if it stopped.
    fn check_alive(&mut self) -> std::io::Result<()> {
        if self.thread.as_ref().is_some_and(|t| t.is_finished()) || self.thread.is_none() {
            return self.join();
        }
        Ok(())
    }

    /// Send what is left, close the queue and wait for the writer.
    fn join(&mut self) -> std::io::Result<()> {
        if let Some(tx) = self.full.take() {
            if !self.buf.is_empty() {
                let _ = tx.send(std::mem::take(&mut self.buf));
            }
        }
        match self.thread.take() {
            Some(t) => t
                .join()
                .unwrap_or_else(|_| Err(std::io::Error::other("the log writer panicked"))),
            None => Err(std::io::Error::other("the log writer is not running")),
        }
    }
}

impl Drop for Writer {
    fn drop(&mut self) {
        if self.thread.is_some() {
            if let Err(e) = self.join() {
                log::warn!("log: {e}");
            }
        }
    }
}

impl CsvLog {
    /// Start a log with `header` (comma-separated column names); `None`
    /// path gives a log that discards everything.
    pub fn create(path: Option<&Path>, header: &str) -> Result<CsvLog, IpcError> {
        let Some(path) = path else {
            return Ok(CsvLog {
                path: PathBuf::new(),
                inner: None,
            });
        };
        let io = |source| IpcError::Io {
            path: path.to_path_buf(),
            source,
        };
        let file = File::create(path).map_err(io)?;
        Ok(CsvLog {
            path: path.to_path_buf(),
            inner: Some(Writer::start(file, header).map_err(io)?),
        })
    }

    fn io(&self, source: std::io::Error) -> IpcError {
        IpcError::Io {
            path: self.path.clone(),
            source,
        }
    }

    /// Append one row of numbers, formatted straight into the buffer (no
    /// allocation and no system call while the writer keeps up: the
    /// controller calls this every period).
    pub fn row(&mut self, values: &[f64]) -> Result<(), IpcError> {
        let Some(w) = self.inner.as_mut() else {
            return Ok(());
        };
        for (i, v) in values.iter().enumerate() {
            if i > 0 {
                w.buf.push(b',');
            }
            // Writing into a Vec cannot fail.
            let _ = write!(w.buf, "{v}");
        }
        w.buf.push(b'\n');
        if w.buf.len() >= HAND_OFF_BYTES {
            let r = w.hand_off();
            r.map_err(|e| self.io(e))?;
        }
        Ok(())
    }

    /// Pass the rows so far on to the writer thread (they reach the file
    /// soon after, not before this returns; [`CsvLog::close`] waits).
    pub fn flush(&mut self) -> Result<(), IpcError> {
        let r = self.inner.as_mut().map_or(Ok(()), Writer::hand_off);
        r.map_err(|e| self.io(e))
    }

    /// Write every row to the file and wait for it: the end of a run.
    pub fn close(mut self) -> Result<(), IpcError> {
        let r = self.inner.as_mut().map_or(Ok(()), Writer::join);
        r.map_err(|e| self.io(e))
    }
}

/// Read a numeric CSV log written by [`CsvLog`]: header names and rows.
/// Every complete row must hold one number per column, or the log is
/// refused naming its line; only a truncated last line is dropped.
pub fn read_log(path: &Path) -> Result<(Vec<String>, Vec<Vec<f64>>), IpcError> {
    let text = std::fs::read_to_string(path).map_err(|source| IpcError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    // The writer ends every line with '\n' and a run's processes can be
    // killed mid-write (the fault scenarios do it on purpose), so bytes
    // after the last '\n' are a row cut short: drop them, whether or not
    // they happen to parse ("1.25" cut to "1.2" would). That is the only
    // damage a kill can do — a log has one writer, appending — so any
    // other bad row is a real fault and an error. A log with no '\n' at
    // all is a (perhaps cut) header and no rows: its columns are checked
    // by [`column`].
    let complete = text.rfind('\n').map_or(text.as_str(), |end| &text[..=end]);
    let bad =
        |line: u64, why: String| IpcError::Other(format!("{}: line {line}: {why}", path.display()));
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(true)
        // Rows of the wrong width get the message below, not csv's.
        .flexible(true)
        .from_reader(complete.as_bytes());
    let header: Vec<String> = reader
        .headers()
        .map_err(|e| bad(1, e.to_string()))?
        .iter()
        .map(str::to_string)
        .collect();
    let mut rows = Vec::new();
    for record in reader.records() {
        let record = record.map_err(|e| {
            let line = e.position().map_or(0, csv::Position::line);
            bad(line, e.to_string())
        })?;
        let line = record.position().map_or(0, csv::Position::line);
        if record.len() != header.len() {
            return Err(bad(
                line,
                format!(
                    "{}, the header has {}",
                    crate::robot::count(record.len(), "field"),
                    header.len()
                ),
            ));
        }
        let row = record
            .iter()
            .zip(&header)
            .map(|(field, name)| {
                field
                    .parse::<f64>()
                    .map_err(|_| bad(line, format!("{name} = {field:?} is not a number")))
            })
            .collect::<Result<Vec<f64>, _>>()?;
        rows.push(row);
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
    fn histogram_percentiles_are_within_its_resolution_of_the_exact_ones() {
        let mut rng = 0x2545_f491_4f6c_dd1du64;
        let mut ns = Vec::new();
        let mut h = Histogram::default();
        for _ in 0..20_000 {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            // Spread over five decades, like lateness (µs) with rare ms spikes.
            let v = 10f64.powf(1.0 + 5.0 * (rng % 10_000) as f64 / 10_000.0) as u64;
            ns.push(v);
            h.record(v);
        }
        let exact = Summary::of_ns(&mut ns);
        let approx = h.summary();
        assert_eq!(approx.count, exact.count);
        assert_eq!(approx.max, exact.max);
        assert!((approx.mean - exact.mean).abs() < 1e-9 * exact.mean);
        for (a, e) in [
            (approx.p50, exact.p50),
            (approx.p90, exact.p90),
            (approx.p99, exact.p99),
            (approx.p999, exact.p999),
        ] {
            assert!((a - e).abs() <= e / 32.0, "{a} vs {e}");
        }
        // Small values are exact.
        let mut small = Histogram::default();
        for v in [3, 7, 7, 9] {
            small.record(v);
        }
        assert_eq!(small.percentile(50.0), Some(7));
        assert_eq!(small.percentile(100.0), Some(9));
        assert_eq!(Histogram::default().percentile(50.0), None);
    }

    #[test]
    fn csv_log_round_trips_and_skips_a_truncated_last_row() {
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
        // A cut last row that still parses ("5,6.25" cut to "5,6.2") is
        // dropped too: only a '\n' says a row is whole.
        std::fs::write(&path, "a,b\n1,2.5\n5,6.2").unwrap();
        assert_eq!(read_log(&path).unwrap().1, vec![vec![1.0, 2.5]]);
    }

    #[test]
    fn a_malformed_row_before_the_last_is_an_error_naming_its_line() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("log.csv");
        for (text, why) in [
            ("a,b\n1,2\n3,x\n5,6\n", "b = \"x\" is not a number"),
            ("a,b\n1,2\n3\n5,6\n", "1 field, the header has 2"),
            ("a,b\n1,2\n3,4,5\n5,6", "3 fields, the header has 2"),
        ] {
            std::fs::write(&path, text).unwrap();
            let err = read_log(&path).unwrap_err().to_string();
            assert_eq!(err, format!("{}: line 3: {why}", path.display()));
        }
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn a_write_error_in_the_writer_thread_reaches_the_caller() {
        // /dev/full takes the open and fails every write with ENOSPC.
        let full = Path::new("/dev/full");
        if !full.exists() {
            eprintln!("skipped: no /dev/full");
            return;
        }
        let mut log = CsvLog::create(Some(full), "a,b").unwrap();
        let row = [1.0; 2];
        // Enough rows for several hand-offs: the writer fails on the first
        // and a later hand-off says so, naming the file.
        let mut failed = None;
        for _ in 0..200_000 {
            if let Err(e) = log.row(&row) {
                failed = Some(e);
                break;
            }
        }
        let e = match failed {
            Some(e) => e,
            None => log.close().expect_err("closing a log on /dev/full fails"),
        };
        let text = e.to_string();
        assert!(text.contains("/dev/full"), "{text}");
    }

    #[cfg(unix)]
    #[test]
    fn a_log_through_a_symlink_or_into_a_device_leaves_the_link_and_the_device() {
        use std::os::unix::fs::FileTypeExt;
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("logs")).unwrap();
        let link = dir.path().join("log.csv");
        std::os::unix::fs::symlink("logs/log.csv", &link).unwrap();
        let mut log = CsvLog::create(Some(&link), "a").unwrap();
        log.row(&[1.0]).unwrap();
        drop(log);
        assert!(std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(
            std::fs::read_to_string(dir.path().join("logs/log.csv")).unwrap(),
            "a\n1\n"
        );
        let null = Path::new("/dev/null");
        let mut log = CsvLog::create(Some(null), "a").unwrap();
        log.row(&[1.0]).unwrap();
        log.flush().unwrap();
        assert!(std::fs::metadata(null)
            .unwrap()
            .file_type()
            .is_char_device());
    }
}

//! From the processes' logs to the report's numbers.
//!
//! The tracking error is computed from two independent records: the
//! planner's log of what it asked for and the plant's log of where the
//! simulated tip really was (no sensor noise), joined by the shared
//! monotonic clock. What the controller noticed comes from its per-period
//! log (status bits) and its statistics.

use std::path::Path;

use tendril_shared::messages::{command_status, plant_status, setpoint_flags};

use super::report::SteadyState;
pub use super::sample::Sample;
use super::supervisor::Role;
use super::SimError;
use crate::ipc::planner::LOG_INJECTED;
use crate::ipc::stats::{column, read_log};
use crate::numerics::percentile;

/// A setpoint the planner logged.
#[derive(Clone, Copy, Debug)]
pub struct SetpointRow {
    /// Send time (monotonic ns).
    pub t_ns: f64,
    /// Wire flags plus the log-only [`LOG_INJECTED`] bit.
    pub flags: u32,
    /// The trajectory's position (m), also for injected messages.
    pub position: [f64; 3],
    /// Planner generation that sent it.
    pub generation: usize,
    /// The stiffness adaptation's κ̂ applied (NaN when off, or a log
    /// without the column).
    pub stiffness: f64,
}

/// One plant step.
#[derive(Clone, Debug)]
pub struct PlantRow {
    /// Step time (monotonic ns).
    pub t_ns: f64,
    /// True tip position (m).
    pub position: [f64; 3],
    /// Commanded tensions (N).
    pub commanded: Vec<f64>,
    /// Actual tensions (N).
    pub actual: Vec<f64>,
    /// [`plant_status`] bits.
    pub status: u32,
    /// Sequence number of the command applied (0 = none yet).
    pub command_seq: f64,
    /// Plant generation that logged it.
    pub generation: usize,
}

/// One controller period.
#[derive(Clone, Copy, Debug)]
pub struct ControllerRow {
    /// Wake-up time (monotonic ns).
    pub t_ns: f64,
    /// [`command_status`] bits.
    pub status: u32,
    /// Sequence number of the setpoint in use.
    pub setpoint_seq: f64,
    /// Sequence number of the plant state in use.
    pub state_seq: f64,
}

/// All logs of one run, each sorted by time.
#[derive(Debug, Default)]
pub struct Logs {
    /// Planner logs, all generations.
    pub setpoints: Vec<SetpointRow>,
    /// Plant logs, all generations.
    pub plant: Vec<PlantRow>,
    /// Tendons (from the plant log's columns; 0 without one).
    pub tendons: usize,
    /// The controller's per-period log.
    pub controller: Vec<ControllerRow>,
}

fn logs_of(dir: &Path, stem: &str, generations: usize) -> Result<Vec<LogFile>, SimError> {
    let mut all = Vec::new();
    for g in 0..generations {
        let path = dir.join(format!("{stem}-{g}.csv"));
        if path.exists() {
            let (header, rows) = read_log(&path)?;
            all.push(LogFile {
                path,
                generation: g,
                header,
                rows,
            });
        }
    }
    Ok(all)
}

struct LogFile {
    path: std::path::PathBuf,
    generation: usize,
    header: Vec<String>,
    rows: Vec<Vec<f64>>,
}

impl Logs {
    /// Read every log in `dir`: `planner-G.csv`, `plant-G.csv` for the
    /// generations started, and `controller.csv` (with `controller-G.csv`
    /// of bridges restarted after a link cut).
    pub fn read(
        dir: &Path,
        planners: usize,
        plants: usize,
        controllers: usize,
    ) -> Result<Logs, SimError> {
        let mut logs = Logs::default();
        for f in logs_of(dir, "planner", planners)? {
            let (it, ifl, ix) = (
                column(&f.header, "t_ns", &f.path)?,
                column(&f.header, "flags", &f.path)?,
                column(&f.header, "px", &f.path)?,
            );
            let istiff = f.header.iter().position(|h| h == "stiffness");
            logs.setpoints.extend(f.rows.iter().map(|r| SetpointRow {
                t_ns: r[it],
                flags: r[ifl] as u32,
                position: [r[ix], r[ix + 1], r[ix + 2]],
                generation: f.generation,
                stiffness: istiff.map_or(f64::NAN, |i| r[i]),
            }));
        }
        logs.setpoints.sort_by(|a, b| a.t_ns.total_cmp(&b.t_ns));
        for f in logs_of(dir, "plant", plants)? {
            let it = column(&f.header, "t_ns", &f.path)?;
            let ix = column(&f.header, "px", &f.path)?;
            let ic = column(&f.header, "cmd0", &f.path)?;
            let ia = column(&f.header, "tau0", &f.path)?;
            let ist = column(&f.header, "status", &f.path)?;
            let iseq = column(&f.header, "cmd_seq", &f.path)?;
            let n = ia - ic;
            logs.tendons = n;
            logs.plant.extend(f.rows.iter().map(|r| PlantRow {
                t_ns: r[it],
                position: [r[ix], r[ix + 1], r[ix + 2]],
                commanded: r[ic..ic + n].to_vec(),
                actual: r[ia..ia + n].to_vec(),
                status: r[ist] as u32,
                command_seq: r[iseq],
                generation: f.generation,
            }));
        }
        logs.plant.sort_by(|a, b| a.t_ns.total_cmp(&b.t_ns));
        let mut controller_log = Vec::new();
        for g in 0..controllers.max(1) {
            let controller = dir.join(format!("{}.csv", super::workdir::stem(Role::Controller, g)));
            if controller.exists() {
                let (header, rows) = read_log(&controller)?;
                controller_log.push(LogFile {
                    path: controller,
                    generation: g,
                    header,
                    rows,
                });
            }
        }
        for f in controller_log {
            let (it, ist, isp, ips) = (
                column(&f.header, "t_ns", &f.path)?,
                column(&f.header, "status", &f.path)?,
                column(&f.header, "sp_seq", &f.path)?,
                column(&f.header, "state_seq", &f.path)?,
            );
            logs.controller.extend(f.rows.iter().map(|r| ControllerRow {
                t_ns: r[it],
                status: r[ist] as u32,
                setpoint_seq: r[isp],
                state_seq: r[ips],
            }));
        }
        logs.controller.sort_by(|a, b| a.t_ns.total_cmp(&b.t_ns));
        Ok(logs)
    }

    /// First controller period at or after `t_ns` with any of `bits` set.
    pub fn controller_flag_after(&self, t_ns: f64, bits: u32) -> Option<f64> {
        self.controller
            .iter()
            .find(|r| r.t_ns >= t_ns && r.status & bits != 0)
            .map(|r| r.t_ns)
    }

    /// First plant step with any of `bits` set.
    pub fn plant_flag(&self, bits: u32) -> Option<f64> {
        self.plant
            .iter()
            .find(|r| r.status & bits != 0)
            .map(|r| r.t_ns)
    }

    /// First plant row at or after `from_ns` where the commanded tension of
    /// `tendon` differs from the measured one by more than `threshold` (N):
    /// when a stuck motor first had an effect anyone could see.
    pub fn first_command_departure(
        &self,
        tendon: usize,
        from_ns: f64,
        threshold: f64,
    ) -> Option<f64> {
        self.plant
            .iter()
            .filter(|r| r.t_ns >= from_ns)
            .find(|r| {
                matches!(
                    (r.commanded.get(tendon), r.actual.get(tendon)),
                    (Some(c), Some(a)) if (c - a).abs() > threshold
                )
            })
            .map(|r| r.t_ns)
    }

    /// Largest |commanded − measured| tension of `tendon` in the plant rows
    /// from `from_ns` on (N); `None` when no row covers that time.
    pub fn largest_command_departure(&self, tendon: usize, from_ns: f64) -> Option<f64> {
        self.plant
            .iter()
            .filter(|r| r.t_ns >= from_ns)
            .filter_map(|r| Some((r.commanded.get(tendon)? - r.actual.get(tendon)?).abs()))
            .reduce(f64::max)
    }

    /// For a plant generation that wrote no statistics (killed): the
    /// commands its log shows applied, and how many of those had a tension
    /// outside `[0, max]` or not finite.
    pub fn commands_logged(&self, generation: usize, max: &[f64]) -> (u64, u64) {
        let mut last = 0.0;
        let (mut seen, mut bad) = (0, 0);
        for r in self.plant.iter().filter(|r| r.generation == generation) {
            if r.command_seq > 0.0 && r.command_seq != last {
                last = r.command_seq;
                seen += 1;
                let out = r
                    .commanded
                    .iter()
                    .zip(max)
                    .any(|(t, m)| !(t.is_finite() && *t >= 0.0 && t <= m));
                bad += u64::from(out);
            }
        }
        (seen, bad)
    }

    /// The stiffness adaptation's κ̂ when the planner stopped (None: off).
    pub fn stiffness_adapted(&self) -> Option<f64> {
        self.setpoints
            .iter()
            .rev()
            .map(|s| s.stiffness)
            .find(|k| k.is_finite())
    }

    /// When the planner's log first says learning stopped (monotonic ns).
    pub fn learning_stopped_ns(&self) -> Option<f64> {
        self.setpoints
            .iter()
            .find(|s| s.flags & crate::ipc::planner::LOG_LEARNING_STOPPED != 0)
            .map(|s| s.t_ns)
    }

    /// Injected planner messages: (first stamp, messages) of each burst of
    /// consecutive injected setpoints.
    pub fn injection_bursts(&self) -> Vec<(f64, usize)> {
        let mut bursts: Vec<(f64, usize)> = Vec::new();
        let mut previous_injected = false;
        for s in &self.setpoints {
            let injected = s.flags & LOG_INJECTED != 0;
            match (injected, previous_injected, bursts.last_mut()) {
                (true, true, Some(last)) => last.1 += 1,
                (true, _, _) => bursts.push((s.t_ns, 1)),
                _ => {}
            }
            previous_injected = injected;
        }
        bursts
    }
}

/// Join each plant step with the planner's path at its instant: the
/// setpoint in force, moved on towards the next one as far as the step is
/// between their send times (a planner at 100 Hz holds each setpoint for
/// 10 ms, 0.19 mm along the 30 mm circle: a tip exactly on the path would
/// otherwise read up to that far ahead of it). None if the planner has
/// been silent for over 50 ms; times in s since `t0_ns`.
pub fn join(logs: &Logs, t0_ns: u64) -> Vec<Sample> {
    let sp = &logs.setpoints;
    let mut samples = Vec::new();
    let mut j = 0;
    for row in &logs.plant {
        while j + 1 < sp.len() && sp[j + 1].t_ns <= row.t_ns {
            j += 1;
        }
        let Some(s) = sp.get(j) else { continue };
        if s.t_ns > row.t_ns || row.t_ns - s.t_ns > SILENT_NS {
            continue;
        }
        samples.push(Sample {
            t: (row.t_ns - t0_ns as f64) * 1e-9,
            desired: path_at(s, sp.get(j + 1), row.t_ns),
            actual: row.position,
            hold: s.flags & (setpoint_flags::HOLD | LOG_INJECTED) != 0,
            moving: s.flags & setpoint_flags::MOVING != 0,
        });
    }
    samples
}

/// A planner silent this long has no path in force, ns.
const SILENT_NS: f64 = 50e6;

/// The planner's path at `t_ns`, between the setpoint in force `s` and the
/// one after it (its position at `t_ns` on the line between them); `s`'s
/// own position when there is no next one from the same planner within
/// [`SILENT_NS`], or either was injected.
fn path_at(s: &SetpointRow, next: Option<&SetpointRow>, t_ns: f64) -> [f64; 3] {
    let Some(n) = next.filter(|n| {
        n.generation == s.generation
            && n.t_ns > s.t_ns
            && n.t_ns - s.t_ns <= SILENT_NS
            && (s.flags | n.flags) & LOG_INJECTED == 0
    }) else {
        return s.position;
    };
    let w = ((t_ns - s.t_ns) / (n.t_ns - s.t_ns)).clamp(0.0, 1.0);
    std::array::from_fn(|k| s.position[k] + w * (n.position[k] - s.position[k]))
}

/// Tracking statistics over the samples outside holds.
#[derive(Clone, Debug, Default)]
pub struct Tracking {
    /// RMS error (mm).
    pub rms: Option<f64>,
    /// Largest error (mm).
    pub max: Option<f64>,
    /// 95th percentile (mm).
    pub p95: Option<f64>,
    /// Samples behind them.
    pub samples: usize,
    /// First and last sample (s).
    pub window: Option<[f64; 2]>,
}

/// RMS of the tracking samples with `from ≤ t < to`, mm.
pub fn rms_between(samples: &[Sample], from: f64, to: f64) -> Option<f64> {
    let e: Vec<f64> = samples
        .iter()
        .filter(|s| !s.hold && s.t >= from && s.t < to)
        .map(Sample::error_mm)
        .collect();
    rms(&e)
}

/// The tracking error's RMS over each whole `period` (s) from `start` to
/// `end`, mm: a repeated path's error pass after pass.
pub fn pass_rms(samples: &[Sample], start: f64, end: f64, period: f64) -> Vec<f64> {
    (0..)
        .map(|k| start + k as f64 * period)
        .take_while(|a| a + period <= end + 1e-9)
        .filter_map(|a| rms_between(samples, a, a + period))
        .collect()
}

fn rms(e: &[f64]) -> Option<f64> {
    (!e.is_empty()).then(|| (e.iter().map(|x| x * x).sum::<f64>() / e.len() as f64).sqrt())
}

/// RMS, max and p95 of the error outside holds.
pub fn tracking(samples: &[Sample]) -> Tracking {
    let tracked: Vec<&Sample> = samples.iter().filter(|s| !s.hold).collect();
    let e: Vec<f64> = tracked.iter().map(|s| s.error_mm()).collect();
    Tracking {
        rms: rms(&e),
        max: e.iter().copied().reduce(f64::max),
        // On a copy: sorting `e` itself would reorder the sums above.
        p95: percentile::of_f64(&mut e.clone(), 95.0),
        samples: e.len(),
        window: tracked.first().zip(tracked.last()).map(|(a, b)| [a.t, b.t]),
    }
}

/// How far in time, either side of a sample, the path it is measured
/// against reaches, s: several periods of the slowest loop (100 Hz with the
/// chip) and the longest latency a clean run has, yet a small arc of any
/// trajectory the planner draws (0.4 s of the 0.2 Hz circle).
pub const PATH_WINDOW_S: f64 = 0.2;

/// RMS distance from the true tip to the planner's path, mm, over the
/// samples outside holds: the contour error of machining. The path is the
/// polyline through the setpoints issued within ±[`PATH_WINDOW_S`] of the
/// sample. The tracking error compares the tip with the path at the same
/// instant, so on a moving setpoint it includes the delay from planner to
/// tip (speed × latency: 0.19 mm per 10 ms on the 30 mm circle);
/// this one does not, and so separates what the controller computes from
/// how fast its commands arrive (reported on its own: setpoint → command).
pub fn path_error_rms(samples: &[Sample]) -> Option<f64> {
    // The path's vertices: the desired position each time it changes.
    let mut vertices: Vec<(f64, [f64; 3])> = Vec::new();
    for s in samples {
        if vertices.last().is_none_or(|v| v.1 != s.desired) {
            vertices.push((s.t, s.desired));
        }
    }
    let e: Vec<f64> = samples
        .iter()
        .filter(|s| !s.hold)
        .map(|s| {
            // The window, and always the vertex in force: a setpoint held
            // longer than the window (a step's target) is still the path.
            let current = vertices.partition_point(|v| v.0 <= s.t).saturating_sub(1);
            let from = vertices
                .partition_point(|v| v.0 < s.t - PATH_WINDOW_S)
                .min(current);
            let to = vertices
                .partition_point(|v| v.0 <= s.t + PATH_WINDOW_S)
                .max(current + 1)
                .min(vertices.len());
            let near = &vertices[from..to];
            let to_segments = near
                .windows(2)
                .map(|w| distance_to_segment(s.actual, w[0].1, w[1].1));
            // A lone vertex (a constant setpoint) is a path of one point.
            to_segments
                .chain(near.iter().map(|v| distance_to_segment(s.actual, v.1, v.1)))
                .fold(f64::INFINITY, f64::min)
                * 1e3
        })
        .collect();
    rms(&e)
}

/// Distance from `p` to the segment `a`–`b` (a point if they coincide), m.
fn distance_to_segment(p: [f64; 3], a: [f64; 3], b: [f64; 3]) -> f64 {
    let ab: [f64; 3] = std::array::from_fn(|k| b[k] - a[k]);
    let ap: [f64; 3] = std::array::from_fn(|k| p[k] - a[k]);
    let len2: f64 = ab.iter().map(|x| x * x).sum();
    let along = if len2 > 0.0 {
        (ap.iter().zip(&ab).map(|(x, y)| x * y).sum::<f64>() / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (0..3)
        .map(|k| (ap[k] - along * ab[k]).powi(2))
        .sum::<f64>()
        .sqrt()
}

/// Every stretch of ≥ 1 s with a constant desired position: the mean true
/// error over its last 0.5 s.
pub fn steady_states(samples: &[Sample]) -> Vec<SteadyState> {
    let mut steady = Vec::new();
    let mut k = 0;
    while k < samples.len() {
        let mut e = k;
        while e + 1 < samples.len() && samples[e + 1].desired == samples[k].desired {
            e += 1;
        }
        if samples[e].t - samples[k].t >= 1.0 {
            let tail: Vec<f64> = samples[k..=e]
                .iter()
                .filter(|s| s.t >= samples[e].t - 0.5)
                .map(Sample::error_mm)
                .collect();
            if !tail.is_empty() {
                let (settle_s, vibration_mm) = settling(samples, k, e);
                steady.push(SteadyState {
                    t_s: samples[k].t,
                    target_mm: [samples[k].desired[0] * 1e3, samples[k].desired[1] * 1e3],
                    error_mm: tail.iter().sum::<f64>() / tail.len() as f64,
                    samples: tail.len(),
                    settle_s,
                    vibration_mm,
                });
            }
        }
        k = e + 1;
    }
    steady
}

/// A step's tolerance for "settled", mm (`docs/design.md` §6.4).
pub const SETTLED_MM: f64 = 0.1;

/// For the constant stretch `k..=e`: how long after the desired position
/// began to move towards it (a shaped step moves before the stretch; a jump
/// moves at its start) the error came within [`SETTLED_MM`] for good, and
/// the RMS of the error vector's deviation from its mean from then to the
/// stretch's end (mm): the ringing left. `None` for both if it never settled
/// (or the stretch is the first, with nothing before it).
fn settling(samples: &[Sample], k: usize, e: usize) -> (Option<f64>, Option<f64>) {
    if k == 0 {
        return (None, None);
    }
    // Back over the move: samples whose desired position still changed.
    let mut start = k;
    while start >= 2 && samples[start - 1].desired != samples[start - 2].desired {
        start -= 1;
    }
    let last_out = (k..=e).rev().find(|&i| samples[i].error_mm() > SETTLED_MM);
    let settled = match last_out {
        None => k,
        Some(i) if i < e => i + 1,
        Some(_) => return (None, None),
    };
    let after = &samples[settled..=e];
    let n = after.len() as f64;
    let mean: [f64; 3] = std::array::from_fn(|a| {
        after
            .iter()
            .map(|s| s.actual[a] - s.desired[a])
            .sum::<f64>()
            / n
    });
    let var = after
        .iter()
        .map(|s| {
            (0..3)
                .map(|a| (s.actual[a] - s.desired[a] - mean[a]).powi(2))
                .sum::<f64>()
        })
        .sum::<f64>()
        / n;
    (
        Some(samples[settled].t - samples[start].t),
        Some(var.sqrt() * 1e3),
    )
}

/// Bits that mark a setpoint the controller would not use.
pub const REJECTED: u32 = command_status::SETPOINT_REJECTED;
/// Bits that mark the plant injecting a fault on itself.
pub const PLANT_FAULT_BITS: [u32; 3] = [
    plant_status::MOTOR_STUCK,
    plant_status::DROPPING,
    plant_status::DELAYING,
];

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(t: f64, desired: f64, actual: f64, hold: bool) -> Sample {
        Sample {
            t,
            desired: [desired, 0.0, 0.2],
            actual: [actual, 0.0, 0.2],
            hold,
            moving: false,
        }
    }

    /// One RMS per whole period from the start; a last partial period and
    /// holds are left out.
    #[test]
    fn pass_rms_is_one_rms_per_whole_period() {
        // 1 mm off over [1, 3), 2 mm over [3, 5), 5 mm after; a hold at 1.5.
        let s: Vec<Sample> = (0..70)
            .map(|i| {
                let t = 1.0 + i as f64 * 0.1;
                let off = if t < 3.0 {
                    1e-3
                } else if t < 5.0 {
                    2e-3
                } else {
                    5e-3
                };
                sample(t, 0.0, off, (t - 1.5).abs() < 0.01)
            })
            .collect();
        let p = pass_rms(&s, 1.0, 7.9, 2.0);
        assert_eq!(p.len(), 3, "{p:?}");
        for (got, want) in p.iter().zip([1.0, 2.0, 5.0]) {
            assert!((got - want).abs() < 1e-9, "{p:?}");
        }
        assert!(pass_rms(&s, 1.0, 2.5, 2.0).is_empty());
    }

    #[test]
    fn tracking_covers_only_samples_outside_holds_and_says_how_many() {
        let s = [
            sample(0.0, 0.0, 0.5, true),
            sample(1.0, 0.0, 0.003, false),
            sample(2.0, 0.0, 0.004, false),
        ];
        let t = tracking(&s);
        assert_eq!(t.samples, 2);
        assert_eq!(t.window, Some([1.0, 2.0]));
        // errors 3 mm and 4 mm: RMS √((9 + 16) / 2)
        assert!((t.rms.unwrap() - (12.5f64).sqrt()).abs() < 1e-9);
        assert!((t.max.unwrap() - 4.0).abs() < 1e-9);
    }

    /// A 100 Hz setpoint along x at 20 mm/s and a tip `lag_s` behind it,
    /// `offset_m` off the line in y; plant samples at 1 kHz.
    fn lagging_line(lag_s: f64, offset_m: f64) -> Vec<Sample> {
        let v = 0.02;
        (0..2000)
            .map(|i| {
                let t = i as f64 * 1e-3;
                let t_sp = (t / 0.01).floor() * 0.01;
                Sample {
                    t,
                    desired: [v * t_sp, 0.0, 0.2],
                    actual: [v * (t - lag_s).max(0.0), offset_m, 0.2],
                    hold: t < 0.5,
                    moving: false,
                }
            })
            .collect()
    }

    fn row(t_ms: f64, x: f64, generation: usize, flags: u32) -> SetpointRow {
        SetpointRow {
            t_ns: t_ms * 1e6,
            flags,
            position: [x, 0.0, 0.2],
            generation,
            stiffness: f64::NAN,
        }
    }

    /// A planner at 100 Hz along x at 20 mm/s: between two setpoints the
    /// path is where the planner was at that instant, not where it was at
    /// the last send; across a restart, an injection or a silence, the
    /// setpoint in force.
    #[test]
    fn the_path_between_setpoints_is_where_the_planner_was_then() {
        let (a, b) = (row(10.0, 0.0002, 1, 0), row(20.0, 0.0004, 1, 0));
        let at = |next: &SetpointRow, t_ms: f64| path_at(&a, Some(next), t_ms * 1e6)[0];
        assert!((at(&b, 14.0) - 0.00028).abs() < 1e-12, "{}", at(&b, 14.0));
        assert_eq!(at(&b, 10.0), 0.0002);
        assert_eq!(path_at(&a, None, 14e6)[0], 0.0002);
        assert_eq!(at(&row(20.0, 0.0004, 2, 0), 14.0), 0.0002);
        assert_eq!(at(&row(20.0, 0.0004, 1, LOG_INJECTED), 14.0), 0.0002);
        assert_eq!(at(&row(70.0, 0.0004, 1, 0), 14.0), 0.0002);
    }

    #[test]
    fn the_path_error_leaves_out_the_delay_along_the_path() {
        // 20 ms behind at 20 mm/s: the tracking error is ~0.4 mm (less
        // the setpoint's own 0–10 ms age), the path error nothing.
        let s = lagging_line(0.02, 0.0);
        let track = tracking(&s).rms.unwrap();
        assert!((0.25..0.35).contains(&track), "{track}");
        assert!(path_error_rms(&s).unwrap() < 1e-9);
    }

    #[test]
    fn the_path_error_keeps_the_distance_across_the_path() {
        let s = lagging_line(0.02, 0.1e-3);
        let p = path_error_rms(&s).unwrap();
        assert!((p - 0.1).abs() < 1e-9, "{p}");
        // A lone setpoint is a path of one point: a steady state's error.
        let fixed = [sample(0.0, 0.01, 0.012, false)];
        assert!((path_error_rms(&fixed).unwrap() - 2.0).abs() < 1e-9);
    }

    #[test]
    fn a_target_held_longer_than_the_window_is_still_the_path() {
        // Steps: 10 mm, held 1 s, then 20 mm; the tip 1 mm short of the
        // first target all along its dwell, on the second at once.
        let s: Vec<Sample> = (0..2000)
            .map(|i| {
                let t = i as f64 * 1e-3;
                let (d, a) = if t < 1.0 { (0.01, 0.009) } else { (0.02, 0.02) };
                sample(t, d, a, false)
            })
            .collect();
        let p = path_error_rms(&s).unwrap();
        // 1 mm for the first half (not the distance to the next target,
        // nor to the segment toward it), 0 for the second: RMS √½ mm.
        assert!((p - 0.5f64.sqrt()).abs() < 1e-9, "{p}");
    }

    #[test]
    fn a_lagging_tip_on_a_circle_is_only_a_chord_off_its_path() {
        // The 30 mm circle at 0.2 Hz, setpoints at 100 Hz, tip 30 ms
        // behind and on the circle: the path error is at most the sagitta
        // of a 10 ms chord, r(1 − cos(ω·0.01/2)) = 3.0e-4 mm (the first
        // 50 ms, with the tip behind the path's start, are a hold).
        let (r, w) = (0.015, 2.0 * std::f64::consts::PI * 0.2);
        let at = |t: f64| [r * (w * t).cos(), r * (w * t).sin(), 0.2];
        let s: Vec<Sample> = (0..3000)
            .map(|i| {
                let t = i as f64 * 1e-3;
                Sample {
                    t,
                    desired: at((t / 0.01).floor() * 0.01),
                    actual: at(t - 0.03),
                    hold: t < 0.05,
                    moving: false,
                }
            })
            .collect();
        assert!(tracking(&s).rms.unwrap() > 0.4);
        let p = path_error_rms(&s).unwrap();
        assert!((1e-4..3.1e-4).contains(&p), "{p}");
    }

    #[test]
    fn no_samples_give_no_statistics_rather_than_zeros() {
        let t = tracking(&[sample(0.0, 0.0, 0.5, true)]);
        assert_eq!((t.rms, t.max, t.p95, t.samples), (None, None, None, 0));
        assert_eq!(path_error_rms(&[sample(0.0, 0.0, 0.5, true)]), None);
    }

    #[test]
    fn a_one_second_stretch_at_one_target_is_a_steady_state() {
        let s: Vec<Sample> = (0..=150)
            .map(|i| sample(i as f64 * 0.01, 0.01, 0.011, false))
            .collect();
        let st = steady_states(&s);
        assert_eq!(st.len(), 1);
        assert!((st[0].error_mm - 1.0).abs() < 1e-9);
        assert_eq!(st[0].samples, 51);
    }

    /// A move from 0 to 10 mm over 0.2 s, then an error ringing down as
    /// 1 mm e^{−t/0.1 s} cos(2π 5 t) about 0.02 mm: it comes within 0.1 mm
    /// for good when the envelope (plus the offset) does, about
    /// 0.1 s · ln(1 / 0.08) after the move; what rings after is a few µm.
    #[test]
    fn a_step_settles_when_its_ringing_stays_under_the_tolerance() {
        let dt = 0.001;
        let s: Vec<Sample> = (0..3000)
            .map(|i| {
                let t = i as f64 * dt;
                let desired = if t < 1.0 {
                    0.0
                } else if t < 1.2 {
                    0.01 * (t - 1.0) / 0.2
                } else {
                    0.01
                };
                let ring = if t >= 1.2 {
                    1e-3 * (-(t - 1.2) / 0.1).exp()
                        * (std::f64::consts::TAU * 5.0 * (t - 1.2)).cos()
                        + 2e-5
                } else {
                    0.0
                };
                sample(t, desired, desired + ring, false)
            })
            .collect();
        let st = steady_states(&s);
        assert_eq!(st.len(), 2, "{st:?}");
        assert_eq!((st[0].settle_s, st[0].vibration_mm), (None, None));
        let settle = st[1].settle_s.unwrap();
        // The last excursion above 0.1 mm is a peak of the cosine before the
        // envelope 0.02 + e^{-t/0.1} mm falls under it at t ≈ 0.253 s.
        assert!(
            settle > 0.2 + 0.15 && settle < 0.2 + 0.26,
            "settle {settle}"
        );
        let ringing = st[1].vibration_mm.unwrap();
        assert!(ringing > 0.001 && ringing < 0.05, "ringing {ringing}");
        // The same step never settling within 0.1 mm: an offset of 0.2 mm.
        let off: Vec<Sample> = s
            .iter()
            .map(|x| Sample {
                actual: [
                    x.actual[0] + if x.t >= 1.0 { 2e-4 } else { 0.0 },
                    x.actual[1],
                    x.actual[2],
                ],
                ..*x
            })
            .collect();
        assert_eq!(steady_states(&off)[1].settle_s, None);
    }
}

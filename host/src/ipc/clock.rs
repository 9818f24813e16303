//! Monotonic time shared by all processes on the machine, absolute-deadline
//! sleeping, and the periodic-loop bookkeeping (lateness, overruns).
//!
//! Why absolute deadlines: a loop that sleeps "one period" after its work
//! drifts by the work time plus the wake-up latency every cycle (and so do
//! iceoryx2 WaitSet intervals); deadlines `t0 + k·T` do not drift at all.

/// `CLOCK_MONOTONIC` in nanoseconds. One clock for every process on the
/// machine, so a message's stamp can be compared with the receiver's clock.
pub fn now_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: valid pointer to a timespec; CLOCK_MONOTONIC always exists on Linux.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// How long a loop thread has waited for a CPU: runnable, but another
/// task or a throttle had the CPU (`/proc/thread-self/schedstat`, read
/// with one `pread` per period: no allocation, no disk). Time blocked in a
/// system call is not waiting for a CPU, so a loop that stalls on its own
/// I/O cannot hide behind it. Where the kernel keeps no schedstat every
/// reading is `None` and nothing is attributed to the machine.
pub struct CpuWait {
    file: Option<std::fs::File>,
    first_ns: Option<u64>,
    last_ns: Option<u64>,
    /// Periods skipped while the thread was waiting for a CPU at least as
    /// long: the machine's stall, not the loop's.
    pub skipped_waiting: u64,
}

impl CpuWait {
    /// Start counting for the calling thread (open it on the loop's thread).
    pub fn for_this_thread() -> CpuWait {
        let file = std::fs::File::open("/proc/thread-self/schedstat").ok();
        let mut w = CpuWait {
            file,
            first_ns: None,
            last_ns: None,
            skipped_waiting: 0,
        };
        w.first_ns = w.read();
        w.last_ns = w.first_ns;
        w
    }

    /// The thread's total wait so far (ns), if the kernel says.
    pub fn read(&self) -> Option<u64> {
        use std::os::unix::fs::FileExt;
        let mut buf = [0u8; 96];
        let n = self.file.as_ref()?.read_at(&mut buf, 0).ok()?;
        let text = std::str::from_utf8(&buf[..n]).ok()?;
        text.split_whitespace().nth(1)?.parse().ok()
    }

    /// Called once a period, right after waking, with the periods the
    /// ticker skipped to get here.
    pub fn after_wake(&mut self, skipped: u64, period_ns: u64) {
        let now = self.read();
        if let (Some(now), Some(last)) = (now, self.last_ns) {
            self.skipped_waiting += skipped_for_wait(skipped, now.saturating_sub(last), period_ns);
        }
        if now.is_some() {
            self.last_ns = now;
        }
    }

    /// Total wait since [`CpuWait::for_this_thread`] (ns), if the kernel says.
    pub fn total_ns(&self) -> Option<u64> {
        Some(self.last_ns?.saturating_sub(self.first_ns?))
    }
}

/// Of `skipped` periods, those the thread spent waiting for a CPU
/// (`wait_ns` since the last period, whole periods of `period_ns`).
/// Each CPU's *steal* time so far, ms (`/proc/stat`, the eighth field of
/// the `cpuN` lines: time the hypervisor ran something else while this VM
/// wanted the CPU); `None` where the kernel does not say. A VM that loses
/// its CPU for 0.3 s skips 300 periods of a 1 kHz loop whatever the loop
/// does: the sim's verdict excuses those, and says so.
pub fn cpu_steal_ms() -> Option<Vec<u64>> {
    let text = std::fs::read_to_string("/proc/stat").ok()?;
    // USER_HZ is 100 on every Linux ABI this runs on (getconf CLK_TCK).
    const MS_PER_TICK: u64 = 10;
    let steal: Vec<u64> = text
        .lines()
        .filter(|l| l.starts_with("cpu") && l.as_bytes().get(3).is_some_and(u8::is_ascii_digit))
        .map(|l| l.split_whitespace().nth(8)?.parse::<u64>().ok())
        .collect::<Option<_>>()?;
    (!steal.is_empty()).then(|| steal.iter().map(|t| t * MS_PER_TICK).collect())
}

/// Steal between two [`cpu_steal_ms`] readings on `cpu`, ms; with no CPU
/// (the loop was not pinned) the most any CPU lost.
pub fn steal_between(before: &[u64], after: &[u64], cpu: Option<usize>) -> u64 {
    let lost = |k: usize| {
        after
            .get(k)
            .zip(before.get(k))
            .map_or(0, |(a, b)| a.saturating_sub(*b))
    };
    match cpu {
        Some(k) => lost(k),
        None => (0..after.len()).map(lost).max().unwrap_or(0),
    }
}

pub fn skipped_for_wait(skipped: u64, wait_ns: u64, period_ns: u64) -> u64 {
    skipped.min(wait_ns / period_ns.max(1))
}

/// Ask the kernel for 1 ns timer slack instead of the default 50 µs, so
/// `clock_nanosleep` wakes close to the deadline. Harmless if refused.
pub fn tighten_timer_slack() {
    // SAFETY: prctl with PR_SET_TIMERSLACK takes one integer argument.
    unsafe {
        libc::prctl(libc::PR_SET_TIMERSLACK, 1 as libc::c_ulong, 0, 0, 0);
    }
}

/// SCHED_FIFO priority of the planner (it only streams setpoints).
pub const PLANNER_PRIORITY: i32 = 40;
/// SCHED_FIFO priority of the controller.
pub const CONTROLLER_PRIORITY: i32 = 50;
/// SCHED_FIFO priority of the simulated plant: *above* the controller. A
/// task woken by another only preempts it when its priority is higher; on
/// the same CPU the plant then runs at once after the controller's event
/// (measured on the 2-core VM: wake-up p50 4 µs, against 15–30 µs when it
/// waits for the controller to sleep or is woken on the other CPU). The
/// plant stands in for hardware, which also reacts at once.
pub const PLANT_PRIORITY: i32 = 55;
/// SCHED_FIFO priority of the simulated plant on the dynamic rod: *below*
/// the controller, on the same CPU. Its time step costs 0.2–2 ms (release
/// to the tests' dev build, p50–p99), against a 1 ms period: above the
/// controller a long step took the controller's next deadlines (12.6 % of
/// the periods overran in the dev build's `everything` circle), and on the
/// planner's CPU it made the planner's setpoints late (482 watchdog holds
/// in the same run). Below the controller, the controller preempts it at
/// each deadline; the plant runs as soon as the controller sleeps, a few µs
/// after the command, and steps the rod over the time that passed.
pub const DYNAMIC_PLANT_PRIORITY: i32 = 45;

/// The plant's SCHED_FIFO priority for its robot model.
pub fn plant_priority(model: crate::plant::RobotModel) -> i32 {
    match model {
        crate::plant::RobotModel::QuasiStatic => PLANT_PRIORITY,
        crate::plant::RobotModel::Dynamic => DYNAMIC_PLANT_PRIORITY,
    }
}

/// The CPUs this process may run on, in order.
pub fn allowed_cpus() -> Vec<usize> {
    // SAFETY: a zeroed cpu_set_t is a valid empty set; sched_getaffinity
    // fills at most size_of::<cpu_set_t>() bytes of it; CPU_ISSET reads in range.
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        if libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set) != 0 {
            return Vec::new();
        }
        (0..libc::CPU_SETSIZE as usize)
            .filter(|&c| libc::CPU_ISSET(c, &set))
            .collect()
    }
}

/// Pin the calling process to one CPU; returns whether it worked.
pub fn pin_to_cpu(cpu: usize) -> bool {
    set_allowed_cpus(&[cpu])
}

/// Let the calling process run on exactly `cpus`; returns whether it worked.
pub fn set_allowed_cpus(cpus: &[usize]) -> bool {
    if cpus.is_empty() || cpus.iter().any(|&c| c >= libc::CPU_SETSIZE as usize) {
        return false;
    }
    // SAFETY: a zeroed cpu_set_t is a valid empty set; every `cpu` is in
    // range for CPU_SET (checked above).
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        for &c in cpus {
            libc::CPU_SET(c, &mut set);
        }
        libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set) == 0
    }
}

/// Pin to `cpu` if given (warn if refused), then try SCHED_FIFO at
/// `priority` if `realtime` (warn if refused). `who` names the process.
pub fn apply_scheduling(who: &str, cpu: Option<usize>, realtime: bool, priority: i32) {
    if let Some(c) = cpu {
        if !pin_to_cpu(c) {
            log::warn!("{who}: cannot pin to CPU {c}, running unpinned");
        }
    }
    if realtime && !try_realtime(priority) {
        log::warn!("{who}: SCHED_FIFO refused, running with normal priority");
    }
}

/// Try to run this thread under `SCHED_FIFO` at `priority` (needs root or
/// CAP_SYS_NICE); returns whether it worked. Off by default: on a shared
/// 2-core machine a real-time spinner can starve everyone else.
pub fn try_realtime(priority: i32) -> bool {
    let param = libc::sched_param {
        sched_priority: priority,
    };
    // SAFETY: plain syscall on the calling thread (pid 0) with a valid param.
    unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) == 0 }
}

/// Sleep until the monotonic clock reads `deadline_ns`: `clock_nanosleep`
/// (absolute, so a signal or early wake-up cannot stretch it) until
/// `spin_ns` before the deadline, then spin for the rest. `spin_ns = 0` is a
/// pure sleep.
pub fn sleep_until(deadline_ns: u64, spin_ns: u64) {
    let wake = deadline_ns.saturating_sub(spin_ns);
    loop {
        let now = now_ns();
        if now >= wake {
            break;
        }
        let ts = libc::timespec {
            tv_sec: (wake / 1_000_000_000) as libc::time_t,
            tv_nsec: (wake % 1_000_000_000) as libc::c_long,
        };
        // SAFETY: valid timespec; TIMER_ABSTIME with a null remainder pointer.
        let rc = unsafe {
            libc::clock_nanosleep(
                libc::CLOCK_MONOTONIC,
                libc::TIMER_ABSTIME,
                &ts,
                std::ptr::null_mut(),
            )
        };
        if rc != 0 && rc != libc::EINTR {
            break;
        }
    }
    while now_ns() < deadline_ns {
        std::hint::spin_loop();
    }
}

/// Deadlines `start + k·period` of a periodic task, with deterministic
/// overrun handling: a period whose deadline has already passed by a full
/// period when the task gets to it is *skipped* (not run late), and counted.
#[derive(Clone, Debug)]
pub struct Ticker {
    start_ns: u64,
    period_ns: u64,
    /// Index of the next period to run.
    next: u64,
    /// Periods run.
    pub cycles: u64,
    /// Periods whose work finished after the next period's deadline.
    pub overruns: u64,
    /// Periods skipped because the task was a full period or more behind.
    pub skipped: u64,
    /// Times the task fell behind and skipped (one stall may skip many
    /// periods): a loop too slow for its period stalls often and briefly,
    /// a machine that takes the CPU away stalls rarely and long.
    pub stalls: u64,
    /// Most periods skipped in one stall.
    pub longest_stall: u64,
}

/// What [`Ticker::wait`] reports about the period it just started.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Tick {
    /// Period index `k` (deadline `start + k·T`).
    pub index: u64,
    /// This period's deadline (ns, monotonic).
    pub deadline_ns: u64,
    /// Wake-up time minus deadline (ns, ≥ 0).
    pub lateness_ns: u64,
    /// Periods skipped just before this one.
    pub skipped: u64,
}

impl Ticker {
    /// A ticker whose period 0 is due at `start_ns`.
    pub fn new(start_ns: u64, period_ns: u64) -> Ticker {
        Ticker {
            start_ns,
            period_ns: period_ns.max(1),
            next: 0,
            cycles: 0,
            overruns: 0,
            skipped: 0,
            stalls: 0,
            longest_stall: 0,
        }
    }

    /// Period 0's deadline (ns).
    pub fn start_ns(&self) -> u64 {
        self.start_ns
    }

    /// Period length (ns).
    pub fn period_ns(&self) -> u64 {
        self.period_ns
    }

    /// Deadline of period `k`.
    pub fn deadline(&self, k: u64) -> u64 {
        self.start_ns + k * self.period_ns
    }

    /// Decide which period runs next given the current time: the next
    /// unstarted one, unless the clock is already a full period past its
    /// deadline, in which case the periods missed are skipped and the most
    /// recent due one runs. Pure (no clock, no sleep) so it can be tested.
    pub fn plan(&mut self, now_ns: u64) -> (u64, u64) {
        let mut k = self.next;
        let mut skipped = 0;
        let due = self.deadline(k);
        if now_ns >= due + self.period_ns {
            let latest = (now_ns - self.start_ns) / self.period_ns;
            skipped = latest - k;
            k = latest;
        }
        self.skipped += skipped;
        if skipped > 0 {
            self.stalls += 1;
            self.longest_stall = self.longest_stall.max(skipped);
        }
        self.next = k + 1;
        self.cycles += 1;
        (k, skipped)
    }

    /// Record that the work of the period started with [`Ticker::wait`]
    /// finished at `now_ns`; counts an overrun if it crossed the next deadline.
    pub fn finish(&mut self, now_ns: u64) -> bool {
        let overrun = now_ns > self.deadline(self.next);
        if overrun {
            self.overruns += 1;
        }
        overrun
    }

    /// Sleep until the next period's deadline and report on it.
    pub fn wait(&mut self, spin_ns: u64) -> Tick {
        let (k, skipped) = self.plan(now_ns());
        let deadline = self.deadline(k);
        sleep_until(deadline, spin_ns);
        let woke = now_ns();
        Tick {
            index: k,
            deadline_ns: deadline,
            lateness_ns: woke.saturating_sub(deadline),
            skipped,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The quasi-static plant preempts the controller (it reacts at once);
    /// the dynamic rod, asked for directly or by a reality, never does.
    #[test]
    fn the_dynamic_plant_runs_below_the_controller_the_quasi_static_one_above() {
        use crate::plant::{reality::Reality, PlantParams, RobotModel};
        let priority = |model, reality: Option<&str>| {
            let params = PlantParams {
                model,
                reality: reality.map(|r| Reality::builtin(r).unwrap()),
                ..PlantParams::default()
            };
            plant_priority(params.model_in_effect())
        };
        for quasi in [
            priority(RobotModel::QuasiStatic, None),
            priority(RobotModel::QuasiStatic, Some("friction")),
        ] {
            assert!(quasi > CONTROLLER_PRIORITY);
        }
        for dynamic in [
            priority(RobotModel::Dynamic, None),
            priority(RobotModel::QuasiStatic, Some("everything")),
            priority(RobotModel::QuasiStatic, Some("dynamic-light-damping")),
        ] {
            assert!(dynamic < CONTROLLER_PRIORITY && dynamic > PLANNER_PRIORITY);
        }
    }

    #[test]
    fn ticker_runs_consecutive_periods_when_on_time() {
        let mut t = Ticker::new(1_000, 100);
        assert_eq!(t.plan(900), (0, 0));
        assert!(!t.finish(1_050));
        assert_eq!(t.plan(1_060), (1, 0));
        assert_eq!(t.deadline(1), 1_100);
        assert_eq!((t.cycles, t.skipped, t.overruns), (2, 0, 0));
    }

    #[test]
    fn ticker_skips_whole_missed_periods_and_counts_them() {
        let mut t = Ticker::new(0, 100);
        assert_eq!(t.plan(0), (0, 0));
        // Work of period 0 ran until t = 350: periods 1 and 2 are lost,
        // period 3 (deadline 300) runs now.
        assert!(t.finish(350));
        assert_eq!(t.plan(350), (3, 2));
        assert_eq!((t.skipped, t.overruns), (2, 1));
        // Late but within one period: run period 4 late, skip nothing.
        assert!(!t.finish(390));
        assert_eq!(t.plan(450), (4, 0));
        // A second stall, of one period: two stalls, the longest of two.
        assert_eq!(t.plan(650), (6, 1));
        assert_eq!((t.skipped, t.stalls, t.longest_stall), (3, 2, 2));
    }

    #[test]
    fn only_whole_periods_of_waiting_excuse_skipped_ones() {
        assert_eq!(skipped_for_wait(0, 5_000_000, 1_000_000), 0);
        assert_eq!(skipped_for_wait(3, 999_999, 1_000_000), 0);
        assert_eq!(skipped_for_wait(3, 2_500_000, 1_000_000), 2);
        assert_eq!(skipped_for_wait(3, 9_000_000, 1_000_000), 3);
    }

    #[test]
    fn cpu_wait_is_counted_where_the_kernel_keeps_it() {
        if !std::path::Path::new("/proc/thread-self/schedstat").exists() {
            eprintln!("skipped: this kernel keeps no schedstat");
            return;
        }
        let mut wait = CpuWait::for_this_thread();
        // A busy thread on every CPU besides this one: more runnable
        // threads than CPUs for 0.3 s, so this one waits.
        let busy: Vec<_> = (0..allowed_cpus().len())
            .map(|_| {
                std::thread::spawn(|| {
                    let t = now_ns();
                    while now_ns() - t < 300_000_000 {
                        std::hint::spin_loop();
                    }
                })
            })
            .collect();
        let t = now_ns();
        while now_ns() - t < 300_000_000 {
            std::hint::spin_loop();
        }
        for b in busy {
            b.join().unwrap();
        }
        // As if the whole stretch had skipped a million 1 µs periods.
        wait.after_wake(1_000_000, 1_000);
        let total = wait.total_ns().expect("schedstat parses");
        assert!(total > 0, "no wait counted while oversubscribed");
        assert_eq!(wait.skipped_waiting, total / 1_000);
    }

    #[test]
    fn sleep_until_never_wakes_early() {
        tighten_timer_slack();
        for spin in [0, 20_000] {
            let deadline = now_ns() + 2_000_000;
            sleep_until(deadline, spin);
            assert!(now_ns() >= deadline);
        }
    }
}

//! Whether the loop below follows the planner's setpoints, judged from the
//! controller's tension commands as the planner hears them
//! (`docs/design.md` §6.5). A controller in its safe hold, or a chip whose
//! link is cut, leaves the tip where it was while the path moves on — an
//! error no stiffness explains, so the stiffness adaptation must not fit it.

use tendril_shared::messages::command_status;

/// The shortest silence that counts as not following, ns: a few of the
/// chip's 10 ms periods, so a host at 1 kHz or the chip at 100 Hz is caught
/// within 50 ms of stopping.
pub const MIN_SILENCE_NS: u64 = 50_000_000;

/// A controller that commands less often may stay silent this many of its own
/// command intervals before it counts as not following: a controller run at
/// 10 Hz is still following 150 ms after its last command.
pub const SILENT_INTERVALS: u64 = 3;

/// How many recent command intervals the rule remembers; it takes the
/// shortest, so one long silence (a cut link) does not excuse the next.
const REMEMBERED: usize = 8;

/// The rule, fed with each command heard: configured once, no allocation.
#[derive(Clone, Debug, Default)]
pub struct Following {
    /// When the newest command was heard (ns) and its status.
    heard: Option<(u64, u32)>,
    /// The last intervals between commands heard, ns (0: not yet seen).
    intervals_ns: [u64; REMEMBERED],
    next: usize,
}

impl Following {
    /// A command with `status` was heard at `now_ns` (the planner's clock).
    pub fn heard(&mut self, now_ns: u64, status: u32) {
        if let Some((before, _)) = self.heard {
            let interval = now_ns.saturating_sub(before);
            if interval > 0 {
                self.intervals_ns[self.next] = interval;
                self.next = (self.next + 1) % REMEMBERED;
            }
        }
        self.heard = Some((now_ns, status));
    }

    /// The silence after which the loop counts as not following, ns:
    /// [`SILENT_INTERVALS`] of the shortest remembered command interval,
    /// and at least [`MIN_SILENCE_NS`].
    pub fn allowed_silence_ns(&self) -> u64 {
        let shortest = self
            .intervals_ns
            .iter()
            .copied()
            .filter(|&i| i > 0)
            .min()
            .unwrap_or(0);
        (SILENT_INTERVALS * shortest).max(MIN_SILENCE_NS)
    }

    /// At `now_ns`: a command came recently enough and did not say the
    /// controller holds.
    pub fn follows(&self, now_ns: u64) -> bool {
        self.heard.is_some_and(|(heard, status)| {
            now_ns.saturating_sub(heard) <= self.allowed_silence_ns()
                && status & command_status::SAFE_HOLD == 0
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    /// Commands every `every_ms` from 0 to `until_ms`.
    fn heard_every(every_ms: u64, until_ms: u64) -> Following {
        let mut f = Following::default();
        for k in 0..=until_ms / every_ms {
            f.heard(k * every_ms * MS, 0);
        }
        f
    }

    #[test]
    fn a_loop_never_heard_does_not_follow() {
        assert!(!Following::default().follows(0));
        assert!(!Following::default().follows(10 * MS));
    }

    #[test]
    fn a_fast_controller_silent_for_more_than_fifty_ms_does_not_follow() {
        let f = heard_every(1, 1000);
        assert!(f.follows(1000 * MS + 50 * MS));
        assert!(!f.follows(1000 * MS + 51 * MS));
        assert_eq!(f.allowed_silence_ns(), MIN_SILENCE_NS);
    }

    #[test]
    fn a_slow_controller_between_its_commands_still_follows() {
        // 10 Hz: the old fixed 50 ms rule called it silent 60 % of the time.
        let f = heard_every(100, 2000);
        assert!(f.follows(2000 * MS + 150 * MS));
        assert!(f.follows(2000 * MS + 300 * MS));
        assert!(!f.follows(2000 * MS + 301 * MS));
    }

    #[test]
    fn a_long_silence_does_not_excuse_the_next_one() {
        let mut f = heard_every(1, 1000);
        // A cut link for a second, one command, and silence again: the
        // newest interval (1 s) would excuse three seconds of it.
        f.heard(2000 * MS, 0);
        assert!(f.follows(2050 * MS));
        assert!(!f.follows(2051 * MS));
    }

    #[test]
    fn a_controller_in_its_safe_hold_does_not_follow() {
        let mut f = heard_every(1, 100);
        assert!(f.follows(101 * MS));
        f.heard(101 * MS, command_status::SAFE_HOLD);
        assert!(!f.follows(101 * MS));
        f.heard(102 * MS, 0);
        assert!(f.follows(102 * MS));
    }
}

//! One plant step joined with the setpoint in force ([`Sample`]): what the
//! run's analysis ([`super::analysis`]) builds and the oscillation test
//! ([`super::oscillation`]) reads.

/// One plant step joined with the setpoint in force.
#[derive(Clone, Copy, Debug)]
pub struct Sample {
    /// Seconds since the run's start.
    pub t: f64,
    /// Desired tip position (m).
    pub desired: [f64; 3],
    /// True tip position (m).
    pub actual: [f64; 3],
    /// Whether the planner was in a hold (settle, restart) or injecting.
    pub hold: bool,
    /// Whether the setpoint was part of a shaped move between targets
    /// (`MOVING`): a step's transient, like a jump.
    pub moving: bool,
}

impl Sample {
    /// Distance between desired and true tip, mm.
    pub fn error_mm(&self) -> f64 {
        let d: f64 = (0..3)
            .map(|k| (self.desired[k] - self.actual[k]).powi(2))
            .sum();
        d.sqrt() * 1e3
    }
}

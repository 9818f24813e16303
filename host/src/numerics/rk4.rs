//! The one classical fourth-order Runge–Kutta step, for every state the
//! house integrates along the rod: the statics pass (`docs/design.md` §2.1),
//! the statics with their sensitivities (§2), and the dynamics pass.
//!
//! The step is written once, generic over the state and the rates function;
//! it is monomorphised and inlined into each caller, so the plain statics
//! pass costs what the hand-written step did (callgrind, `statics_cost`).
//! The arithmetic is the old steps' exactly, stage by stage, so the results
//! are bit-identical to them.

/// A state RK4 can step: `y + h·k` for rates `k`, and the weighted mean
/// (k₁ + 2 k₂ + 2 k₃ + k₄) / 6 of four rates.
pub trait Rk4State: Sized {
    /// d/ds of the state.
    type Rates;

    /// `self + h · rates` (one stage, or the step itself).
    fn advanced(&self, rates: &Self::Rates, h: f64) -> Self;

    /// RK4's weighted mean (k₁ + (k₂ + k₃)·2 + k₄) / 6 of the four stages'
    /// rates, in that order of operations.
    fn rk4_mean(k: [&Self::Rates; 4]) -> Self::Rates;
}

/// The state and its linearisation stepped together: RK4 of the pair is the
/// pair of RK4s, so the linearisation is the exact derivative of the step.
impl<A: Rk4State, B: Rk4State> Rk4State for (A, B) {
    type Rates = (A::Rates, B::Rates);

    #[inline(always)]
    fn advanced(&self, rates: &Self::Rates, h: f64) -> Self {
        (self.0.advanced(&rates.0, h), self.1.advanced(&rates.1, h))
    }

    #[inline(always)]
    fn rk4_mean(k: [&Self::Rates; 4]) -> Self::Rates {
        (
            A::rk4_mean([&k[0].0, &k[1].0, &k[2].0, &k[3].0]),
            B::rk4_mean([&k[0].1, &k[1].1, &k[2].1, &k[3].1]),
        )
    }
}

/// The rates function RK4 calls: `at(stage, s, y)`. Every closure of the
/// right shape is one. A caller whose rates must be *inlined* into the
/// step implements it on a type of its own with `#[inline(always)]`: the
/// compiler leaves a closure as large as the rod's rates a call per stage
/// (the statics pass: 7 % of its time, `statics::integrate`).
pub trait Rates<Y: Rk4State, E> {
    /// d/ds of the state `y` at `s`, for stage 0..4 of the step.
    fn at(&mut self, stage: usize, s: f64, y: &Y) -> Result<Y::Rates, E>;
}

impl<Y: Rk4State, E, F: FnMut(usize, f64, &Y) -> Result<Y::Rates, E>> Rates<Y, E> for F {
    #[inline(always)]
    fn at(&mut self, stage: usize, s: f64, y: &Y) -> Result<Y::Rates, E> {
        self(stage, s, y)
    }
}

/// One classical RK4 step of size `h` from `s`. `rates(stage, s, y)` is
/// called for the stages 0..4 in order, at s, s + h/2, s + h/2 and s + h
/// (the stage index lets a caller keep per-stage data, as the dynamics'
/// history terms); its first error ends the step.
#[inline(always)]
pub fn rk4_step<Y, E, F>(s: f64, y: &Y, h: f64, rates: F) -> Result<Y, E>
where
    Y: Rk4State,
    F: FnMut(usize, f64, &Y) -> Result<Y::Rates, E>,
{
    rk4_step_with(s, y, h, rates)
}

/// [`rk4_step`] with any [`Rates`], a closure or a type of the caller's.
#[inline(always)]
pub fn rk4_step_with<Y, E, R>(s: f64, y: &Y, h: f64, mut rates: R) -> Result<Y, E>
where
    Y: Rk4State,
    R: Rates<Y, E>,
{
    let k1 = rates.at(0, s, y)?;
    let k2 = rates.at(1, s + 0.5 * h, &y.advanced(&k1, 0.5 * h))?;
    let k3 = rates.at(2, s + 0.5 * h, &y.advanced(&k2, 0.5 * h))?;
    let k4 = rates.at(3, s + h, &y.advanced(&k3, h))?;
    Ok(y.advanced(&Y::rk4_mean([&k1, &k2, &k3, &k4]), h))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A scalar state for the closed-form checks.
    #[derive(Clone, Copy, Debug, PartialEq)]
    struct Scalar(f64);

    impl Rk4State for Scalar {
        type Rates = f64;
        fn advanced(&self, rates: &f64, h: f64) -> Scalar {
            Scalar(self.0 + rates * h)
        }
        fn rk4_mean(k: [&f64; 4]) -> f64 {
            (k[0] + (k[1] + k[2]) * 2.0 + k[3]) / 6.0
        }
    }

    #[test]
    fn integrates_a_cubic_exactly() {
        // y' = 3 s² from y(0) = 0: RK4 is exact for polynomials of degree ≤ 3.
        let mut y = Scalar(0.0);
        for k in 0..4 {
            let s = k as f64 * 0.25;
            y = rk4_step(s, &y, 0.25, |_, s, _| Ok::<_, ()>(3.0 * s * s)).unwrap();
        }
        assert!((y.0 - 1.0).abs() < 1e-15);
    }

    #[test]
    fn exponential_error_falls_at_fourth_order() {
        let error = |n: usize| {
            let h = 1.0 / n as f64;
            let mut y = Scalar(1.0);
            for k in 0..n {
                y = rk4_step(k as f64 * h, &y, h, |_, _, y| Ok::<_, ()>(y.0)).unwrap();
            }
            (y.0 - 1f64.exp()).abs()
        };
        let ratio = error(8) / error(16);
        assert!((14.0..18.0).contains(&ratio), "ratio {ratio}");
    }

    #[test]
    fn stages_come_in_order_and_an_error_stops_the_step() {
        let mut seen = Vec::new();
        let out = rk4_step(1.0, &Scalar(0.0), 0.5, |stage, s, _| {
            seen.push((stage, s));
            if stage == 2 {
                Err("stop")
            } else {
                Ok(0.0)
            }
        });
        assert_eq!(out, Err("stop"));
        assert_eq!(seen, [(0, 1.0), (1, 1.25), (2, 1.25)]);
    }
}

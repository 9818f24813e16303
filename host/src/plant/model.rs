//! The plant model: one first-order motor per tendon with saturation, dead
//! band and backlash, optional series tendon compliance, the robot's tip
//! from warm-started Cosserat statics or from the dynamic rod
//! (docs/design.md §4.2), the tip tracker, and the injectable motor and
//! message faults (docs/design.md §6). With a [`Reality`] the robot it moves
//! is not the robot file's (docs/design.md §6.2).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::params::{PlantParams, RobotModel, StuckFault};
use super::reality::{Frame, Tracker, TrackerSpec};
use super::PlantError;
use crate::dynamics::{Dynamics, DynamicsSettings};
use crate::robot::Robot;
use crate::statics::pose::{orthonormalise, quaternion_wxyz};
use crate::statics::{Friction, FrictionState, SolverSettings, Statics, WarmStart};

/// Most dynamic time steps one plant step takes: after a stall longer than
/// this many steps, the rest of the elapsed time is skipped, not simulated.
const MAX_SUBSTEPS: usize = 100;

/// Plant steps between refreshes of the dynamic rod's friction profile.
const PROFILE_REFRESH_STEPS: u32 = 20;

/// The plant's physics, free of any IPC (testable, benchmarkable).
pub struct PlantModel {
    statics: Statics,
    params: PlantParams,
    max_tension: Vec<f64>,
    /// Each tendon's floor: the drive keeps its pretension whatever it is
    /// commanded (`min_tension` of the plant's robot, which may differ from
    /// the controller's model: `--plant-robot`).
    min_tension: Vec<f64>,
    /// Motor output tension (N).
    motor: Vec<f64>,
    /// Tension in the tendon at the tip (N); equals `motor` for rigid tendons.
    tendon: Vec<f64>,
    target: Vec<f64>,
    warm: Option<WarmStart>,
    /// The last converged quasi-static solution (the shape a run log draws).
    solution: Option<crate::statics::Solution>,
    solved_for: Vec<f64>,
    pose: [f64; 7],
    rng: ChaCha8Rng,
    stuck: bool,
    /// The dynamic robot, when the model is [`RobotModel::Dynamic`].
    dynamics: Option<Box<Dynamics>>,
    /// Elapsed time not yet simulated by the dynamic robot, s.
    lag_s: f64,
    /// The tip tracker.
    tracker: Tracker,
    /// Base frame → the tracker's (the real robot's `[base]`): every tip
    /// and shape the plant reports is in the tracker's frame.
    to_tracker: crate::robot::RigidMap,
    /// Per motor: the play operator's output (backlash) and the tension the
    /// drive holds (dead band), N.
    drive: Vec<(f64, f64)>,
    dead_band_n: f64,
    backlash_n: f64,
    /// Tendon friction (docs/design.md §2.3): the sliding directions and
    /// the tension profiles, one fixed-point pass per plant step.
    friction: Option<FrictionState>,
    /// Dynamic plant with friction: steps until its profile is refreshed.
    profile_countdown: u32,
    /// Statics (or dynamics) failures (the last good pose was kept).
    pub solve_failures: u64,
}

impl PlantModel {
    /// A plant at rest with all tensions zero, moving the robot `robot`
    /// changed by `params.reality` if there is one.
    pub fn new(robot: &Robot, mut params: PlantParams) -> Result<PlantModel, PlantError> {
        let reality = params.reality.clone().unwrap_or_default();
        let real = reality
            .real_robot(robot)
            .map_err(|e| PlantError::Config(format!("plant: reality {}: {e}", reality.name)))?;
        let robot = &real;
        if let Some(tau) = reality.motors.and_then(|m| m.time_constant_ms) {
            params.motor_tau_s = tau * 1e-3;
        }
        let damping = reality.damping(robot);
        params.model = params.model_in_effect();
        let tracker = reality.tracker.unwrap_or(TrackerSpec {
            position_jitter_mm: params.noise_m * 1e3,
            // A rotation by a small angle a moves the quaternion's vector
            // part by a/2: the ideal sensor's per-component noise doubled.
            orientation_jitter_deg: (2.0 * params.noise_quat).to_degrees(),
            ..TrackerSpec::IDEAL
        });
        tracker
            .validate()
            .map_err(|(f, p)| PlantError::Config(format!("plant: tracker {f}: {p}")))?;
        if !(params.motor_tau_s > 0.0 && params.compliance_tau_s >= 0.0 && params.noise_m >= 0.0) {
            return Err(PlantError::Config(
                "plant: motor time constant must be > 0, compliance and noise ≥ 0".into(),
            ));
        }
        if !(params.statics_tol > 0.0
            && params.statics_tol.is_finite()
            && params.statics_final_step_m >= 0.0
            && params.statics_final_step_m.is_finite())
        {
            return Err(PlantError::Config(format!(
                "plant: statics tolerance {} must be > 0 and the final step bound {} m ≥ 0",
                params.statics_tol, params.statics_final_step_m
            )));
        }
        if let Some(StuckFault { tendon: k, .. }) = params.faults.stuck {
            if k >= robot.n_tendons() {
                return Err(PlantError::Config(format!(
                    "plant: stuck motor {k} but the robot has {} tendons",
                    robot.n_tendons()
                )));
            }
        }
        let settings = SolverSettings {
            steps: params.statics_steps.max(4),
            tol: params.statics_tol,
            final_step_m: params.statics_final_step_m,
            ..SolverSettings::default()
        };
        let statics = Statics::new(robot, settings);
        let n = robot.n_tendons();
        let zero = vec![0.0; n];
        let sol = statics
            .solve(&zero, None)
            .map_err(|e| PlantError::Solve(format!("plant: statics at rest: {e}")))?;
        let dynamics = match params.model {
            RobotModel::QuasiStatic => None,
            RobotModel::Dynamic => Some(Box::new(
                Dynamics::at_rest(
                    robot,
                    damping,
                    DynamicsSettings {
                        dt_s: params.dynamics_dt_s,
                        steps: settings.steps,
                        ..DynamicsSettings::default()
                    },
                    &zero,
                    nalgebra::Vector3::zeros(),
                    nalgebra::Vector3::zeros(),
                )
                .map_err(|e| PlantError::Config(format!("plant: dynamic robot: {e}")))?,
            )),
        };
        Ok(PlantModel {
            max_tension: robot.max_tensions(),
            min_tension: robot.min_tensions(),
            motor: zero.clone(),
            tendon: zero.clone(),
            target: zero.clone(),
            warm: Some(sol.warm.clone()),
            solution: Some(sol.clone()),
            solved_for: zero,
            pose: sol.pose(),
            rng: ChaCha8Rng::seed_from_u64(params.seed),
            stuck: false,
            dynamics,
            lag_s: 0.0,
            tracker: Tracker::new(tracker),
            to_tracker: robot.base.to_tracker(),
            drive: vec![(0.0, 0.0); n],
            dead_band_n: reality.motors.map_or(0.0, |m| m.dead_band_n),
            backlash_n: reality.motors.map_or(0.0, |m| m.backlash_n),
            friction: reality.friction.map(|f| {
                let mut state = FrictionState::new(
                    Friction {
                        mu: f.mu,
                        reversal_n: f.reversal_n,
                    },
                    n,
                );
                // Stepping at 1 kHz the last profile is nearly right: one
                // pass per step, the profile one step behind (≈ 1 µm per mN).
                state.set_max_passes(1);
                state
            }),
            profile_countdown: 0,
            solve_failures: 0,
            statics,
            params,
        })
    }

    /// Number of tendons.
    pub fn n(&self) -> usize {
        self.motor.len()
    }

    /// Set the commanded tensions, saturated to each motor's range; returns
    /// whether the command was out of range (or not finite) before saturation.
    pub fn command(&mut self, tensions: &[f64]) -> bool {
        let mut bad = tensions.len() != self.n();
        for (i, target) in self.target.iter_mut().enumerate() {
            let t = tensions.get(i).copied().unwrap_or(f64::NAN);
            if !t.is_finite() {
                bad = true;
                continue; // keep the previous target for this motor
            }
            if t < 0.0 || t > self.max_tension[i] {
                bad = true;
            }
            *target = drive(
                &mut self.drive[i],
                t.clamp(0.0, self.max_tension[i]).max(self.min_tension[i]),
                self.backlash_n,
                self.dead_band_n,
            );
        }
        bad
    }

    /// Freeze motor `k` where it is (fault injection).
    pub fn set_stuck(&mut self) {
        self.stuck = true;
    }

    /// Advance by `dt` seconds: motors, tendons, statics. Returns whether the
    /// statics converged (otherwise the previous pose is kept).
    pub fn step(&mut self, dt: f64) -> bool {
        let dt = dt.clamp(0.0, 0.1);
        let a_m = 1.0 - (-dt / self.params.motor_tau_s).exp();
        let stuck = if self.stuck {
            self.params.faults.stuck.map(|s| s.tendon)
        } else {
            None
        };
        for i in 0..self.n() {
            if stuck != Some(i) {
                self.motor[i] += (self.target[i] - self.motor[i]) * a_m;
            }
            self.tendon[i] = if self.params.compliance_tau_s > 0.0 {
                let a_c = 1.0 - (-dt / self.params.compliance_tau_s).exp();
                self.tendon[i] + (self.motor[i] - self.tendon[i]) * a_c
            } else {
                self.motor[i]
            };
        }
        if let Some(friction) = self.friction.as_mut() {
            friction.update_direction(&self.tendon);
        }
        if self.dynamics.is_some() {
            self.refresh_dynamic_friction();
            return self.step_dynamics(dt);
        }
        let moved = self
            .tendon
            .iter()
            .zip(&self.solved_for)
            .any(|(a, b)| (a - b).abs() > 1e-9);
        if !moved {
            return true;
        }
        let sol = match self.friction.as_mut() {
            Some(f) => f
                .solve(&self.statics, &self.tendon, self.warm.as_ref())
                .or_else(|_| f.solve(&self.statics, &self.tendon, None)),
            None => self
                .statics
                .solve(&self.tendon, self.warm.as_ref())
                .or_else(|_| self.statics.solve(&self.tendon, None)),
        };
        match sol {
            Ok(mut sol) => {
                // The plant's solves form a chain of nearby tensions: pay
                // dx/dτ once (after the first solve, or a cold fallback), and
                // every warm solve after it starts from the prediction and
                // hands dx/dτ on (docs/design.md §2, "Solve").
                if self.friction.is_none() && sol.warm.tension_sensitivity().is_none() {
                    self.statics.add_tension_sensitivity(&mut sol);
                }
                self.pose = sol.pose();
                self.warm = Some(sol.warm.clone());
                self.solution = Some(sol);
                self.solved_for.clone_from(&self.tendon);
                true
            }
            Err(_) => {
                self.solve_failures += 1;
                false
            }
        }
    }

    /// With friction on the dynamic rod: every [`PROFILE_REFRESH_STEPS`]
    /// plant steps, the tension profile of a friction statics solve at the
    /// tendons' tensions (the profile follows the tensions and the sliding
    /// directions, not each swing of the rod).
    fn refresh_dynamic_friction(&mut self) {
        let (Some(friction), Some(dynamics)) = (self.friction.as_mut(), self.dynamics.as_mut())
        else {
            return;
        };
        if self.profile_countdown > 0 {
            self.profile_countdown -= 1;
            return;
        }
        self.profile_countdown = PROFILE_REFRESH_STEPS;
        match friction.solve(&self.statics, &self.tendon, self.warm.as_ref()) {
            Ok(sol) => {
                dynamics.set_friction_profile(sol.profile().cloned());
                self.warm = Some(sol.warm);
            }
            Err(e) => log::debug!("plant: friction profile: {e}"),
        }
    }

    /// The dynamic robot over `dt` s: whole time steps while at least half
    /// of one is due, the tendon tensions held over them.
    fn step_dynamics(&mut self, dt: f64) -> bool {
        let Some(dynamics) = self.dynamics.as_mut() else {
            return false;
        };
        let dt_s = dynamics.settings().dt_s;
        self.lag_s += dt;
        let mut substeps = 0;
        while self.lag_s >= 0.5 * dt_s {
            if substeps == MAX_SUBSTEPS {
                self.lag_s = 0.0;
                break;
            }
            self.lag_s -= dt_s;
            substeps += 1;
            match dynamics.step(&self.tendon) {
                Ok(tip) => {
                    let q = quaternion_wxyz(&orthonormalise(&tip.rotation));
                    let p = tip.position;
                    self.pose = [p.x, p.y, p.z, q[0], q[1], q[2], q[3]];
                }
                Err(e) => {
                    log::debug!("plant: dynamic step failed: {e}");
                    self.solve_failures += 1;
                    self.lag_s = 0.0;
                    return false;
                }
            }
        }
        true
    }

    /// The rod's backbone and tendon paths at `points` arc lengths (the
    /// tracker's frame, m), for a run log. The quasi-static plant has them
    /// from its last solve; the dynamic rod gives its backbone on its own
    /// grid, resampled here, and no tendon paths.
    pub fn shape(&self, points: usize) -> Option<crate::statics::RodShape> {
        let mut shape = match &self.dynamics {
            Some(d) => crate::statics::RodShape {
                backbone: crate::numerics::polyline::resample(d.backbone(), points),
                tendons: vec![],
            },
            None => self
                .statics
                .shape_with_tendons(self.solution.as_ref()?, points),
        };
        if !self.to_tracker.is_identity() {
            let map =
                |p: &mut nalgebra::Vector3<f64>| *p = self.to_tracker.point((*p).into()).into();
            shape.backbone.iter_mut().for_each(map);
            shape.tendons.iter_mut().flatten().for_each(map);
        }
        Some(shape)
    }

    /// The robot's base pose in the tracker's frame (its `[base]`).
    pub fn base_pose(&self) -> [f64; 7] {
        self.to_tracker.pose([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0])
    }

    /// True tip pose (no noise), in the tracker's frame.
    pub fn pose(&self) -> [f64; 7] {
        self.to_tracker.pose(self.pose)
    }

    /// True tip pose in the robot's own base frame (what `/tf` calls
    /// `base_link` → `tip`).
    pub fn pose_in_base(&self) -> [f64; 7] {
        self.pose
    }

    /// Tendon tensions (N).
    pub fn tensions(&self) -> &[f64] {
        &self.tendon
    }

    /// Commanded (saturated) tensions (N).
    pub fn targets(&self) -> &[f64] {
        &self.target
    }

    /// The tracker at plant time `now_ns` (after [`PlantModel::step`]):
    /// it samples the true tip when a frame is due and delivers the frames
    /// whose latency has passed. Returns whether a new frame arrived.
    pub fn sense(&mut self, now_ns: u64) -> bool {
        self.tracker.step(now_ns, &self.pose(), &mut self.rng)
    }

    /// The tracker's newest delivered frame (None before the first).
    pub fn frame(&self) -> Option<&Frame> {
        self.tracker.latest()
    }

    /// The tracker (its counts of frames taken, delivered and lost).
    pub fn tracker(&self) -> &Tracker {
        &self.tracker
    }

    /// A uniform draw in [0, 1) from the plant's generator (drop decisions).
    pub fn uniform(&mut self) -> f64 {
        self.rng.random::<f64>()
    }
}

/// What a drive does with the command `cmd` (N): backlash first — the play
/// operator, whose output `state.0` moves only once the command has pushed
/// it `backlash / 2` either way — then the dead band: the tension held
/// (`state.1`) follows only when the play's output is more than `dead_band`
/// away from it. Returns the tension the motor now tracks.
fn drive(state: &mut (f64, f64), cmd: f64, backlash: f64, dead_band: f64) -> f64 {
    let half = 0.5 * backlash;
    state.0 = state.0.clamp(cmd - half, cmd + half);
    if (state.0 - state.1).abs() > dead_band {
        state.1 = state.0;
    }
    state.1
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plant::reality::Reality;
    use crate::plant::PlantFaults;
    use std::path::Path;

    fn robot() -> Robot {
        Robot::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../robots/seed-4t.toml")).unwrap()
    }

    #[test]
    fn the_drive_keeps_the_plant_robots_floors_whatever_is_commanded() {
        let text = std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../robots/seed-paper.toml"),
        )
        .unwrap();
        let paper = Robot::from_toml(&text, Path::new("seed-paper.toml")).unwrap();
        let params = PlantParams {
            noise_m: 0.0,
            noise_quat: 0.0,
            ..PlantParams::default()
        };
        let mut m = PlantModel::new(&paper, params).unwrap();
        // A controller whose model has no floor commands 0 N: the drive
        // holds the 5 N pretension, and that is no out-of-range command.
        assert!(!m.command(&[7.0, 0.0, 0.0, 0.0]));
        for _ in 0..500 {
            m.step(0.001);
        }
        for (k, t) in m.tensions().iter().enumerate() {
            assert!(
                *t >= paper.tendons[k].min_tension - 1e-6,
                "tendon {k}: {t} N"
            );
        }
    }

    #[test]
    fn motor_follows_first_order_step_response() {
        let params = PlantParams {
            noise_m: 0.0,
            noise_quat: 0.0,
            ..PlantParams::default()
        };
        let mut m = PlantModel::new(&robot(), params).unwrap();
        assert!(!m.command(&[2.0, 0.0, 0.0, 0.0]));
        // One time constant in 20 steps of 1 ms: 1 − e^−1 of the step.
        for _ in 0..20 {
            assert!(m.step(0.001));
        }
        let expect = 2.0 * (1.0 - (-1.0f64).exp());
        assert!((m.tensions()[0] - expect).abs() < 1e-9);
        // And the pose is the statics of exactly those tensions.
        let s = Statics::new(&robot(), SolverSettings::default());
        let sol = s.solve(m.tensions(), None).unwrap();
        assert!((sol.position - nalgebra::Vector3::from_row_slice(&m.pose()[..3])).norm() < 1e-6);
    }

    /// The plant's warm starts carry dx/dτ after its first solve and, by
    /// default, end on one unverified chord step: along a moving command
    /// (the motors turning the bend vector as a circle does, and a step in
    /// it), every pose stays within the stated 0.1 µm of a verified cold
    /// solve of its tensions, and most steps take the one pass.
    #[test]
    fn a_chain_of_plant_steps_takes_one_pass_and_keeps_the_statics_answer_to_a_tenth_of_a_micron() {
        let params = PlantParams {
            noise_m: 0.0,
            noise_quat: 0.0,
            ..PlantParams::default()
        };
        let mut m = PlantModel::new(&robot(), params).unwrap();
        let s = Statics::new(&robot(), SolverSettings::default());
        let (mut worst, mut one_pass, steps) = (0.0f64, 0, 600);
        for k in 0..steps {
            let a = std::f64::consts::TAU * 0.5 * k as f64 * 1e-3;
            let jump = if k >= 300 { 1.0 } else { 0.0 };
            m.command(&[3.0 + a.cos() + jump, 1.0 + a.sin(), 0.5, 0.0]);
            assert!(m.step(0.001), "step {k}");
            let warm = m.warm.as_ref().unwrap();
            assert!(warm.tension_sensitivity().is_some(), "step {k}");
            one_pass += usize::from(m.solution.as_ref().is_some_and(|s| s.extrapolated));
            let sol = s.solve(m.tensions(), None).unwrap();
            let err = (sol.position - nalgebra::Vector3::from_row_slice(&m.pose()[..3])).norm();
            worst = worst.max(err);
        }
        assert!(worst < 1e-7, "{worst:e} m from a verified cold solve");
        assert!(
            2 * one_pass > steps,
            "only {one_pass} of {steps} steps took one pass"
        );
    }

    #[test]
    fn dynamic_plant_swings_and_comes_to_the_quasi_static_pose() {
        // The dynamic robot lags the motors and rings about the pose the
        // quasi-static plant jumps to, decaying towards it (docs/design.md
        // §4.2; that a damped run comes to rest exactly there is checked in
        // `dynamics::tests`).
        let plant = |model| {
            let params = PlantParams {
                noise_m: 0.0,
                noise_quat: 0.0,
                model,
                ..PlantParams::default()
            };
            PlantModel::new(&robot(), params).unwrap()
        };
        let mut quasi = plant(RobotModel::QuasiStatic);
        let mut dynamic = plant(RobotModel::Dynamic);
        let mut largest_gap: f64 = 0.0;
        for k in 0..3000 {
            // The motors get a 2 N step, held.
            let cmd = [2.0, 0.0, 0.0, 0.0];
            quasi.command(&cmd);
            dynamic.command(&cmd);
            assert!(quasi.step(1e-3) && dynamic.step(1e-3), "step {k} failed");
            largest_gap = largest_gap.max((quasi.pose()[0] - dynamic.pose()[0]).abs());
        }
        let gap = (0..3)
            .map(|i| (quasi.pose()[i] - dynamic.pose()[i]).abs())
            .fold(0.0, f64::max);
        assert!(
            largest_gap > 1e-3,
            "the dynamic robot never lagged: {largest_gap}"
        );
        assert!(
            gap < 0.2 * largest_gap,
            "after 3 s still {gap:.2e} m from the quasi-static pose (largest {largest_gap:.2e} m)"
        );
    }

    #[test]
    fn both_plants_shape_ends_at_their_tip_and_starts_at_the_base() {
        // What a run log draws (docs/design.md §12): the backbone's last
        // point is the tip the plant reports, for the quasi-static rod
        // (integrated from its solve) and the swinging dynamic one (its own
        // grid, resampled).
        for model in [RobotModel::QuasiStatic, RobotModel::Dynamic] {
            let params = PlantParams {
                noise_m: 0.0,
                model,
                ..PlantParams::default()
            };
            let mut m = PlantModel::new(&robot(), params).unwrap();
            for _ in 0..40 {
                m.command(&[3.0, 0.0, 1.0, 0.0]);
                assert!(m.step(1e-3));
            }
            let shape = m.shape(21).expect("a shape");
            assert_eq!(shape.backbone.len(), 21, "{model:?}");
            assert!(shape.backbone[0].norm() < 1e-12, "{model:?}");
            let p = m.pose();
            let tip = nalgebra::Vector3::new(p[0], p[1], p[2]);
            let d = (shape.backbone[20] - tip).norm();
            assert!(d < 1e-6, "{model:?}: backbone ends {d:.2e} m from the tip");
            // Evenly spaced along a rod of length L: 20 chords, each ≈ L/20.
            let chords: Vec<f64> = shape
                .backbone
                .windows(2)
                .map(|w| (w[1] - w[0]).norm())
                .collect();
            let (lo, hi) = chords
                .iter()
                .fold((f64::MAX, 0.0f64), |(a, b), &c| (a.min(c), b.max(c)));
            assert!(hi < 1.05 * lo, "{model:?}: chords {lo:.2e}..{hi:.2e} m");
            let tendons = if model == RobotModel::QuasiStatic {
                4
            } else {
                0
            };
            assert_eq!(shape.tendons.len(), tendons, "{model:?}");
        }
    }

    #[test]
    fn resampling_keeps_the_ends_and_spaces_by_length() {
        let v = |x: f64| nalgebra::Vector3::new(x, 0.0, 0.0);
        let line = [v(0.0), v(0.1), v(0.4), v(1.0)];
        let r = crate::numerics::polyline::resample(&line, 5);
        let xs: Vec<f64> = r.iter().map(|p| p.x).collect();
        for (got, want) in xs.iter().zip([0.0, 0.25, 0.5, 0.75, 1.0]) {
            assert!((got - want).abs() < 1e-12, "{xs:?}");
        }
        assert_eq!(
            crate::numerics::polyline::resample(&[v(2.0)], 3),
            vec![v(2.0); 3]
        );
        assert!(crate::numerics::polyline::resample(&[], 3).is_empty());
    }

    #[test]
    fn out_of_range_commands_are_flagged_and_saturated() {
        let mut m = PlantModel::new(&robot(), PlantParams::default()).unwrap();
        assert!(m.command(&[12.0, -1.0, f64::NAN, 1.0]));
        assert_eq!(m.targets(), &[10.0, 0.0, 0.0, 1.0]);
        assert!(m.command(&[1.0, 1.0]));
    }

    #[test]
    fn stuck_motor_keeps_its_tension() {
        let params = PlantParams {
            faults: PlantFaults {
                stuck: Some(StuckFault {
                    tendon: 1,
                    at_s: 0.0,
                }),
                ..PlantFaults::default()
            },
            ..PlantParams::default()
        };
        let mut m = PlantModel::new(&robot(), params).unwrap();
        m.command(&[1.0, 1.0, 0.0, 0.0]);
        m.step(0.01);
        let held = m.tensions()[1];
        m.set_stuck();
        m.command(&[1.0, 3.0, 0.0, 0.0]);
        for _ in 0..50 {
            m.step(0.01);
        }
        assert_eq!(m.tensions()[1], held);
        assert!((m.tensions()[0] - 1.0).abs() < 1e-6);
    }

    #[test]
    fn sensor_noise_has_the_configured_spread() {
        let params = PlantParams {
            noise_m: 1e-4,
            ..PlantParams::default()
        };
        let mut m = PlantModel::new(&robot(), params).unwrap();
        let truth = m.pose();
        let k = 4000;
        let mut sum2 = 0.0;
        for step in 0..k {
            // The ideal tracker: a frame every millisecond, on time.
            assert!(m.sense(step * 1_000_000));
            let d = m.frame().unwrap().pose[0] - truth[0];
            sum2 += d * d;
        }
        let sd = (sum2 / k as f64).sqrt();
        assert!((sd - 1e-4).abs() < 0.1e-4, "sd = {sd}");
    }

    #[test]
    fn a_plant_with_friction_reaches_less_far_pulling_than_releasing() {
        // The same 3 N on tendon 0, once pulled up from 0 N and once let
        // down from 6 N: friction in the guides keeps tension from the tip
        // while pulling and holds it there while releasing (hysteresis).
        let reality: Reality = toml::from_str("name = \"f\"\n[friction]\nmu = 0.2\n").unwrap();
        let plant = || {
            let params = PlantParams {
                noise_m: 0.0,
                noise_quat: 0.0,
                reality: Some(reality.clone()),
                ..PlantParams::default()
            };
            PlantModel::new(&robot(), params).unwrap()
        };
        let settle = |m: &mut PlantModel, t: f64| {
            m.command(&[t, 0.0, 0.0, 0.0]);
            for _ in 0..300 {
                assert!(m.step(1e-3));
            }
        };
        let mut up = plant();
        settle(&mut up, 3.0);
        let mut down = plant();
        settle(&mut down, 6.0);
        settle(&mut down, 3.0);
        let mut none = PlantModel::new(
            &robot(),
            PlantParams {
                noise_m: 0.0,
                noise_quat: 0.0,
                ..PlantParams::default()
            },
        )
        .unwrap();
        settle(&mut none, 3.0);
        // How far tendon 0 moved the tip along x from the rest pose.
        let rest = plant().pose()[0];
        let reach = |m: &PlantModel| (m.pose()[0] - rest).abs();
        assert!(
            reach(&up) < reach(&none) && reach(&none) < reach(&down),
            "pulling {:.3} mm, frictionless {:.3} mm, releasing {:.3} mm",
            reach(&up) * 1e3,
            reach(&none) * 1e3,
            reach(&down) * 1e3
        );
    }
}

//! The loop on the model, in process and in virtual time: the planner's
//! motion and setpoints, the host controller (the firmware's period) and
//! the plant model of the robot file, lock-step at the controller's rate.
//! No clock, no IPC: a run is a function of its inputs, so two runs that
//! differ only in the offset differ only by what the offset did (the
//! tracker's noise repeats with its seed).

use tendril_shared::messages::{Header, TensionCommand};

use crate::ipc::clock::Tick;
use crate::ipc::controller::{Controller, ControllerConfig, Inbox};
use crate::ipc::planner::setpoint_for;
use crate::ipc::plant::state_message;
use crate::ipc::IpcError;
use crate::plan::{Motion, TurningOffset};
use crate::plant::{PlantModel, PlantParams};
use crate::robot::Robot;

/// Complex harmonic coefficient.
pub type Complex = nalgebra::Complex<f64>;

/// What one run measures: each pass's error (the planner's pose less the
/// true tip) in the turning frame, as harmonics `[axis][m]` of the pass
/// (u = Re Σ U_m e^{j2πmφ}), and each pass's RMS (m, x y z).
#[derive(Clone, Debug)]
pub struct PassErrors {
    /// Per pass, per axis (radial, tangential, height), harmonics 0..n.
    pub harmonics: Vec<[Vec<Complex>; 3]>,
    /// Per pass, RMS of the error's length, m.
    pub rms_m: Vec<f64>,
    /// The error over the path's first seconds, turning frame: the mean of
    /// each of the window's bins (m).
    pub start: Vec<[f64; 3]>,
    /// RMS of the error's length over that window, m.
    pub start_rms_m: f64,
}

/// The first seconds of the path a run measures bin by bin (real time
/// from the path's start): `bins` bins of `bin_s` (none: `bins` 0).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StartWindow {
    /// Width of a bin, s.
    pub bin_s: f64,
    /// Bins.
    pub bins: usize,
}

impl StartWindow {
    /// Its length, s.
    pub fn length_s(&self) -> f64 {
        self.bin_s * self.bins as f64
    }
}

/// The loop's parts, set up once and run many times.
pub struct VirtualLoop<'a> {
    /// The robot file.
    pub robot: &'a Robot,
    /// The controller's net (`.tnet` bytes).
    pub net: &'a [u8],
    /// The controller's configuration (its rate is the loop's).
    pub controller: &'a ControllerConfig,
    /// The plant model's parameters (no reality: the model).
    pub plant: &'a PlantParams,
    /// The planner's motion (its own offsets included).
    pub motion: &'a Motion,
    /// The path's period, s, and the settle before it.
    pub period_s: f64,
    /// The settle hold, s.
    pub settle_s: f64,
}

impl VirtualLoop<'_> {
    /// Run the settle and `passes` periods of the path (at least the
    /// `window`) with `offset` (in the turning frame of `offset`'s circle)
    /// on top of the motion's own; measure `harmonics` harmonics of each
    /// pass and the window's bins.
    pub fn run(
        &self,
        offset: &TurningOffset,
        passes: usize,
        harmonics: usize,
        window: StartWindow,
    ) -> Result<PassErrors, IpcError> {
        let period_ns = (1e9 / self.controller.rate_hz).round() as u64;
        let dt = period_ns as f64 * 1e-9;
        let substeps = (dt / crate::ipc::plant::IDLE_PERIOD_S).round().max(1.0) as usize;
        let start_ns: u64 = 1_000_000_000;
        let mut controller = Controller::new(self.controller, self.robot, self.net, start_ns)?;
        let mut plant = PlantModel::new(self.robot, self.plant.clone())
            .map_err(|e| IpcError::Other(format!("the model's plant: {e}")))?;
        let to_tracker = self.robot.base.to_tracker();
        let motion = self.motion.clone().with_turning_offset(offset.clone());
        let n = self.robot.n_tendons();
        let path_s = (self.period_s * passes as f64).max(window.length_s());
        let steps = ((self.settle_s + path_s) / dt).ceil() as u64 + 1;
        let mut sums = vec![[(); 3].map(|_| vec![Complex::new(0.0, 0.0); harmonics]); passes];
        let mut squares = vec![0.0; passes];
        let mut counts = vec![0usize; passes];
        let mut start = vec![([0.0; 3], 0usize); window.bins];
        let (mut start_squares, mut start_count) = (0.0, 0usize);
        let mut command: Option<TensionCommand> = None;
        let mut tau = vec![0.0; n];
        // e^{−j2πmφ} of the sample, one per harmonic, shared by the axes.
        let mut rotors = vec![Complex::new(0.0, 0.0); harmonics];
        for k in 0..steps {
            let now_ns = start_ns + k * period_ns;
            let t = k as f64 * dt;
            if let Some(c) = &command {
                for (d, &v) in tau.iter_mut().zip(&c.tensions[..n]) {
                    *d = f64::from(v);
                }
                plant.command(&tau);
            }
            // The plant process steps at least every millisecond, whatever
            // the controller's rate (its idle period), the command held.
            if k > 0 && !(0..substeps).all(|_| plant.step(dt / substeps as f64)) {
                return Err(IpcError::Other(format!(
                    "the model's plant did not solve at {t:.3} s"
                )));
            }
            plant.sense(now_ns);
            let header = Header {
                seq: k + 1,
                stamp_ns: now_ns,
            };
            let status = 0;
            let state = state_message(&plant, header, command.map_or(0, |c| c.header.seq), status);
            let desired = motion.at(t);
            let mut setpoint = setpoint_for(&motion, t, &desired, None);
            setpoint.header = Header {
                seq: k + 1,
                stamp_ns: now_ns,
            };
            let inbox = Inbox {
                setpoint: Some(crate::ipc::frame::setpoint(&to_tracker, &setpoint)),
                setpoints: 1,
                superseded_nonfinite: 0,
                state: Some(state),
                states: 1,
                weights: None,
            };
            let tick = Tick {
                index: k,
                deadline_ns: now_ns,
                lateness_ns: 0,
                skipped: 0,
            };
            command = Some(controller.period(&tick, now_ns, false, &inbox));
            controller.finish(0);
            let since = t - self.settle_s;
            let pass = (since / self.period_s).floor();
            if desired.holding || desired.moving || since < 0.0 {
                continue;
            }
            let p = desired.point.pose;
            let tip = plant.pose_in_base();
            let e = [p[0] - tip[0], p[1] - tip[1], p[2] - tip[2]];
            let turned = offset.turned([p[0], p[1], p[2]], e);
            if let Some((sum, count)) = start.get_mut((since / window.bin_s.max(1e-9)) as usize) {
                for (s, v) in sum.iter_mut().zip(turned) {
                    *s += v;
                }
                *count += 1;
                start_squares += e.iter().map(|v| v * v).sum::<f64>();
                start_count += 1;
            }
            if pass as usize >= passes {
                continue;
            }
            let pass = pass as usize;
            squares[pass] += e.iter().map(|v| v * v).sum::<f64>();
            counts[pass] += 1;
            let phase = (desired.t_path / offset.period_s).rem_euclid(1.0);
            for (m, rotor) in rotors.iter_mut().enumerate() {
                *rotor = Complex::from_polar(1.0, -std::f64::consts::TAU * m as f64 * phase);
            }
            for (axis, value) in turned.iter().enumerate() {
                for (sum, rotor) in sums[pass][axis].iter_mut().zip(&rotors) {
                    *sum += rotor * *value;
                }
            }
        }
        for (pass, sum) in sums.iter_mut().enumerate() {
            let count = counts[pass].max(1) as f64;
            for axis in sum.iter_mut() {
                for (m, c) in axis.iter_mut().enumerate() {
                    *c *= if m == 0 { 1.0 } else { 2.0 } / count;
                }
            }
            squares[pass] = (squares[pass] / count).sqrt();
        }
        Ok(PassErrors {
            harmonics: sums,
            rms_m: squares,
            start: start
                .into_iter()
                .map(|(sum, count)| sum.map(|v| v / count.max(1) as f64))
                .collect(),
            start_rms_m: (start_squares / start_count.max(1) as f64).sqrt(),
        })
    }
}

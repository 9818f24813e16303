//! How finely and how far a statics solve goes ([`SolverSettings`]).

/// Most RK4 steps over the length a solve accepts (`tendril fk --steps`):
/// 6000 times the default, far past where the discretisation error meets
/// roundoff, and a solve there still takes well under a second.
pub const MAX_STEPS: usize = 100_000;

/// Discretisation and convergence settings of the statics solve.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SolverSettings {
    /// RK4 steps over the length. 16 puts the default robot's tip within
    /// 1e-7 m of the converged answer (see `BENCHMARKS.md`).
    pub steps: usize,
    /// Convergence: Euclidean norm of the tip residual [force N; moment N·m].
    pub tol: f64,
    /// Newton iterations before giving up.
    pub max_iter: usize,
    /// A warm solve predicted by dx/dτ ([`Statics::add_tension_sensitivity`])
    /// may end on a chord step that no further pass verifies, when that
    /// step moves the tip by at most this (m): the tip is then the last
    /// pass's, moved by the carried ∂tip/∂x, and the solution says so
    /// ([`Solution::extrapolated`]). The step contracts the residual
    /// 10–1000-fold, so the tip's error is a few percent of this bound
    /// (`docs/design.md` §2, "Solve"). 0, the default: every solve ends on
    /// a pass whose residual is below `tol`.
    #[serde(default)]
    pub final_step_m: f64,
}

impl Default for SolverSettings {
    fn default() -> Self {
        SolverSettings {
            steps: 16,
            tol: 5e-10,
            max_iter: 60,
            final_step_m: 0.0,
        }
    }
}

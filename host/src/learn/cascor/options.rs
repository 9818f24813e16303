//! Hyper-parameters of cascade-correlation training (`docs/design.md` §4): which
//! output configurations are tried, the two Quickprop phases, stopping.

use serde::{Deserialize, Serialize};

use super::net::OutputKind;
use super::polish::PolishOptions;
use super::quickprop::QuickpropParams;
use crate::robot::bending_dof;
use crate::robot::Robot;

/// How the output weights are trained.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum OutputSolver {
    /// Fahlman's Quickprop descent on the squared error.
    Quickprop,
    /// Exact ridge least squares over the cached features (linear outputs only),
    /// the ridge strength chosen on the validation split.
    Ridge,
}

impl std::fmt::Display for OutputSolver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            OutputSolver::Quickprop => "quickprop",
            OutputSolver::Ridge => "ridge",
        })
    }
}

/// Which candidate objectives the pool uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum ObjectiveChoice {
    /// Every candidate maximises Fahlman's covariance.
    Covariance,
    /// Every candidate maximises Cascade 2's error reduction.
    Cascade2,
    /// Half the pool each; the installed unit is chosen by validation, so the
    /// objective is picked per unit.
    Mixed,
}

/// Hyper-parameters of [`super::train`]; defaults follow Fahlman's cascor code where it has one.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CascorOptions {
    /// Hidden-unit cap (the firmware's capacity bounds it; ≤ 64).
    pub max_hidden: usize,
    /// Candidates trained per installed unit.
    pub pool: usize,
    /// Candidate objective(s).
    pub objective: ObjectiveChoice,
    /// Output activations to try (`[Linear, Sigmoid]` = choose by validation).
    pub output_kinds: Vec<OutputKind>,
    /// Output solvers to try for linear outputs (sigmoid outputs always use Quickprop).
    pub output_solvers: Vec<OutputSolver>,
    /// Output-phase Quickprop (ε is divided by the number of patterns).
    pub output: QuickpropParams,
    /// Candidate-phase Quickprop (ε is divided by patterns × candidate fan-in).
    pub candidate: QuickpropParams,
    /// Sigmoid-prime offset in the output error of sigmoid outputs (Fahlman: 0.1).
    pub output_prime_offset: f64,
    /// Sigmoid-prime offset in the candidate gradient.
    pub candidate_prime_offset: f64,
    /// Ridge strengths tried, relative to the mean diagonal of the Gram matrix.
    pub ridge_lambdas: Vec<f64>,
    /// Stop after this many installed units without a new best validation RMSE.
    pub valid_patience: usize,
    /// Stop once the validation RMSE (normalised units) is at or below this.
    pub target_rmse: f64,
    /// Hidden units grown by every output configuration before validation picks one
    /// (only when more than one configuration is allowed).
    pub pilot_units: usize,
    /// Train candidates on a fixed random subset of this many training rows
    /// (re-drawn per unit; 0 = all rows). Installation and outputs use all rows.
    pub candidate_patterns: usize,
    /// Show a progress bar on stderr.
    pub progress: bool,
    /// The polish phase after growth (`docs/design.md` §4, "Polish"; off by default, on past two bending degrees of freedom).
    #[serde(default)]
    pub polish: PolishOptions,
}

impl Default for CascorOptions {
    fn default() -> Self {
        CascorOptions {
            max_hidden: tendril_shared::MAX_HIDDEN,
            pool: 8,
            objective: ObjectiveChoice::Cascade2,
            output_kinds: vec![OutputKind::Linear, OutputKind::Sigmoid],
            output_solvers: vec![OutputSolver::Ridge, OutputSolver::Quickprop],
            output: QuickpropParams {
                mu: 2.0,
                epsilon: 0.35,
                decay: 1e-4,
                patience: 8,
                threshold: 0.01,
                max_epochs: 1000,
            },
            // Fahlman: ε 1.0, patience 8, threshold 3 %. With normalised objectives that
            // leaves candidates almost untrained on the IK data (test RMSE ×100 0.21 vs
            // 0.065 at 40 units, BENCHMARKS.md), so the defaults train them longer.
            candidate: QuickpropParams {
                mu: 2.0,
                epsilon: 1000.0,
                decay: 0.0,
                patience: 25,
                threshold: 0.01,
                max_epochs: 1000,
            },
            output_prime_offset: 0.1,
            candidate_prime_offset: 0.1,
            ridge_lambdas: vec![1e-12, 1e-10, 1e-8, 1e-6, 1e-4],
            valid_patience: 8,
            target_rmse: 0.0,
            pilot_units: 3,
            candidate_patterns: 3000,
            progress: true,
            polish: PolishOptions::default(),
        }
    }
}

/// Polish steps of [`CascorOptions::for_robot`] past two bending degrees of
/// freedom. With [`super::polish::POLISH_MEMORY`] pairs the two-segment robot's validation
/// error reaches in 2,000 steps what 12 pairs reached in 10,000; 3,000
/// left split seed 3's held-out p95 at 0.256 mm, over its 0.25 mm target
/// (`docs/design.md` §4, "Polish"). Each step costs about one pass of the
/// training rows forward and back.
pub const POLISH_STEPS: usize = 4_000;

/// The robust loss's δ, in median row errors, of [`CascorOptions::for_robot`]
/// past four bending degrees of freedom (three segments).
pub const ROBUST_SCALE: f64 = 3.0;

impl CascorOptions {
    /// The defaults for `robot` (`docs/design.md` §4): past two bending
    /// degrees of freedom (a two-segment robot) the inverse map is harder
    /// and the 64 units are the limit, so after growth every weight is
    /// polished together ([`POLISH_STEPS`] L-BFGS steps on the tip loss).
    /// Two segments grow with the defaults: a better pick per unit (twice
    /// the pool, candidates on 10,000 rows) cost 7× the growth time for a
    /// start the polish overtakes within its steps. Three keep that better
    /// pick: their robust polish stops by its patience after ≈ 1,000 steps,
    /// and from the default start its validation error stayed 18 % higher
    /// (held-out p95 0.193 against 0.144 mm). One and two (the
    /// single-segment robots, whose net is at the f32 floor) are not
    /// polished.
    pub fn for_robot(robot: &Robot) -> CascorOptions {
        let mut o = CascorOptions::default();
        if bending_dof(robot) > 2 {
            o.polish.max_iterations = POLISH_STEPS;
        }
        if bending_dof(robot) > 4 {
            // Three segments: held-out errors are heavy-tailed (rows on the
            // fold between mirror S-bends), the squared loss chases them and
            // its validation error rises from the first step; the robust
            // loss halves the held-out p95 (`docs/design.md` §4, "Polish").
            o.polish.robust = ROBUST_SCALE;
            o.pool = 16;
            o.candidate_patterns = 10_000;
        }
        o
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::robot::repo_robot as robot;

    #[test]
    fn two_segments_bend_four_ways_and_get_the_polish() {
        let dof = |n| bending_dof(&robot(n));
        assert_eq!(
            (
                dof("seed-1t.toml"),
                dof("seed-4t.toml"),
                dof("tdcr-2seg.toml")
            ),
            (1, 2, 4)
        );
        assert_eq!(
            CascorOptions::for_robot(&robot("seed-4t.toml")),
            CascorOptions::default()
        );
        let two = CascorOptions::for_robot(&robot("tdcr-2seg.toml"));
        let d = CascorOptions::default();
        assert_eq!(
            (two.pool, two.candidate_patterns),
            (d.pool, d.candidate_patterns)
        );
        assert_eq!(two.polish.max_iterations, POLISH_STEPS);
        assert_eq!(two.polish.loss, super::super::PolishLoss::Tip);
        assert_eq!(two.polish.robust, 0.0);
        let three = CascorOptions::for_robot(&robot("tdcr-3seg.toml"));
        assert_eq!(bending_dof(&robot("tdcr-3seg.toml")), 6);
        assert_eq!(three.polish.robust, ROBUST_SCALE);
        assert_eq!((three.pool, three.candidate_patterns), (16, 10_000));
    }
}

//! The identifiability rule (`docs/design.md` §11): which parameters the
//! rows cannot determine, and what data would separate them.

use nalgebra::DMatrix;

use super::params::Param;
use super::report::Unidentified;
use crate::robot::{Robot, Routing};

/// G's explanation: the one parameter known unseen before any fit.
const G_UNSEEN: &str = "G shows only in torsion and shear: tip orientations under \
    helical routing or a known tip moment (mx,my,mz columns) separate it";

/// G, when the rows cannot show it at all (`docs/design.md` §11): with
/// straight tendons and no tip moment the rod does not twist, so only tip
/// orientations could show its shear, and only when they are used. A fit
/// of G there would return whatever its noise says.
pub fn shear_modulus_unseen(
    robot: &Robot,
    params: &[Param],
    used_orientation: bool,
    any_tip_moment: bool,
) -> Option<Unidentified> {
    let straight = robot
        .tendons
        .iter()
        .all(|t| matches!(t.routing, Routing::Straight));
    let asked = params.contains(&Param::ShearModulus);
    (asked && straight && !any_tip_moment && !used_orientation).then(|| Unidentified {
        fixed: Param::ShearModulus.to_string(),
        confounded_with: Vec::new(),
        std_fraction: f64::INFINITY,
        separate_with: G_UNSEEN.into(),
    })
}

/// The identifiability rule (`docs/design.md` §11): while the least
/// determined direction v of the scaled parameters has a standard deviation
/// σ / √λ_min above `fraction`, fix the parameter that weighs most in it
/// (ties within 30 % by [`Param::fix_priority`]) and look again. Returns
/// the parameters left free and what was fixed, with its partners.
pub fn identify(
    a: &DMatrix<f64>,
    params: &[Param],
    sigma: f64,
    fraction: f64,
) -> (Vec<Param>, Vec<Unidentified>) {
    let mut free: Vec<usize> = (0..params.len()).collect();
    let mut fixed = Vec::new();
    while !free.is_empty() {
        let sub = DMatrix::from_fn(free.len(), free.len(), |i, j| a[(free[i], free[j])]);
        let eig = sub.symmetric_eigen();
        let (k, &lmin) = eig
            .eigenvalues
            .iter()
            .enumerate()
            .min_by(|x, y| x.1.total_cmp(y.1))
            .expect("non-empty");
        let std = sigma / lmin.max(0.0).sqrt();
        if std <= fraction {
            break;
        }
        let v = eig.eigenvectors.column(k);
        let vmax = v.amax();
        let pick = (0..free.len())
            .filter(|&i| v[i].abs() >= 0.7 * vmax)
            .min_by_key(|&i| (params[free[i]].fix_priority(), free[i]))
            .expect("the largest component qualifies");
        let partners: Vec<String> = (0..free.len())
            .filter(|&i| i != pick && v[i].abs() >= 0.2 * vmax)
            .map(|i| params[free[i]].to_string())
            .collect();
        let p = params[free[pick]];
        fixed.push(Unidentified {
            fixed: p.to_string(),
            confounded_with: partners.clone(),
            std_fraction: std,
            separate_with: separating_data(p, &partners),
        });
        free.remove(pick);
    }
    (free.iter().map(|&i| params[i]).collect(), fixed)
}

/// What measurement would separate `p` from its partners, in words.
pub fn separating_data(p: Param, partners: &[String]) -> String {
    let with = |s: &str| partners.iter().any(|x| x.starts_with(s));
    match p {
        Param::YoungsModulus | Param::TensionScale(_) | Param::Offset(_)
            if with("offset") || with("tension_scale") || with("E") || with("density") =>
        {
            "tendons and weight bend the rod by τ·s·d/(E·I) and ρ·A·g/(E·I): only the ratios \
             are seen in tip positions. A known tip load (fx,fy,fz columns: a hung weight), \
             a measured tendon offset or a load-cell-calibrated tension separates them"
                .into()
        }
        Param::ShearModulus => G_UNSEEN.into(),
        Param::Density => "the rod's weight is seen only against its stiffness: a known tip \
            load, or weighing the rod, separates it"
            .into(),
        Param::Angle(_) | Param::BaseRotation(_) => "a common turn of the tendons looks like \
            a turn of the base about its axis: tip orientations (qw..qz) or rows at zero \
            tension under gravity along another axis separate them"
            .into(),
        _ => "more rows spread over the tension limits (tendril calibrate --plan N) or \
            orientation columns"
            .into(),
    }
}

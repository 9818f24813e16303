//! Small dense solvers: the 6×6 symmetric positive definite systems of the
//! rod (the strain-rate matrix K at every RK4 stage, `docs/design.md` §2, and
//! the section stiffness across an anchor, §2.1), each with an LU fallback
//! for when roundoff breaks positive definiteness. A matrix that neither can
//! solve is reported, never guessed at.

use nalgebra::{Cholesky, Matrix6, Vector6, LU, U6};

/// Square-root-free Cholesky factor K = L D Lᵀ (L unit lower triangular,
/// D diagonal) of a 6×6 symmetric positive definite matrix, in fixed arrays:
/// the strain-rate system is factored four times per RK4 step, and at this
/// size fully unrolled loops beat a general decomposition (measured, see
/// BENCHMARKS.md "Statics"). LDLᵀ rather than LLᵀ: the six square roots of
/// LLᵀ sit on the factor's critical path, the divisions of both do too.
#[derive(Clone, Copy, Debug)]
pub struct Ldlt6 {
    /// L, row-major, below the diagonal; entries on and above it unused.
    l: [[f64; 6]; 6],
    /// 1 / D_jj.
    inv_d: [f64; 6],
}

// Index loops on purpose: the triangular recurrences read as in the textbook,
// and the constant bounds are what makes them unroll.
#[allow(clippy::needless_range_loop)]
impl Ldlt6 {
    /// Factor the matrix whose lower triangle is `k` (row-major); `None`
    /// when a pivot is not positive (or not finite).
    #[inline(always)]
    pub fn new(k: &[[f64; 6]; 6]) -> Option<Ldlt6> {
        let mut f = Ldlt6 {
            l: [[0.0; 6]; 6],
            inv_d: [0.0; 6],
        };
        // dl[i][p] = L_ip D_pp, kept so each entry costs one product.
        let mut dl = [[0.0; 6]; 6];
        // One call per column with the column as a constant, so that every
        // loop has constant bounds and unrolls.
        let ok = f.column::<0>(k, &mut dl)
            && f.column::<1>(k, &mut dl)
            && f.column::<2>(k, &mut dl)
            && f.column::<3>(k, &mut dl)
            && f.column::<4>(k, &mut dl)
            && f.column::<5>(k, &mut dl);
        ok.then_some(f)
    }

    /// Column J of L and D_JJ; false when the pivot is not positive and finite.
    #[inline(always)]
    fn column<const J: usize>(&mut self, k: &[[f64; 6]; 6], dl: &mut [[f64; 6]; 6]) -> bool {
        let l = &mut self.l;
        let mut d = k[J][J];
        for p in 0..J {
            d -= l[J][p] * dl[J][p];
        }
        if !(d > 0.0 && d < f64::INFINITY) {
            return false;
        }
        let inv = 1.0 / d;
        self.inv_d[J] = inv;
        for i in J + 1..6 {
            let mut x = k[i][J];
            for p in 0..J {
                x -= dl[i][p] * l[J][p];
            }
            dl[i][J] = x;
            l[i][J] = x * inv;
        }
        true
    }

    /// Solve K x = b in place, b a vector.
    pub fn solve_vector(&self, b: &mut Vector6<f64>) {
        let mut x = [0.0; 6];
        x.copy_from_slice(b.as_slice());
        self.solve(&mut x);
        b.copy_from_slice(&x);
    }

    /// Solve K x = b in place.
    #[inline(always)]
    pub fn solve(&self, b: &mut [f64; 6]) {
        self.forward::<1>(b);
        self.forward::<2>(b);
        self.forward::<3>(b);
        self.forward::<4>(b);
        self.forward::<5>(b);
        for (x, inv) in b.iter_mut().zip(&self.inv_d) {
            *x *= inv;
        }
        self.backward::<4>(b);
        self.backward::<3>(b);
        self.backward::<2>(b);
        self.backward::<1>(b);
        self.backward::<0>(b);
    }

    /// Row I of L y = b (unit diagonal).
    #[inline(always)]
    fn forward<const I: usize>(&self, b: &mut [f64; 6]) {
        let mut x = b[I];
        for p in 0..I {
            x -= self.l[I][p] * b[p];
        }
        b[I] = x;
    }

    /// Row I of Lᵀ x = y (unit diagonal).
    #[inline(always)]
    fn backward<const I: usize>(&self, b: &mut [f64; 6]) {
        let mut x = b[I];
        for p in I + 1..6 {
            x -= self.l[p][I] * b[p];
        }
        b[I] = x;
    }
}

/// A factored 6×6 matrix, solved many times (the six or more sensitivity
/// columns of `statics::tangent` reuse the strain-rate factor).
#[derive(Clone, Debug)]
pub enum Factor6 {
    /// The fixed-array LDLᵀ of the strain-rate matrix ([`Ldlt6`]).
    Ldlt(Ldlt6),
    /// nalgebra's Cholesky (the stiffness across an anchor).
    Cholesky(Cholesky<f64, U6>),
    /// The fallback when a Cholesky pivot is not positive.
    Lu(LU<f64, U6, U6>),
}

impl Factor6 {
    /// Factor the SPD matrix whose lower triangle is `k` (row-major) and
    /// solve K x = rhs: [`Ldlt6`], LU when a pivot is not positive. `None`
    /// when neither solves or the solution is not finite.
    #[inline(always)]
    pub fn ldlt_solve(k: &[[f64; 6]; 6], rhs: [f64; 6]) -> Option<(Factor6, [f64; 6])> {
        let (factor, x) = match Ldlt6::new(k) {
            Some(c) => {
                let mut x = rhs;
                c.solve(&mut x);
                (Factor6::Ldlt(c), x)
            }
            None => {
                let full = Matrix6::from_fn(|i, j| if j <= i { k[i][j] } else { k[j][i] });
                let lu = full.lu();
                let x = lu.solve(&Vector6::from_row_slice(&rhs))?;
                (Factor6::Lu(lu), [x[0], x[1], x[2], x[3], x[4], x[5]])
            }
        };
        x.iter().all(|v| v.is_finite()).then_some((factor, x))
    }

    /// Cholesky of the SPD matrix `k`, LU when it fails.
    pub fn cholesky_or_lu(k: Matrix6<f64>) -> Factor6 {
        match k.cholesky() {
            Some(c) => Factor6::Cholesky(c),
            None => Factor6::Lu(k.lu()),
        }
    }

    /// Solve K x = b in place for every column b of `b`; false when the
    /// factor cannot. (One dispatch on the factor for all the columns: the
    /// sensitivity pass solves six or more per RK4 stage.)
    #[inline(always)]
    pub fn solve_columns(&self, b: &mut [Vector6<f64>]) -> bool {
        match self {
            Factor6::Ldlt(c) => {
                for x in b {
                    c.solve_vector(x);
                }
                true
            }
            Factor6::Cholesky(c) => {
                for x in b {
                    c.solve_mut(x);
                }
                true
            }
            Factor6::Lu(lu) => b.iter_mut().all(|x| lu.solve_mut(x)),
        }
    }

    /// Solve K x = b in place, b a vector; false when the factor cannot.
    #[inline(always)]
    pub fn solve_vector(&self, b: &mut Vector6<f64>) -> bool {
        match self {
            Factor6::Ldlt(c) => {
                c.solve_vector(b);
                true
            }
            Factor6::Cholesky(c) => {
                c.solve_mut(b);
                true
            }
            Factor6::Lu(lu) => lu.solve_mut(b),
        }
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::{Matrix6, Vector6};

    use super::*;

    /// A symmetric positive definite test matrix: diagonal stiffnesses of very
    /// different sizes (as Kse and Kbt are) plus a rank-one tendon term.
    fn spd() -> Matrix6<f64> {
        let z = Vector6::new(0.3, -0.1, 0.9, 0.002, -0.004, 0.001);
        Matrix6::from_diagonal(&Vector6::new(4.0e3, 4.0e3, 1.0e4, 0.02, 0.02, 0.015))
            + z * z.transpose() * 50.0
    }

    fn lower(k: &Matrix6<f64>) -> [[f64; 6]; 6] {
        let mut a = [[0.0; 6]; 6];
        for (i, row) in a.iter_mut().enumerate() {
            for (j, x) in row.iter_mut().enumerate().take(i + 1) {
                *x = k[(i, j)];
            }
        }
        a
    }

    #[test]
    fn ldlt_solves_an_spd_system_to_roundoff() {
        let k = spd();
        let b = Vector6::new(1.0, -2.0, 0.5, 0.01, 0.0, -0.03);
        let (factor, x) = Factor6::ldlt_solve(&lower(&k), b.into()).unwrap();
        assert!(matches!(factor, Factor6::Ldlt(_)));
        let x = Vector6::from_row_slice(&x);
        assert!((k * x - b).norm() < 1e-12 * b.norm());
        let mut again = b;
        assert!(factor.solve_vector(&mut again));
        assert_eq!(again, x);
    }

    #[test]
    fn an_indefinite_matrix_falls_back_to_lu() {
        let mut k = spd();
        k[(5, 5)] = -k[(5, 5)];
        assert!(Ldlt6::new(&lower(&k)).is_none());
        let b = Vector6::new(1.0, 0.0, 0.0, 0.0, 0.0, 1.0);
        let (factor, x) = Factor6::ldlt_solve(&lower(&k), b.into()).unwrap();
        assert!(matches!(factor, Factor6::Lu(_)));
        assert!((k * Vector6::from_row_slice(&x) - b).norm() < 1e-10);
        let mut c = b;
        assert!(Factor6::cholesky_or_lu(k).solve_vector(&mut c));
        assert!((k * c - b).norm() < 1e-10);
    }

    #[test]
    fn a_singular_matrix_is_reported() {
        let k = [[0.0; 6]; 6];
        assert!(Factor6::ldlt_solve(&k, [1.0; 6]).is_none());
    }
}

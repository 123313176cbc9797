//! Local identifiability of the fitted parameters at a least-squares optimum.
//!
//! At the optimum `θ̂` of `S(θ) = Σ_k r_k(θ)²`, with `r_k = sim_k − meas_k`
//! (weighted exactly as in the objective), the Gauss–Newton / Fisher
//! approximation of the parameter covariance is
//!
//! ```text
//! cov(θ̂) ≈ σ² · (JᵀJ)⁻¹,      J_kj = ∂r_k/∂θ_j  (N x p),      σ² = RSS / (N − p)
//! ```
//!
//! It assumes the (weighted) residuals are independent with a common variance
//! `σ²` and that the model is close to linear in `θ` over the confidence
//! region. Residuals of PMU fits are usually autocorrelated, so the standard
//! errors are optimistic in absolute terms; the *relative* information (which
//! parameters are poorly determined, which are strongly correlated, which are
//! not determined at all) is what the calibrator uses this for.
//!
//! # Computation
//!
//! Parameters have very different units (seconds, per-unit gains, ...), so
//! `JᵀJ` is never formed. Instead:
//!
//! 1. Each column is scaled to unit Euclidean norm, `J_s = J·D⁻¹` with
//!    `D = diag(d_j)`, `d_j = ‖J_{:,j}‖`. A column with `d_j = 0` (or a
//!    subnormal norm) means the residuals do not depend on `θ_j`: it is left at
//!    zero and the parameter is unidentified.
//! 2. SVD `J_s = U·S·Vᵀ` (if `N < p`, `J_s` is padded with zero rows to `p x p`,
//!    which does not change `J_sᵀJ_s`, so that `V` spans all of parameter space).
//! 3. Singular values `s_k ≤ 1e-10 · s_max` ([`RELATIVE_CUTOFF`]) are treated as
//!    zero. `rank` counts the others; `condition = s_max / s_min` over all `p`
//!    singular values of `J_s` (`∞` if `J_s` is rank-deficient).
//! 4. The scaled pseudo-inverse `C = (J_sᵀJ_s)⁺ = Σ_{s_k > cut} v_k v_kᵀ / s_k²`,
//!    and the projector onto the numerical null space
//!    `P₀ = Σ_{s_k ≤ cut} v_k v_kᵀ`.
//! 5. Parameter `j` is **unidentified** if its column is zero or its component in
//!    the null space, `sqrt(P₀_jj)`, exceeds [`NULL_COMPONENT_LIMIT`] (0.1):
//!    moving along that direction changes the residuals by (numerically) nothing,
//!    so the data do not determine `θ_j`. Its standard error is `+∞`.
//! 6. Unscaling: `cov_ij = σ²·C_ij / (d_i d_j)`, so `std_j = σ·sqrt(C_jj) / d_j`
//!    in the units of `θ_j`, and `ρ_ij = C_ij / sqrt(C_ii C_jj)` (unit-free and
//!    independent of `σ²`).
//!
//! # Correlated pairs
//!
//! For two identified parameters the pair `(i, j, ρ_ij)` is reported when
//! `|ρ_ij| > threshold`. For two *unidentified* parameters the covariance is
//! unbounded; its limiting correlation as the null-space singular values go to
//! zero (all at the same rate) is `P₀_ij / sqrt(P₀_ii P₀_jj)`, which is `±1` for
//! two parameters that trade off along a single unresolved direction (e.g. two
//! identical columns give `ρ = −1`: only their sum is determined). Such pairs are
//! reported with that limiting value, while the `correlation` matrix itself holds
//! NaN for them. Mixed pairs (one identified, one not) are not reported.
//!
//! # Degenerate input
//!
//! * `N ≤ p`: `σ²` cannot be estimated and is NaN, so the standard errors of
//!   identified parameters are NaN (those of unidentified ones stay `+∞`), while
//!   the correlations, rank, condition and `unidentified` are still computed from
//!   `(JᵀJ)⁺`. The same holds for a NaN, infinite or negative `rss`.
//! * `rss = 0` (exact fit): `σ² = 0`, identified standard errors are 0.
//! * A non-finite entry in `jac`, rows of unequal length, a column norm that
//!   overflows `f64`, or an SVD that does not converge: nothing can be said; the
//!   result has `sigma2` from `rss` as usual, all standard errors, correlations
//!   and `condition` NaN, `rank` 0, no pairs, and every parameter listed as
//!   unidentified. The function never panics.
//! * An empty Jacobian (`N = 0`, so `p = 0`) gives empty vectors.

use nalgebra::{DMatrix, SVD};

/// Singular values at or below this fraction of the largest are treated as zero.
pub const RELATIVE_CUTOFF: f64 = 1e-10;

/// A parameter whose component in the numerical null space (`sqrt(P₀_jj)`, see
/// the module docs) exceeds this is unidentified.
pub const NULL_COMPONENT_LIMIT: f64 = 0.1;

/// Identifiability diagnostics at a least-squares optimum (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct Identifiability {
    /// Residual variance estimate `RSS / (N − p)`, in squared (weighted)
    /// residual units; NaN if `N ≤ p` or `rss` is not a finite non-negative number.
    pub sigma2: f64,
    /// `sqrt(diag(cov))` in each parameter's own units; `f64::INFINITY` for
    /// parameters the data do not determine (see `unidentified`), NaN when
    /// `sigma2` is NaN (identified parameters) or the Jacobian is invalid.
    pub std_errors: Vec<f64>,
    /// `p x p` correlation matrix of the estimates (1 on the diagonal); NaN in
    /// the rows and columns of parameters whose standard error is infinite.
    pub correlation: Vec<Vec<f64>>,
    /// Pairs `(i, j, ρ)` with `i < j` and `|ρ| > threshold`, in row-major order;
    /// for two unidentified parameters `ρ` is the limiting correlation.
    pub correlated_pairs: Vec<(usize, usize, f64)>,
    /// Numerical rank of the column-scaled Jacobian (singular values above
    /// `RELATIVE_CUTOFF · s_max`).
    pub rank: usize,
    /// Condition number `s_max / s_min` of the column-scaled Jacobian over all
    /// `p` singular values (`∞` if rank-deficient, NaN for invalid input).
    pub condition: f64,
    /// Indices (ascending) of parameters with zero sensitivity or infinite
    /// standard error.
    pub unidentified: Vec<usize>,
}

/// Local identifiability analysis at a least-squares optimum.
///
/// * `jac` — `N x p` Jacobian of the residual vector `r` (`r_k = sim_k − meas_k`,
///   weighted as in the objective) with respect to the parameters, row-major:
///   `jac[k][j] = ∂r_k/∂θ_j`. All rows must have the same length `p`.
/// * `rss` — residual sum of squares `Σ r_k²` at the optimum (same weighting).
/// * `threshold` — `|ρ|` above which a pair is reported, e.g. `0.95`.
///
/// The covariance is `σ²(JᵀJ)⁺` computed by SVD of the column-scaled Jacobian;
/// see the module documentation for the method and the conventions for
/// rank-deficient, under-determined and invalid input. Never panics.
pub fn analyse(jac: &[Vec<f64>], rss: f64, threshold: f64) -> Identifiability {
    let n = jac.len();
    let p = jac.first().map_or(0, Vec::len);

    let sigma2 = if n > p && rss.is_finite() && rss >= 0.0 {
        rss / (n - p) as f64
    } else {
        f64::NAN
    };

    if p == 0 {
        return Identifiability {
            sigma2,
            std_errors: Vec::new(),
            correlation: Vec::new(),
            correlated_pairs: Vec::new(),
            rank: 0,
            condition: f64::NAN,
            unidentified: Vec::new(),
        };
    }

    let valid = jac
        .iter()
        .all(|row| row.len() == p && row.iter().all(|v| v.is_finite()));
    if !valid {
        return invalid(sigma2, p);
    }

    // Column norms, computed with scaling so that huge or tiny entries neither
    // overflow nor underflow.
    let norms: Vec<f64> = (0..p)
        .map(|j| scaled_norm(jac.iter().map(|row| row[j])))
        .collect();
    if norms.iter().any(|d| !d.is_finite()) {
        return invalid(sigma2, p); // a column norm beyond f64::MAX
    }
    let zero_col: Vec<bool> = norms.iter().map(|&d| d < f64::MIN_POSITIVE).collect();

    // Scaled Jacobian, padded with zero rows to at least p rows.
    let rows = n.max(p);
    let js = DMatrix::from_fn(rows, p, |k, j| {
        if k < n && !zero_col[j] {
            jac[k][j] / norms[j]
        } else {
            0.0
        }
    });

    // Generous iteration cap: only reached on pathological input.
    let max_niter = 1000 + 200 * p;
    let Some(svd) = SVD::try_new_unordered(js, false, true, 5.0 * f64::EPSILON, max_niter) else {
        return invalid(sigma2, p);
    };
    let Some(v_t) = svd.v_t.as_ref() else {
        return invalid(sigma2, p);
    };
    let s = &svd.singular_values; // length p (rows ≥ p)

    let s_max = s.iter().copied().fold(0.0, f64::max);
    let s_min = s.iter().copied().fold(f64::INFINITY, f64::min);
    let cut = RELATIVE_CUTOFF * s_max;
    let kept: Vec<bool> = s.iter().map(|&sk| s_max > 0.0 && sk > cut).collect();
    let rank = kept.iter().filter(|&&k| k).count();
    let condition = if rank == p && s_min > 0.0 {
        s_max / s_min
    } else {
        f64::INFINITY
    };

    // C = (J_sᵀJ_s)⁺ and P₀ = null-space projector, both p x p.
    let mut c = vec![vec![0.0; p]; p];
    let mut p0 = vec![vec![0.0; p]; p];
    for (k, &keep) in kept.iter().enumerate() {
        let w = if keep { 1.0 / (s[k] * s[k]) } else { 1.0 };
        let target = if keep { &mut c } else { &mut p0 };
        for i in 0..p {
            let vi = v_t[(k, i)] * w;
            if vi == 0.0 {
                continue;
            }
            for j in i..p {
                target[i][j] += vi * v_t[(k, j)];
            }
        }
    }
    // Mirror the upper triangles so both matrices are exactly symmetric.
    for i in 0..p {
        for j in 0..i {
            c[i][j] = c[j][i];
            p0[i][j] = p0[j][i];
        }
    }

    let unident: Vec<bool> = (0..p)
        .map(|j| {
            zero_col[j]
                || p0[j][j].max(0.0).sqrt() > NULL_COMPONENT_LIMIT
                || c[j][j].is_nan()
                || c[j][j] <= 0.0
        })
        .collect();

    let sigma = sigma2.sqrt();
    let std_errors: Vec<f64> = (0..p)
        .map(|j| {
            if unident[j] {
                f64::INFINITY
            } else {
                sigma * c[j][j].sqrt() / norms[j]
            }
        })
        .collect();

    let correlation: Vec<Vec<f64>> = (0..p)
        .map(|i| {
            (0..p)
                .map(|j| {
                    if unident[i] || unident[j] {
                        f64::NAN
                    } else if i == j {
                        1.0
                    } else {
                        (c[i][j] / (c[i][i].sqrt() * c[j][j].sqrt())).clamp(-1.0, 1.0)
                    }
                })
                .collect()
        })
        .collect();

    let mut correlated_pairs = Vec::new();
    for i in 0..p {
        for j in i + 1..p {
            let rho = match (unident[i], unident[j]) {
                (false, false) => correlation[i][j],
                (true, true) if !zero_col[i] && !zero_col[j] => {
                    let denom = p0[i][i].sqrt() * p0[j][j].sqrt();
                    (p0[i][j] / denom).clamp(-1.0, 1.0)
                }
                _ => continue,
            };
            if rho.abs() > threshold {
                correlated_pairs.push((i, j, rho));
            }
        }
    }

    Identifiability {
        sigma2,
        std_errors,
        correlation,
        correlated_pairs,
        rank,
        condition,
        unidentified: (0..p).filter(|&j| unident[j]).collect(),
    }
}

/// Result for a Jacobian nothing can be concluded from.
fn invalid(sigma2: f64, p: usize) -> Identifiability {
    Identifiability {
        sigma2,
        std_errors: vec![f64::NAN; p],
        correlation: vec![vec![f64::NAN; p]; p],
        correlated_pairs: Vec::new(),
        rank: 0,
        condition: f64::NAN,
        unidentified: (0..p).collect(),
    }
}

/// Euclidean norm without overflow/underflow (finite input).
fn scaled_norm(values: impl Iterator<Item = f64> + Clone) -> f64 {
    let amax = values.clone().fold(0.0_f64, |m, v| m.max(v.abs()));
    if amax == 0.0 {
        return 0.0;
    }
    amax * values.map(|v| (v / amax) * (v / amax)).sum::<f64>().sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;

    /// Seeded test noise: the workspace's one random source.
    use itaipu_dynamics::rng::Normal as Rng;

    fn rel_err(a: f64, b: f64) -> f64 {
        (a - b).abs() / b.abs()
    }

    /// Columns to a row-major Jacobian.
    fn from_columns(cols: &[Vec<f64>]) -> Vec<Vec<f64>> {
        (0..cols[0].len())
            .map(|k| cols.iter().map(|c| c[k]).collect())
            .collect()
    }

    /// Textbook simple regression y = a + b x: (a, b, RSS, s², se_a, se_b, corr(a, b)).
    fn textbook(x: &[f64], y: &[f64]) -> (f64, f64, f64, f64, f64, f64, f64) {
        let n = x.len() as f64;
        let xbar = x.iter().sum::<f64>() / n;
        let ybar = y.iter().sum::<f64>() / n;
        let sxx: f64 = x.iter().map(|xi| (xi - xbar).powi(2)).sum();
        let sxy: f64 = x
            .iter()
            .zip(y)
            .map(|(xi, yi)| (xi - xbar) * (yi - ybar))
            .sum();
        let b = sxy / sxx;
        let a = ybar - b * xbar;
        let rss: f64 = x
            .iter()
            .zip(y)
            .map(|(xi, yi)| (a + b * xi - yi).powi(2))
            .sum();
        let s2 = rss / (n - 2.0);
        let se_b = (s2 / sxx).sqrt();
        let se_a = (s2 * (1.0 / n + xbar * xbar / sxx)).sqrt();
        let sum_x2: f64 = x.iter().map(|xi| xi * xi).sum();
        let corr = -xbar * n.sqrt() / sum_x2.sqrt();
        (a, b, rss, s2, se_a, se_b, corr)
    }

    fn noisy_line(x: &[f64], a: f64, b: f64, sigma: f64, seed: u64) -> Vec<f64> {
        let mut rng = Rng::new(seed);
        x.iter()
            .map(|xi| a + b * xi + sigma * rng.sample())
            .collect()
    }

    #[test]
    fn linear_regression_matches_textbook_standard_errors() {
        // Centred-ish abscissa, and one far from the origin (strong a-b correlation).
        for &(x0, seed) in &[(0.0, 1_u64), (100.0, 2), (-3.0, 3)] {
            let x: Vec<f64> = (0..50).map(|k| x0 + 0.1 * k as f64).collect();
            let y = noisy_line(&x, 1.5, -0.7, 0.1, seed);
            let (_, _, rss, s2, se_a, se_b, corr) = textbook(&x, &y);
            let jac = from_columns(&[vec![1.0; x.len()], x.clone()]);
            let r = analyse(&jac, rss, 0.95);
            assert!(rel_err(r.sigma2, s2) < 1e-12);
            assert!(
                rel_err(r.std_errors[0], se_a) < 1e-10,
                "x0={x0}: {} vs {se_a}",
                r.std_errors[0]
            );
            assert!(
                rel_err(r.std_errors[1], se_b) < 1e-10,
                "x0={x0}: {} vs {se_b}",
                r.std_errors[1]
            );
            assert!((r.correlation[0][1] - corr).abs() < 1e-10);
            assert!((r.correlation[1][0] - corr).abs() < 1e-10);
            assert_eq!(r.correlation[0][0], 1.0);
            assert_eq!(r.rank, 2);
            assert!(r.condition.is_finite() && r.condition >= 1.0);
            assert!(r.unidentified.is_empty());
            if corr.abs() > 0.95 {
                assert_eq!(r.correlated_pairs.len(), 1);
                let (i, j, rho) = r.correlated_pairs[0];
                assert_eq!((i, j), (0, 1));
                assert!((rho - corr).abs() < 1e-10);
            } else {
                assert!(r.correlated_pairs.is_empty());
            }
        }
    }

    #[test]
    fn identical_columns_are_unidentified_and_paired() {
        let x: Vec<f64> = (0..40).map(|k| 0.25 * k as f64 - 3.0).collect();
        let y = noisy_line(&x, 0.3, 2.0, 0.2, 11);
        let (_, _, rss, _, _, _, _) = textbook(&x, &y);
        // Model y = a + b x + c x: b and c enter only as b + c.
        let jac = from_columns(&[vec![1.0; x.len()], x.clone(), x.clone()]);
        let r = analyse(&jac, rss, 0.95);
        assert_eq!(r.unidentified, vec![1, 2]);
        assert_eq!(r.std_errors[1], f64::INFINITY);
        assert_eq!(r.std_errors[2], f64::INFINITY);
        assert!(r.correlation[1][2].is_nan() && r.correlation[0][1].is_nan());
        assert_eq!(r.rank, 2);
        assert_eq!(r.condition, f64::INFINITY);
        // The intercept is still determined, with the textbook standard error of
        // the 2-parameter line but σ² on N − 3 degrees of freedom.
        assert!(r.std_errors[0].is_finite());
        let s2_3 = rss / (x.len() - 3) as f64;
        let n = x.len() as f64;
        let xbar = x.iter().sum::<f64>() / n;
        let sxx: f64 = x.iter().map(|xi| (xi - xbar).powi(2)).sum();
        let se_a = (s2_3 * (1.0 / n + xbar * xbar / sxx)).sqrt();
        assert!(rel_err(r.std_errors[0], se_a) < 1e-10);
        // Only b + c is determined: estimates trade off one for one, ρ = −1.
        assert_eq!(r.correlated_pairs.len(), 1);
        let (i, j, rho) = r.correlated_pairs[0];
        assert_eq!((i, j), (1, 2));
        assert!((rho + 1.0).abs() < 1e-10, "rho = {rho}");
    }

    #[test]
    fn small_null_component_stays_identified() {
        // c1 = c0 + 0.05·c2: null direction ∝ (1, −1, 0.05); θ2's component is ~0.035 < 0.1.
        let mut rng = Rng::new(5);
        let c0: Vec<f64> = (0..30).map(|_| rng.sample()).collect();
        let c2: Vec<f64> = (0..30).map(|_| rng.sample()).collect();
        let c1: Vec<f64> = c0.iter().zip(&c2).map(|(a, b)| a + 0.05 * b).collect();
        let r = analyse(&from_columns(&[c0, c1, c2]), 1.0, 0.95);
        assert_eq!(r.rank, 2);
        assert_eq!(r.unidentified, vec![0, 1]);
        assert!(r.std_errors[2].is_finite());
        assert_eq!(r.correlated_pairs.len(), 1);
        assert!((r.correlated_pairs[0].2 + 1.0).abs() < 1e-10);
    }

    #[test]
    fn unit_change_scales_the_standard_error_by_the_same_factor() {
        let x: Vec<f64> = (0..30).map(|k| 1.0 + 0.2 * k as f64).collect();
        let y = noisy_line(&x, -2.0, 0.5, 0.05, 21);
        let (_, _, rss, _, _, _, _) = textbook(&x, &y);
        let base = analyse(&from_columns(&[vec![1.0; x.len()], x.clone()]), rss, 0.95);
        for &f in &[1e-3, 1e3, 1e150, 1e-150] {
            // θ1' = θ1 / f, so ∂r/∂θ1' = f·∂r/∂θ1 and se(θ1') = se(θ1) / f.
            let xf: Vec<f64> = x.iter().map(|v| v * f).collect();
            let r = analyse(&from_columns(&[vec![1.0; x.len()], xf]), rss, 0.95);
            assert!(
                rel_err(r.std_errors[1] * f, base.std_errors[1]) < 1e-12,
                "f={f}"
            );
            assert!(
                rel_err(r.std_errors[0], base.std_errors[0]) < 1e-12,
                "f={f}"
            );
            assert!((r.correlation[0][1] - base.correlation[0][1]).abs() < 1e-12);
            assert!(rel_err(r.condition, base.condition) < 1e-12);
            assert_eq!(r.rank, 2);
        }
    }

    #[test]
    fn near_collinear_pair_reported_with_right_rho() {
        let n = 64;
        let mut rng = Rng::new(31);
        let u: Vec<f64> = (0..n).map(|_| rng.sample()).collect();
        let noise: Vec<f64> = (0..n).map(|_| rng.sample()).collect();
        let other: Vec<f64> = (0..n).map(|k| (0.3 * k as f64).sin()).collect();
        // w ≈ u with a little independent content: cos(u, w) ≈ 0.99.
        let w: Vec<f64> = u
            .iter()
            .zip(&noise)
            .map(|(a, b)| 1e3 * (a + 0.14 * b))
            .collect();
        let jac = from_columns(&[u, other, w]);
        let r = analyse(&jac, 2.5, 0.95);

        // Independent reference: explicit inverse of JᵀJ.
        let j = DMatrix::from_fn(n, 3, |k, c| jac[k][c]);
        let cov = (j.transpose() * &j).try_inverse().unwrap() * (2.5 / (n - 3) as f64);
        let rho02 = cov[(0, 2)] / (cov[(0, 0)] * cov[(2, 2)]).sqrt();
        assert!(
            rho02.abs() > 0.98 && rho02.abs() < 0.995,
            "design rho {rho02}"
        );
        for c in 0..3 {
            assert!(rel_err(r.std_errors[c], cov[(c, c)].sqrt()) < 1e-9);
        }
        assert_eq!(r.correlated_pairs.len(), 1, "{:?}", r.correlated_pairs);
        let (i, jj, rho) = r.correlated_pairs[0];
        assert_eq!((i, jj), (0, 2));
        assert!((rho - rho02).abs() < 1e-10, "{rho} vs {rho02}");
        assert!(r.unidentified.is_empty());
    }

    #[test]
    fn orthogonal_design_reports_no_pairs() {
        // Walsh columns (mutually orthogonal), in very different units.
        let n = 64;
        let units = [1.0, 1e-4, 3e5, 7.0];
        let cols: Vec<Vec<f64>> = (0..4)
            .map(|bit| {
                (0..n)
                    .map(|k: usize| units[bit] * if (k >> bit) & 1 == 0 { 1.0 } else { -1.0 })
                    .collect()
            })
            .collect();
        let r = analyse(&from_columns(&cols), 6.0, 0.5);
        assert!(r.correlated_pairs.is_empty());
        assert_eq!(r.rank, 4);
        assert!((r.condition - 1.0).abs() < 1e-12);
        let sigma = (6.0 / (n - 4) as f64).sqrt();
        for (i, unit) in units.iter().enumerate() {
            // se = σ / ‖column‖ for an orthogonal design.
            let expected = sigma / (unit * (n as f64).sqrt());
            assert!(rel_err(r.std_errors[i], expected) < 1e-12);
            for j in 0..4 {
                let e = if i == j { 1.0 } else { 0.0 };
                assert!((r.correlation[i][j] - e).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn zero_column_is_unidentified_others_fine() {
        let x: Vec<f64> = (0..25).map(|k| k as f64 - 12.0).collect();
        let y = noisy_line(&x, 4.0, 0.1, 0.3, 41);
        let (_, _, rss, _, _, _, _) = textbook(&x, &y);
        let jac = from_columns(&[vec![1.0; x.len()], vec![0.0; x.len()], x.clone()]);
        let r = analyse(&jac, rss, 0.95);
        assert_eq!(r.unidentified, vec![1]);
        assert_eq!(r.std_errors[1], f64::INFINITY);
        assert_eq!(r.rank, 2);
        assert_eq!(r.condition, f64::INFINITY);
        let s2 = rss / (x.len() - 3) as f64;
        let n = x.len() as f64;
        let sxx: f64 = x.iter().map(|v| v * v).sum(); // x is centred
        assert!(rel_err(r.std_errors[0], (s2 / n).sqrt()) < 1e-10);
        assert!(rel_err(r.std_errors[2], (s2 / sxx).sqrt()) < 1e-10);
        assert!(r.correlation[0][2].abs() < 1e-12);
        assert!(r.correlation[1].iter().all(|v| v.is_nan()));
        assert!(r.correlated_pairs.is_empty());
    }

    #[test]
    fn underdetermined_gives_nan_sigma_but_correlations() {
        // N = p = 2, full rank.
        let r = analyse(&[vec![1.0, 2.0], vec![1.0, -1.0]], 0.0, 0.5);
        assert!(r.sigma2.is_nan());
        assert!(r.std_errors.iter().all(|v| v.is_nan()));
        assert_eq!(r.rank, 2);
        let j = DMatrix::<f64>::from_row_slice(2, 2, &[1.0, 2.0, 1.0, -1.0]);
        let c = (j.transpose() * &j).try_inverse().unwrap();
        let rho = c[(0, 1)] / (c[(0, 0)] * c[(1, 1)]).sqrt();
        assert!((r.correlation[0][1] - rho).abs() < 1e-12);
        assert!(r.unidentified.is_empty());
        assert_eq!(r.correlated_pairs.len(), usize::from(rho.abs() > 0.5));

        // N = 1 < p = 2: only θ0 + θ1 is determined.
        let r = analyse(&[vec![3.0, 3.0]], 0.1, 0.95);
        assert!(r.sigma2.is_nan());
        assert_eq!(r.rank, 1);
        assert_eq!(r.unidentified, vec![0, 1]);
        assert!(r.std_errors.iter().all(|v| *v == f64::INFINITY));
        assert_eq!(r.correlated_pairs.len(), 1);
        assert!((r.correlated_pairs[0].2 + 1.0).abs() < 1e-12);
    }

    #[test]
    fn invalid_input_never_panics() {
        let good = vec![vec![1.0, 0.0], vec![1.0, 1.0], vec![1.0, 2.0]];
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let mut jac = good.clone();
            jac[1][0] = bad;
            let r = analyse(&jac, 1.0, 0.95);
            assert_eq!(r.rank, 0);
            assert!(r.std_errors.iter().all(|v| v.is_nan()));
            assert!(r.correlation.iter().flatten().all(|v| v.is_nan()));
            assert!(r.condition.is_nan());
            assert!(r.correlated_pairs.is_empty());
            assert_eq!(r.unidentified, vec![0, 1]);
        }
        // NaN / negative RSS: σ² unknown, structure still analysed.
        for rss in [f64::NAN, -1.0, f64::INFINITY] {
            let r = analyse(&good, rss, 0.95);
            assert!(r.sigma2.is_nan());
            assert!(r.std_errors.iter().all(|v| v.is_nan()));
            assert_eq!(r.rank, 2);
            assert!(r.correlation[0][1].is_finite());
        }
        // Ragged rows, empty input, all-zero Jacobian, NaN threshold.
        let r = analyse(&[vec![1.0, 2.0], vec![1.0]], 1.0, 0.95);
        assert_eq!((r.rank, r.unidentified.len()), (0, 2));
        let r = analyse(&[], 1.0, 0.95);
        assert!(r.std_errors.is_empty() && r.correlation.is_empty() && r.rank == 0);
        let r = analyse(&vec![vec![0.0; 3]; 5], 1.0, 0.95);
        assert_eq!(r.rank, 0);
        assert_eq!(r.unidentified, vec![0, 1, 2]);
        assert!(r.std_errors.iter().all(|v| *v == f64::INFINITY));
        assert!(r.correlated_pairs.is_empty());
        let r = analyse(&good, 1.0, f64::NAN);
        assert!(r.correlated_pairs.is_empty() && r.rank == 2);
    }

    #[test]
    fn random_degenerate_inputs_keep_invariants() {
        let mut rng = Rng::new(77);
        let pick = |rng: &mut Rng| -> f64 {
            match rng.next_u64() % 10 {
                0 => 0.0,
                1 => 1.0,
                2 => -1.0,
                3 => 1e200 * rng.sample(),
                4 => 1e-200 * rng.sample(),
                5 if rng.next_u64().is_multiple_of(20) => f64::NAN,
                _ => rng.sample(),
            }
        };
        for _ in 0..2000 {
            let n = (rng.next_u64() % 7) as usize;
            let p = 1 + (rng.next_u64() % 5) as usize;
            let mut jac: Vec<Vec<f64>> = (0..n)
                .map(|_| (0..p).map(|_| pick(&mut rng)).collect())
                .collect();
            if p > 1 && n > 0 && rng.next_u64().is_multiple_of(3) {
                // Duplicate (possibly scaled) column.
                let f = pick(&mut rng);
                for row in &mut jac {
                    row[p - 1] = f * row[0];
                }
            }
            let r = analyse(&jac, pick(&mut rng).abs(), 0.9);
            if n == 0 {
                assert!(r.std_errors.is_empty());
                continue;
            }
            assert_eq!(r.std_errors.len(), p);
            assert!(r.rank <= n.min(p));
            assert!(r.unidentified.windows(2).all(|w| w[0] < w[1]));
            assert!(r.std_errors.iter().all(|v| v.is_nan() || *v >= 0.0));
            for i in 0..p {
                for j in 0..p {
                    let (a, b) = (r.correlation[i][j], r.correlation[j][i]);
                    assert!((a.is_nan() && b.is_nan()) || (a == b && a.abs() <= 1.0));
                }
            }
            for &(i, j, rho) in &r.correlated_pairs {
                assert!(i < j && j < p && rho.abs() > 0.9 && rho.abs() <= 1.0);
            }
            if r.rank == p {
                assert!(r.unidentified.is_empty() && r.condition.is_finite());
            }
        }
    }

    /// Gauss–Newton fit of y = a·exp(−b t); returns (θ̂, Jacobian rows, RSS).
    fn fit_exp(t: &[f64], y: &[f64], start: [f64; 2]) -> ([f64; 2], Vec<Vec<f64>>, f64) {
        let [mut a, mut b] = start;
        let jacobian = |a: f64, b: f64| -> Vec<Vec<f64>> {
            t.iter()
                .map(|&tk| {
                    let e = (-b * tk).exp();
                    vec![e, -a * tk * e]
                })
                .collect()
        };
        for _ in 0..100 {
            let jac = jacobian(a, b);
            // Normal equations (JᵀJ) δ = −Jᵀr, r = model − y.
            let (mut m00, mut m01, mut m11, mut g0, mut g1) = (0.0, 0.0, 0.0, 0.0, 0.0);
            for ((row, &tk), &yk) in jac.iter().zip(t).zip(y) {
                let r = a * (-b * tk).exp() - yk;
                m00 += row[0] * row[0];
                m01 += row[0] * row[1];
                m11 += row[1] * row[1];
                g0 += row[0] * r;
                g1 += row[1] * r;
            }
            let det = m00 * m11 - m01 * m01;
            let da = -(m11 * g0 - m01 * g1) / det;
            let db = -(m00 * g1 - m01 * g0) / det;
            a += da;
            b += db;
            if da.abs() < 1e-13 * a.abs() && db.abs() < 1e-13 * b.abs() {
                break;
            }
        }
        let rss = t
            .iter()
            .zip(y)
            .map(|(&tk, &yk)| (a * (-b * tk).exp() - yk).powi(2))
            .sum();
        ([a, b], jacobian(a, b), rss)
    }

    #[test]
    fn monte_carlo_spread_matches_analysed_std_error() {
        let (a_true, b_true, sigma) = (2.0, 0.7, 0.05);
        let t: Vec<f64> = (0..60).map(|k| 0.1 * k as f64).collect();
        let mut rng = Rng::new(2024);
        let draws = 200;
        let (mut b_hats, mut a_hats, mut se_b, mut se_a) = (vec![], vec![], 0.0, 0.0);
        for _ in 0..draws {
            let y: Vec<f64> = t
                .iter()
                .map(|&tk| a_true * (-b_true * tk).exp() + sigma * rng.sample())
                .collect();
            let (theta, jac, rss) = fit_exp(&t, &y, [0.8 * a_true, 1.3 * b_true]);
            let r = analyse(&jac, rss, 0.95);
            assert_eq!(r.rank, 2);
            a_hats.push(theta[0]);
            b_hats.push(theta[1]);
            se_a += r.std_errors[0] / draws as f64;
            se_b += r.std_errors[1] / draws as f64;
        }
        let std = |v: &[f64]| {
            let m = v.iter().sum::<f64>() / v.len() as f64;
            (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
        };
        let (emp_b, emp_a) = (std(&b_hats), std(&a_hats));
        assert!(
            rel_err(emp_b, se_b) < 0.2,
            "empirical std(b) {emp_b} vs analysed {se_b}"
        );
        assert!(
            rel_err(emp_a, se_a) < 0.2,
            "empirical std(a) {emp_a} vs analysed {se_a}"
        );
        let mean_b = b_hats.iter().sum::<f64>() / draws as f64;
        assert!((mean_b - b_true).abs() < 3.0 * emp_b / (draws as f64).sqrt() + 1e-3);
    }
}

//! Cross-correlation of a residual with a played-back input over lags, with a band corrected
//! for autocorrelation and for the number of lags searched.

use serde::{Deserialize, Serialize};

use super::*;

/// Strongest cross-correlation between the residual and one played-back input.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CrossCorrelation {
    /// Input name.
    pub input: String,
    /// Lag `k` maximising `|ρ̂_ru(k)|`; positive means the residual follows the input `k` samples
    /// later (`r_t` resembles `u_{t−k}`).
    pub best_lag_samples: i64,
    /// `ρ̂_ru(k)` at the best lag (signed).
    pub correlation: f64,
    /// Significance threshold on `|ρ̂_ru|` (see [`cross_correlation`]).
    pub band: f64,
    /// `|correlation| > band`.
    pub significant: bool,
}

/// Two-sided standard-normal quantile `z` with `P(|Z| > z) = alpha`, by bisection on
/// `P(|Z| > z) = Q(½, z²/2)` ([`gamma_q`]).
pub(super) fn normal_two_sided_quantile(alpha: f64) -> f64 {
    let (mut lo, mut hi) = (0.0_f64, 40.0_f64);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if gamma_q(0.5, 0.5 * mid * mid) > alpha {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Strongest cross-correlation between a residual `r` and an input `u` over lags
/// `k = −max_lag..=max_lag` (clamped to `N − 2`):
///
/// `ρ̂_ru(k) = Σ_t (r_t − r̄)(u_{t−k} − ū) / √(Σ (r_t − r̄)² Σ (u_t − ū)²)`
///
/// (sum over the `t` where both exist; positive `k`: the residual follows the input).
///
/// The band accounts for two things a plain `1.96/√N` ignores, either of which would turn
/// independent series into false alarms:
/// * the autocorrelation of both series (Bartlett): `Var ρ̂_ru ≈ (1 + 2 Σ_{j=1}^{J} ρ̂_rr(j)
///   ρ̂_uu(j))/N` with `J = ⌊N/4⌋`, floored at `1/N`;
/// * the search over `m = 2·max_lag + 1` lags (Bonferroni): `z` with `P(|Z| > z) = 0.05/m`
///   (`z ≈ 3.35` for `m = 61`),
///
/// so `band = z √Var`, and `significant = |ρ̂_ru(k*)| > band`. A constant series gives
/// correlation 0, not significant.
pub fn cross_correlation(name: &str, r: &[f64], u: &[f64], max_lag: usize) -> CrossCorrelation {
    let n = r.len().min(u.len());
    let insignificant = CrossCorrelation {
        input: name.to_string(),
        best_lag_samples: 0,
        correlation: 0.0,
        band: 0.0,
        significant: false,
    };
    if n < 3 {
        return insignificant;
    }
    let center = |x: &[f64]| {
        let m = x[..n].iter().sum::<f64>() / n as f64;
        x[..n].iter().map(|v| v - m).collect::<Vec<f64>>()
    };
    let (rc, uc) = (center(r), center(u));
    let (sr, su) = (
        rc.iter().map(|v| v * v).sum::<f64>(),
        uc.iter().map(|v| v * v).sum::<f64>(),
    );
    let l = max_lag.min(n - 2) as i64;
    let nf = n as f64;
    let j = n / 4;
    let (ar, au) = (autocorrelation(r, j), autocorrelation(u, j));
    let var =
        ((1.0 + 2.0 * ar.iter().zip(&au).map(|(a, b)| a * b).sum::<f64>()) / nf).max(1.0 / nf);
    let z = normal_two_sided_quantile(0.05 / (2 * l + 1) as f64);
    let band = z * var.sqrt();
    if !(sr > 0.0 && su > 0.0) {
        return CrossCorrelation {
            band,
            ..insignificant
        };
    }
    let norm = (sr * su).sqrt();
    let mut best = (0_i64, 0.0_f64);
    for k in -l..=l {
        let mut s = 0.0;
        for t in 0..n as i64 {
            let tu = t - k;
            if tu >= 0 && tu < n as i64 {
                s += rc[t as usize] * uc[tu as usize];
            }
        }
        let c = s / norm;
        if c.abs() > best.1.abs() {
            best = (k, c);
        }
    }
    CrossCorrelation {
        input: name.to_string(),
        best_lag_samples: best.0,
        correlation: best.1,
        band,
        significant: best.1.abs() > band,
    }
}

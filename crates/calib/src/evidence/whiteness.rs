//! Whiteness of a residual: sample autocorrelation, the Ljung-Box portmanteau test and the
//! χ² tail (incomplete gamma function) it needs.

use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// Whiteness of the residual: sample autocorrelation and the Ljung-Box portmanteau test.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Whiteness {
    /// Number of lags `h` used (the requested number, clamped to `N − 1`).
    pub lags: usize,
    /// Sample autocorrelation `ρ̂_k` for lags `k = 1..=h`.
    pub acf: Vec<f64>,
    /// Approximate 95 % band for white noise, `1.96/√N`.
    pub band: f64,
    /// Number of lags with `|ρ̂_k| > band` (about 5 % of `h` expected for white noise).
    pub outside_band: usize,
    /// Ljung-Box statistic `Q = N(N+2) Σ_{k=1}^{h} ρ̂_k²/(N−k)`.
    pub ljung_box_q: f64,
    /// `P(χ²_h > Q)`.
    pub p_value: f64,
    /// `p_value >= 0.05`.
    pub white: bool,
}

/// Sample autocorrelation for lags `1..=lags`:
///
/// `ρ̂_k = Σ_{t=k}^{N−1} (x_t − x̄)(x_{t−k} − x̄) / Σ_{t=0}^{N−1} (x_t − x̄)²`
///
/// (the biased estimator, as in Box-Jenkins). All zeros for a constant series.
pub fn autocorrelation(x: &[f64], lags: usize) -> Vec<f64> {
    let n = x.len();
    if n == 0 {
        return vec![0.0; lags];
    }
    let mean = x.iter().sum::<f64>() / n as f64;
    let c: Vec<f64> = x.iter().map(|v| v - mean).collect();
    let c0: f64 = c.iter().map(|v| v * v).sum();
    (1..=lags)
        .map(|k| {
            if c0 <= 0.0 || k >= n {
                0.0
            } else {
                (k..n).map(|i| c[i] * c[i - k]).sum::<f64>() / c0
            }
        })
        .collect()
}

/// Ljung-Box portmanteau test of whiteness with `h = lags` lags:
///
/// `Q = N(N+2) Σ_{k=1}^{h} ρ̂_k² / (N − k)`, `p = P(χ²_h > Q) = Γ(h/2, Q/2)/Γ(h/2)`
///
/// ([`autocorrelation`] for `ρ̂_k`, [`chi_square_sf`] for the tail). Returns `(Q, p)`;
/// `lags` is clamped to `N − 1`, and `(0, 1)` is returned when no lag is available.
/// With residuals of a fitted model, the `h` degrees of freedom are slightly too many
/// (the test is then a little conservative).
pub fn ljung_box(x: &[f64], lags: usize) -> (f64, f64) {
    let n = x.len();
    let h = lags.min(n.saturating_sub(1));
    if h == 0 {
        return (0.0, 1.0);
    }
    let acf = autocorrelation(x, h);
    let nf = n as f64;
    let q = nf
        * (nf + 2.0)
        * acf
            .iter()
            .enumerate()
            .map(|(i, r)| r * r / (nf - (i + 1) as f64))
            .sum::<f64>();
    (q, chi_square_sf(q, h as f64))
}

/// [`Whiteness`] of `x` with `lags` lags (clamped to `N − 1`): ACF, band `1.96/√N`, count outside
/// the band, Ljung-Box `Q` and p-value, `white = p ≥ 0.05`.
pub fn whiteness(x: &[f64], lags: usize) -> Whiteness {
    let n = x.len();
    let h = lags.min(n.saturating_sub(1));
    let acf = autocorrelation(x, h);
    let band = if n > 0 { 1.96 / (n as f64).sqrt() } else { 0.0 };
    let outside_band = acf.iter().filter(|r| r.abs() > band).count();
    let (q, p) = ljung_box(x, h);
    Whiteness {
        lags: h,
        acf,
        band,
        outside_band,
        ljung_box_q: q,
        p_value: p,
        white: p >= 0.05,
    }
}

/// `P(χ²_ν > x) = Q(ν/2, x/2)` (see [`gamma_q`]); 1 for `x ≤ 0`.
pub fn chi_square_sf(x: f64, dof: f64) -> f64 {
    if !(x > 0.0) {
        return 1.0;
    }
    gamma_q(0.5 * dof, 0.5 * x)
}

/// `ln Γ(a)` for `a > 0`, Lanczos approximation (`g = 7`, 9 coefficients, relative error
/// ~1e-15):
///
/// `Γ(z+1) = √(2π) (z + g + ½)^{z+½} e^{−(z+g+½)} A_g(z)`, with the reflection
/// `Γ(a)Γ(1−a) = π/sin(πa)` for `a < ½`.
pub fn ln_gamma(a: f64) -> f64 {
    const G: f64 = 7.0;
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if a < 0.5 {
        return (PI / (PI * a).sin()).ln() - ln_gamma(1.0 - a);
    }
    let z = a - 1.0;
    let mut s = C[0];
    for (i, c) in C.iter().enumerate().skip(1) {
        s += c / (z + i as f64);
    }
    let tt = z + G + 0.5;
    0.5 * (2.0 * PI).ln() + (z + 0.5) * tt.ln() - tt + s.ln()
}

/// Regularised upper incomplete gamma function `Q(a, x) = Γ(a, x)/Γ(a)`, `a > 0`.
///
/// For `x < a + 1` the series `P(a, x) = e^{−x} x^a / Γ(a) · Σ_{n≥0} xⁿ / (a(a+1)…(a+n))` and
/// `Q = 1 − P`; otherwise the continued fraction
/// `Q(a, x) = e^{−x} x^a / Γ(a) · 1/(x+1−a − 1·(1−a)/(x+3−a − 2·(2−a)/(x+5−a − …)))`
/// evaluated by the modified Lentz method (relative tolerance 1e-15).
/// Returns 1 for `x ≤ 0` and NaN for `a ≤ 0` or NaN input.
pub fn gamma_q(a: f64, x: f64) -> f64 {
    if !(a > 0.0) || x.is_nan() {
        return f64::NAN;
    }
    if x <= 0.0 {
        return 1.0;
    }
    if x.is_infinite() {
        return 0.0;
    }
    const EPS: f64 = 1e-15;
    const TINY: f64 = 1e-300;
    let prefactor = (-x + a * x.ln() - ln_gamma(a)).exp();
    if x < a + 1.0 {
        let mut ap = a;
        let mut term = 1.0 / a;
        let mut sum = term;
        for _ in 0..10_000 {
            ap += 1.0;
            term *= x / ap;
            sum += term;
            if term.abs() < sum.abs() * EPS {
                break;
            }
        }
        (1.0 - sum * prefactor).clamp(0.0, 1.0)
    } else {
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / TINY;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..10_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < TINY {
                d = TINY;
            }
            c = b + an / c;
            if c.abs() < TINY {
                c = TINY;
            }
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if (del - 1.0).abs() < EPS {
                break;
            }
        }
        (prefactor * h).clamp(0.0, 1.0)
    }
}

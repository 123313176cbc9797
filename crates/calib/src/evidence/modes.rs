//! Modes of a residual (frequency, damping, amplitude, phase) by the matrix pencil method.

use nalgebra::{Complex, DMatrix, DVector, Schur, SVD};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// One mode of the residual, `a e^{σt} cos(2π f t + φ)` (or `a e^{σt}` for a real mode).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Mode {
    /// Damped frequency `f = |Im s|/2π` (Hz); 0 for a non-oscillatory mode.
    pub freq_hz: f64,
    /// Damping ratio `ζ = −Re s/|s|` (negative when growing; ±1 for a real mode).
    pub damping_ratio: f64,
    /// Amplitude at the first sample: `2|R|` for a conjugate pair, `|R|` for a real mode.
    pub amplitude: f64,
    /// Phase `arg R` at the first sample (rad) (0 or π for a real mode).
    pub phase_rad: f64,
    /// Share of the fitted signal energy, `Σ_k x_k² / Σ_modes Σ_k x_k²` with `x_k` this mode's
    /// samples over the record.
    pub energy_share: f64,
}

/// Damping ratios a mode of a residual of a recorded, stable event can plausibly have: a
/// growing oscillation (ζ well below 0) or a non-oscillatory term fitted as a mode (|ζ| near 1)
/// is an artefact of the fit, not a finding.
pub const PLAUSIBLE_ZETA: (f64, f64) = (-0.05, 0.95);

/// Lowest frequency of a mode shown as a finding [Hz]: below, a slow drift of the residual.
pub const FINDING_MIN_HZ: f64 = 0.1;

impl Mode {
    /// Whether the mode is a finding (an oscillation above [`FINDING_MIN_HZ`] with a
    /// plausible damping, [`PLAUSIBLE_ZETA`]): the one rule by which every report shows modes
    /// and the verdict cites them.
    pub fn is_finding(&self) -> bool {
        self.freq_hz.is_finite()
            && self.freq_hz > FINDING_MIN_HZ
            && self.damping_ratio > PLAUSIBLE_ZETA.0
            && self.damping_ratio < PLAUSIBLE_ZETA.1
    }
}

/// Largest pencil parameter used: the Hankel matrix has at most `MAX_PENCIL + 1` columns,
/// which bounds the SVD cost on long records.
pub(super) const MAX_PENCIL: usize = 400;

/// Singular values kept by the pencil must exceed this multiple of the median singular value
/// (see [`matrix_pencil`], step 2).
pub(super) const NOISE_EDGE: f64 = 3.0;

/// A real mode with `|s| · N dt` below this is a constant (bias) and gets `ζ = 0`.
pub(super) const CONSTANT_MODE: f64 = 1e-6;

/// Iteration cap of a decomposition of a matrix with `dim` columns: generous (the QR sweeps of
/// a well-posed matrix take a few per singular value), reached only on pathological input.
fn max_niter(dim: usize) -> usize {
    1000 + 200 * dim
}

/// Modes of `y_k ≈ Σ_i R_i z_i^k` (`z_i = e^{s_i dt}`), by the matrix pencil method
/// (Hua and Sarkar 1990; Sarkar and Pereira 1995).
///
/// 1. Hankel matrix `Y` (`(N−L) × (L+1)`), `Y_{jm} = y_{j+m}`, pencil parameter
///    `L = min(⌊N/3⌋, 400)` (`N/3 ≤ L ≤ N/2` is best for noise).
/// 2. SVD `Y = U Σ Vᵀ`; model order `M` = number of singular values with `σ_i > 10⁻³ σ_1`
///    and `σ_i > 3 median(σ)`, capped at `max_order` and at `L − 1` (at least 1). The second
///    condition is a noise edge: with white noise and few modes the median singular value is a
///    noise singular value, so noise directions are not fitted (on 1.3 Hz, ζ = 0.08 with noise
///    at 10 % of the amplitude it brings the RMS damping error from about 1.1 to 1.0 × the
///    Cramér-Rao bound); on noise-free data the median is at round-off and only the first
///    condition acts. `V'` = the first `M` right singular vectors (the signal subspace, which
///    contains the vectors `(1, z_i, …, z_i^L)`).
/// 3. `V₁'`, `V₂'` = `V'` without its last / first row; shift invariance gives
///    `V₂' c_i = z_i V₁' c_i`, so `z_i = eig(V₁'⁺ V₂')` (an `M × M` real matrix).
/// 4. `s_i = ln(z_i)/dt`; residues `R` by least squares on the complex Vandermonde system
///    `y_k = Σ_i R_i z_i^k`, `k = 0..N−1` (columns scaled to unit norm, solved by SVD).
/// 5. Conjugate pairs are reported once (the member with `Im s > 0`): `f = Im s/2π`,
///    `ζ = −Re s/|s|`, amplitude `2|R|`, phase `arg R`; a real `z > 0` is a non-oscillatory
///    mode with `f = 0`, `ζ = −sign(Re s)` (0 for a constant: `|s| N dt < 10⁻⁶`), amplitude `|R|` and phase 0 or π.
///    Modes at or above `0.95 ×` Nyquist (`f ≥ 0.95/(2dt)`, including real `z < 0`) are
///    dropped. Energy `E_i = Σ_k x_{i,k}²` with `x_{i,k}` the mode's real samples; modes are
///    sorted by decreasing `E_i` and `energy_share = E_i/Σ E`.
///
/// Time starts at the first sample: amplitude and phase refer to `y_0`. Returns an empty list
/// for `N < 6`, `max_order = 0`, or an all-zero signal. With noise and `M` at `max_order`, some
/// low-energy modes are noise; read the dominant ones.
pub fn matrix_pencil(y: &[f64], dt: f64, max_order: usize) -> Vec<Mode> {
    let n = y.len();
    // Non-finite samples: nalgebra's decompositions never converge on them (they spin).
    if n < 6
        || max_order == 0
        || !(dt > 0.0)
        || y.iter().all(|v| *v == 0.0)
        || !y.iter().all(|v| v.is_finite())
    {
        return Vec::new();
    }
    let l = (n / 3).clamp(2, MAX_PENCIL);
    let rows = n - l;
    let hankel = DMatrix::from_fn(rows, l + 1, |j, m| y[j + m]);
    // Every decomposition with an iteration cap (nalgebra's `svd`, `pseudo_inverse` and
    // `complex_eigenvalues` have none): only pathological input reaches it, and has no modes.
    let Some(svd) = SVD::try_new(hankel, false, true, f64::EPSILON, max_niter(l + 1)) else {
        return Vec::new();
    };
    let Some(v_t) = svd.v_t else {
        return Vec::new();
    };
    let sv = &svd.singular_values;
    let s1 = sv[0];
    if !(s1 > 0.0) {
        return Vec::new();
    }
    let mut sorted: Vec<f64> = sv.iter().copied().collect();
    sorted.sort_by(|a, b| a.total_cmp(b));
    let noise_edge = NOISE_EDGE * sorted[sorted.len() / 2];
    let m = sv
        .iter()
        .filter(|s| **s > 1e-3 * s1 && **s > noise_edge)
        .count()
        .min(max_order)
        .min(l - 1)
        .max(1);
    // V' is (L+1) × M: the first M rows of Vᵀ, transposed.
    let vp = v_t.rows(0, m).transpose();
    let v1 = vp.rows(0, l).into_owned();
    let v2 = vp.rows(1, l).into_owned();
    let Some(Ok(v1_pinv)) =
        SVD::try_new(v1, true, true, f64::EPSILON, max_niter(m)).map(|d| d.pseudo_inverse(1e-12))
    else {
        return Vec::new();
    };
    let a = v1_pinv * v2;
    let Some(schur) = Schur::try_new(a, f64::EPSILON, max_niter(m)) else {
        return Vec::new();
    };
    let z: Vec<Complex<f64>> = schur.complex_eigenvalues().iter().copied().collect();

    // Least-squares residues on the column-scaled Vandermonde matrix.
    let mut vand = DMatrix::<Complex<f64>>::zeros(n, m);
    let mut scale = vec![0.0; m];
    for (i, zi) in z.iter().enumerate() {
        let mut p = Complex::new(1.0, 0.0);
        for k in 0..n {
            vand[(k, i)] = p;
            p *= zi;
        }
        let norm = vand.column(i).norm();
        scale[i] = if norm > 0.0 && norm.is_finite() {
            norm
        } else {
            1.0
        };
        let s = scale[i];
        vand.column_mut(i).iter_mut().for_each(|c| *c /= s);
    }
    // A pole far outside the unit circle overflows its column (z^k beyond f64): no residues.
    if !vand.iter().all(|c| c.re.is_finite() && c.im.is_finite()) {
        return Vec::new();
    }
    let b = DVector::from_iterator(n, y.iter().map(|v| Complex::new(*v, 0.0)));
    let Some(Ok(sol)) =
        SVD::try_new(vand, true, true, f64::EPSILON, max_niter(m)).map(|d| d.solve(&b, 1e-12))
    else {
        return Vec::new();
    };
    let resid: Vec<Complex<f64>> = (0..m).map(|i| sol[i] / scale[i]).collect();

    let nyq = 0.5 / dt;
    let imag_tol = 1e-9;
    let mut modes: Vec<(Mode, f64)> = Vec::new();
    for i in 0..m {
        let zi = z[i];
        if !(zi.norm() > 0.0) || !zi.re.is_finite() || !zi.im.is_finite() {
            continue;
        }
        let s = Complex::new(zi.norm().ln(), zi.im.atan2(zi.re)) / dt;
        let r = resid[i];
        let pair = zi.im.abs() > imag_tol * zi.norm();
        if pair && zi.im < 0.0 {
            continue; // the conjugate with Im s > 0 reports the pair
        }
        if !pair && zi.re < 0.0 {
            continue; // real negative z: a mode at Nyquist
        }
        let freq = if pair { s.im / (2.0 * PI) } else { 0.0 };
        if freq >= 0.95 * nyq {
            continue;
        }
        let sn = s.norm();
        let constant = !pair && sn * n as f64 * dt < CONSTANT_MODE;
        let damping = if sn > 0.0 && !constant {
            -s.re / sn
        } else {
            0.0
        };
        let (amplitude, phase) = if pair {
            (2.0 * r.norm(), r.im.atan2(r.re))
        } else {
            (r.re.abs(), if r.re < 0.0 { PI } else { 0.0 })
        };
        // Energy of the mode's real samples x_k = 2 Re(R z^k) (pair) or R z^k (real).
        let mut e = 0.0;
        let mut p = r;
        let factor = if pair { 2.0 } else { 1.0 };
        for _ in 0..n {
            let xk = factor * p.re;
            e += xk * xk;
            p *= zi;
        }
        if !e.is_finite() {
            continue;
        }
        modes.push((
            Mode {
                freq_hz: freq,
                damping_ratio: damping,
                amplitude,
                phase_rad: phase,
                energy_share: 0.0,
            },
            e,
        ));
    }
    let total: f64 = modes.iter().map(|(_, e)| e).sum();
    modes.sort_by(|a, b| b.1.total_cmp(&a.1));
    modes
        .into_iter()
        .map(|(mut md, e)| {
            md.energy_share = if total > 0.0 { e / total } else { 0.0 };
            md
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A residual with a NaN or an infinite sample (a simulation that ran away between two
    /// checks) has no modes; the decompositions must neither panic nor spin on it.
    #[test]
    fn non_finite_samples_give_no_mode() {
        let dt = 1.0 / 60.0;
        let mut y: Vec<f64> = (0..300).map(|k| (0.3 * k as f64).sin()).collect();
        assert!(!matrix_pencil(&y, dt, 10).is_empty());
        for bad in [f64::NAN, f64::INFINITY] {
            y[100] = bad;
            assert!(matrix_pencil(&y, dt, 10).is_empty(), "{bad}");
        }
    }
}

//! Oscillatory content by frequency: the Hann-windowed amplitude spectrum and the resonance
//! (spectral peak) test.

use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

use super::*;

/// Single-sided amplitude spectrum of the (mean-removed, Hann-windowed) residual.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Spectrum {
    /// Bin frequencies `f_k = k/(N Δt)`, `k = 0..=N/2` (Hz).
    pub freq_hz: Vec<f64>,
    /// Amplitude of a sinusoid at `f_k` (coherent-gain corrected), same units as the signal.
    pub amplitude: Vec<f64>,
    /// Frequency of the largest non-DC bin, `None` when the spectrum is empty or zero.
    pub peak_hz: Option<f64>,
    /// Amplitude at `peak_hz` (0 when none).
    pub peak_amplitude: f64,
    /// Peak amplitude over the median non-DC amplitude (0 when undefined).
    pub peak_significance: f64,
}

/// The discrete Fourier transform of `x` at the bins `ks`, `X_k = Σ_m x_m e^{−2πi k m / N}`, as
/// `(re, im)`: direct sums over a table of the N twiddle factors (the bins asked for are few or
/// the records short, so no FFT is needed). Every `k` must be below N.
pub(super) fn dft(x: &[f64], ks: std::ops::RangeInclusive<usize>) -> Vec<(f64, f64)> {
    let n = x.len();
    let (cos, sin): (Vec<f64>, Vec<f64>) = (0..n)
        .map(|m| (2.0 * PI * m as f64 / n as f64).sin_cos())
        .map(|(s, c)| (c, s))
        .unzip();
    ks.map(|k| {
        let (mut re, mut im) = (0.0, 0.0);
        let mut idx = 0usize;
        for xi in x {
            re += xi * cos[idx];
            im -= xi * sin[idx];
            idx += k;
            if idx >= n {
                idx -= n;
            }
        }
        (re, im)
    })
    .collect()
}

/// Single-sided amplitude spectrum of `y` sampled every `dt` seconds.
///
/// The mean is removed, the Hann window `w_n = ½(1 − cos(2πn/(N−1)))` applied, and the plain
/// DFT `X_k = Σ_n w_n (y_n − ȳ) e^{−2πikn/N}` evaluated for `k = 0..=⌊N/2⌋` (exact twiddle
/// table, `O(N²)`). The amplitude is corrected for the window's coherent gain so that a
/// sinusoid of amplitude `A` on a bin reads `A`:
///
/// `A_k = 2|X_k| / Σ_n w_n` (`|X_k| / Σ w_n` at `k = 0` and at the Nyquist bin),
/// `f_k = k/(N dt)`.
///
/// The peak is the largest bin with `k ≥ 1`; `peak_significance = A_peak / median_{k≥1} A_k`.
/// Empty output for `N < 2`.
pub fn spectrum(y: &[f64], dt: f64) -> Spectrum {
    let n = y.len();
    let empty = Spectrum {
        freq_hz: Vec::new(),
        amplitude: Vec::new(),
        peak_hz: None,
        peak_amplitude: 0.0,
        peak_significance: 0.0,
    };
    if n < 2 {
        return empty;
    }
    let mean = y.iter().sum::<f64>() / n as f64;
    let w: Vec<f64> = (0..n)
        .map(|i| 0.5 * (1.0 - (2.0 * PI * i as f64 / (n - 1) as f64).cos()))
        .collect();
    let wsum: f64 = w.iter().sum();
    let x: Vec<f64> = y.iter().zip(&w).map(|(v, wi)| (v - mean) * wi).collect();
    let half = n / 2;
    let mut freq_hz = Vec::with_capacity(half + 1);
    let mut amplitude = Vec::with_capacity(half + 1);
    for (k, (re, im)) in (0..=half).zip(dft(&x, 0..=half)) {
        let edge = k == 0 || 2 * k == n;
        let scale = if edge { 1.0 } else { 2.0 };
        freq_hz.push(k as f64 / (n as f64 * dt));
        amplitude.push(scale * (re * re + im * im).sqrt() / wsum);
    }
    let mut peak_k = None;
    let mut peak_amplitude = 0.0;
    for (k, &a) in amplitude.iter().enumerate().skip(1) {
        if a > peak_amplitude {
            peak_amplitude = a;
            peak_k = Some(k);
        }
    }
    let mut rest: Vec<f64> = amplitude[1..].to_vec();
    rest.sort_by(|a, b| a.total_cmp(b));
    let median = if rest.is_empty() {
        0.0
    } else {
        0.5 * (rest[(rest.len() - 1) / 2] + rest[rest.len() / 2])
    };
    Spectrum {
        peak_hz: peak_k.map(|k| freq_hz[k]),
        peak_amplitude,
        peak_significance: if median > 0.0 {
            peak_amplitude / median
        } else {
            0.0
        },
        freq_hz,
        amplitude,
    }
}

/// A resonance in a residual's spectrum: the test for a persistent oscillation that the model
/// has no state for. A torsional mode kept ringing by random turbine torque is such a
/// resonance; a deterministic playback cannot reproduce it and a re-fit cannot fit it, but it
/// stands out of the flat spectrum of the measurement noise.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SpectralPeak {
    /// Power-weighted mean frequency of the window with the most excess power [Hz].
    pub freq_hz: f64,
    /// Mean periodogram over that window, over the band's background level.
    pub ratio: f64,
    /// Natural frequency bins averaged in one window.
    pub window_bins: usize,
    /// Windows searched (band width over window width).
    pub windows: usize,
    /// Mean periodogram over the window, over the larger of the means over the two windows
    /// one window-width away on either side: a resonance stands out of its neighbourhood,
    /// the shoulder of a low-frequency misfit leaking into the band does not.
    pub prominence: f64,
    /// Probability that noise alone gives such a window somewhere in the band:
    /// `min(1, windows · Q(K, K·ratio))` with `K = window_bins`.
    pub p_value: f64,
}

/// Width of the window a resonance is averaged over [Hz]: the electrical damping of a
/// played-back machine widens a shaft mode to a few tenths of a hertz.
pub const PEAK_WINDOW_HZ: f64 = 0.5;

/// The window of width [`PEAK_WINDOW_HZ`] with the most power of `y` (sampled every `dt`)
/// between `f_lo` and `f_hi` Hz, against the band's background.
///
/// 1. Periodogram `I_k = |Σ_n (y_n − ȳ) e^{−2πikn/N}|²` on the natural bins `f_k = k/(N dt)`
///    (rectangular window: the bins of white noise are then independent).
/// 2. Background: the median of `I_k` over the band divided by `ln 2`. For a flat (white)
///    spectrum `I_k` is exponential and its median is `ln 2` times its mean; the median is not
///    moved by a resonance that covers a small part of the band.
/// 3. The mean of `I_k` over each window of `K` bins, over the background: under the null it is
///    Gamma(K, 1/K), so `P(ratio > x) = Q(K, K x)` (regularised upper incomplete gamma); over
///    the band's `M = (f_hi − f_lo) / window` windows, the chance that noise alone gives such a
///    window anywhere is at most `M · Q(K, K x)` (Bonferroni over the disjoint windows, which
///    the sliding maximum exceeds only slightly).
///
/// `None` when the band holds fewer than two windows or the series is constant.
pub fn spectral_peak(y: &[f64], dt: f64, f_lo: f64, f_hi: f64) -> Option<SpectralPeak> {
    let n = y.len();
    if n < 8 || !(dt > 0.0) {
        return None;
    }
    let t_rec = n as f64 * dt;
    let f_hi = f_hi.min(0.5 / dt);
    let k_lo = (f_lo * t_rec).ceil().max(1.0) as usize;
    let k_hi = (f_hi * t_rec).floor() as usize;
    let window = ((PEAK_WINDOW_HZ * t_rec).round() as usize).max(2);
    if k_hi < k_lo + 2 * window {
        return None;
    }
    let mean = y.iter().sum::<f64>() / n as f64;
    let x: Vec<f64> = y.iter().map(|v| v - mean).collect();
    // The band and two window-widths either side (for the neighbourhood of a window).
    let e_lo = k_lo.saturating_sub(2 * window).max(1);
    let e_hi = (k_hi + 2 * window).min(n / 2);
    let ext: Vec<f64> = dft(&x, e_lo..=e_hi)
        .into_iter()
        .map(|(re, im)| re * re + im * im)
        .collect();
    let power = &ext[k_lo - e_lo..=k_hi - e_lo];
    let mut sorted = power.to_vec();
    sorted.sort_by(|a, b| a.total_cmp(b));
    let background = sorted[sorted.len() / 2] / std::f64::consts::LN_2;
    if !(background > 0.0) {
        return None;
    }
    let mut best: Option<(usize, f64)> = None;
    let mut sum: f64 = power[..window].iter().sum();
    for start in 0..=power.len() - window {
        if start > 0 {
            sum += power[start + window - 1] - power[start - 1];
        }
        let ratio = sum / window as f64 / background;
        if best.is_none_or(|(_, r)| ratio > r) {
            best = Some((start, ratio));
        }
    }
    let (start, ratio) = best?;
    // Neighbourhood: the windows [start − 2W, start − W) and [end + W, end + 2W) (in `ext`).
    let at = k_lo - e_lo + start;
    let mean_of = |a: isize, b: isize| -> f64 {
        let (a, b) = (a.max(0) as usize, (b.max(0) as usize).min(ext.len()));
        if b > a {
            ext[a..b].iter().sum::<f64>() / (b - a) as f64
        } else {
            0.0
        }
    };
    let (w, at_i) = (window as isize, at as isize);
    let neighbours = mean_of(at_i - 2 * w, at_i - w).max(mean_of(at_i + 2 * w, at_i + 3 * w));
    let seg = &power[start..start + window];
    let total: f64 = seg.iter().sum();
    let freq_hz = seg
        .iter()
        .enumerate()
        .map(|(i, p)| (k_lo + start + i) as f64 / t_rec * p)
        .sum::<f64>()
        / total;
    let windows = power.len() / window;
    let kf = window as f64;
    Some(SpectralPeak {
        freq_hz,
        ratio,
        window_bins: window,
        windows,
        prominence: if neighbours > 0.0 {
            ratio * background / neighbours
        } else {
            f64::INFINITY
        },
        p_value: (windows as f64 * gamma_q(kf, kf * ratio)).min(1.0),
    })
}

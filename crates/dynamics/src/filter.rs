//! Zero-phase low-pass filtering of uniformly sampled measurement signals.
//!
//! The source papers low-pass the PMU active and reactive power (P, Q) at 15 Hz
//! before fitting, so that measurement noise and fast transients the model does
//! not represent do not drive the calibration. [`lowpass_zero_phase`] reproduces
//! that step without shifting events in time: a 2nd-order Butterworth biquad is
//! run forward and then backward over the record (the "filtfilt" scheme). The
//! played-back terminal voltage is smoothed with it too, between its switching
//! edges ([`crate::event::smoothing`]).
//!
//! # Conventions and units
//!
//! * Frequencies are in hertz (Hz); sample times in seconds (s).
//! * Signals are plain `&[f64]` slices sampled uniformly at `sample_rate_hz`;
//!   use [`sample_rate`] to obtain (and check) the rate from a time column.
//! * The output has the same length and units as the input.
//!
//! # Filter design
//!
//! The analogue prototype is the normalised 2nd-order Butterworth low-pass
//! `H(s) = 1 / (s² + √2·s + 1)`. It is mapped to the z-plane by the bilinear
//! transform with frequency pre-warping, so that the digital filter has its
//! −3 dB point (|H| = 1/√2) exactly at `cutoff_hz`. With
//! `K = tan(π·fc/fs)` and `n = 1 / (1 + √2·K + K²)`:
//!
//! ```text
//! b0 = K²·n,  b1 = 2·b0,  b2 = b0
//! a0 = 1,     a1 = 2·(K² − 1)·n,  a2 = (1 − √2·K + K²)·n
//! y[k] = b0·x[k] + b1·x[k−1] + b2·x[k−2] − a1·y[k−1] − a2·y[k−2]
//! ```
//!
//! These are the coefficients `scipy.signal.butter(2, fc, fs=fs)` returns.
//! The single-pass magnitude is `|H(f)| = 1/sqrt(1 + (tan(π f/fs)/tan(π fc/fs))⁴)`.
//!
//! # Zero phase, forward–backward
//!
//! Filtering forward and then backward in time gives the overall response
//! `|H(f)|²` with **zero phase**: the magnitude response is that of a
//! 4th-order filter (attenuation in dB doubled, −6.02 dB at `fc`), and edges,
//! peaks and steps stay at their original time stamps. The price is that the
//! filter is non-causal (it needs the whole record), which is fine for offline
//! calibration.
//!
//! # Edge handling (as `scipy.signal.filtfilt` with its defaults)
//!
//! * The record is extended at both ends by `PAD_LEN = 3·(order + 1) = 9`
//!   samples of odd (point-reflection) padding: `x[-k] = 2·x[0] − x[k]` and
//!   `x[n−1+k] = 2·x[n−1] − x[n−1−k]`, which continues the local trend.
//! * Each pass starts from the filter's steady-state initial conditions for a
//!   constant input equal to the first sample of that pass (`lfilter_zi`
//!   scaled by the first sample), so a constant signal passes unchanged and a
//!   record that starts at an offset produces no start-up transient. (It is
//!   implemented as filtering the deviation from that first sample from a zero
//!   state, which is the same thing in exact arithmetic and makes the constant
//!   case bit-exact.)
//! * The input must be longer than `PAD_LEN` samples (as in scipy).

use std::f64::consts::{PI, SQRT_2};
use std::fmt;

/// Butterworth order of one pass (the forward–backward result has twice this order).
pub const ORDER: usize = 2;

/// Samples of odd padding added at each end, `3·(ORDER + 1)` as in scipy's `filtfilt`.
pub const PAD_LEN: usize = 3 * (ORDER + 1);

/// Relative tolerance on sample spacing accepted by [`sample_rate`] (1 %).
pub const SPACING_TOLERANCE: f64 = 0.01;

/// Errors of the filtering helpers.
#[derive(Debug, Clone, PartialEq)]
pub enum FilterError {
    /// Fewer samples than the operation needs (`len` given, at least `min` required).
    TooShort {
        /// Number of samples supplied.
        len: usize,
        /// Minimum number of samples required.
        min: usize,
    },
    /// Time stamps that are not uniformly spaced (within [`SPACING_TOLERANCE`]),
    /// not increasing, or not finite.
    NonUniform {
        /// Index `i` of the offending step `t[i+1] − t[i]`.
        index: usize,
        /// That step, in seconds (NaN if a time stamp is not finite).
        dt: f64,
        /// Mean step `(t[n−1] − t[0])/(n − 1)`, in seconds.
        mean_dt: f64,
    },
    /// Cut-off frequency outside `0 < cutoff_hz < sample_rate_hz/2`, or a
    /// sample rate that is not a positive finite number.
    BadCutoff {
        /// Requested cut-off frequency, Hz.
        cutoff_hz: f64,
        /// Sample rate, Hz (the Nyquist frequency is half of it).
        sample_rate_hz: f64,
    },
}

impl fmt::Display for FilterError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FilterError::TooShort { len, min } => write!(
                f,
                "signal too short for filtering: {len} samples, at least {min} required"
            ),
            FilterError::NonUniform { index, dt, mean_dt } => write!(
                f,
                "time stamps not uniformly spaced: step {index} is {dt} s, mean step is {mean_dt} s \
                 (tolerance {} %)",
                SPACING_TOLERANCE * 100.0
            ),
            FilterError::BadCutoff {
                cutoff_hz,
                sample_rate_hz,
            } => write!(
                f,
                "low-pass cut-off {cutoff_hz} Hz is invalid for sample rate {sample_rate_hz} Hz: \
                 need 0 < cut-off < Nyquist = {} Hz",
                sample_rate_hz / 2.0
            ),
        }
    }
}

impl std::error::Error for FilterError {}

/// A second-order IIR section `H(z) = (b0 + b1 z⁻¹ + b2 z⁻²) / (1 + a1 z⁻¹ + a2 z⁻²)`
/// (`a[0]` is always 1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Biquad {
    /// Numerator coefficients `[b0, b1, b2]`.
    pub b: [f64; 3],
    /// Denominator coefficients `[1, a1, a2]`.
    pub a: [f64; 3],
}

impl Biquad {
    /// 2nd-order Butterworth low-pass by the bilinear transform with pre-warping
    /// (see the module docs for the formulas).
    ///
    /// # Errors
    ///
    /// [`FilterError::BadCutoff`] unless `sample_rate_hz` is finite and positive
    /// and `0 < cutoff_hz < sample_rate_hz / 2`.
    pub fn butterworth_lowpass(sample_rate_hz: f64, cutoff_hz: f64) -> Result<Self, FilterError> {
        let ok = sample_rate_hz.is_finite()
            && sample_rate_hz > 0.0
            && cutoff_hz.is_finite()
            && cutoff_hz > 0.0
            && cutoff_hz < 0.5 * sample_rate_hz;
        if !ok {
            return Err(FilterError::BadCutoff {
                cutoff_hz,
                sample_rate_hz,
            });
        }
        // Pre-warped analogue cut-off, normalised by 2·fs: K = tan(π fc / fs).
        let k = (PI * cutoff_hz / sample_rate_hz).tan();
        let k2 = k * k;
        let norm = 1.0 / (1.0 + SQRT_2 * k + k2);
        let b0 = k2 * norm;
        Ok(Biquad {
            b: [b0, 2.0 * b0, b0],
            a: [1.0, 2.0 * (k2 - 1.0) * norm, (1.0 - SQRT_2 * k + k2) * norm],
        })
    }

    /// Magnitude `|H(e^{j 2π f/fs})|` of one pass at frequency `f_hz`.
    #[must_use]
    pub fn gain_at(&self, f_hz: f64, sample_rate_hz: f64) -> f64 {
        let w = 2.0 * PI * f_hz / sample_rate_hz;
        // Evaluate the polynomials in z⁻¹ = e^{-jw}.
        let eval = |c: &[f64; 3]| {
            let re = c[0] + c[1] * w.cos() + c[2] * (2.0 * w).cos();
            let im = -c[1] * w.sin() - c[2] * (2.0 * w).sin();
            re.hypot(im)
        };
        eval(&self.b) / eval(&self.a)
    }

    /// Steady-state gain `H(1) = Σb / Σa` (1 for the low-pass, up to rounding).
    #[must_use]
    pub fn dc_gain(&self) -> f64 {
        (self.b[0] + self.b[1] + self.b[2]) / (self.a[0] + self.a[1] + self.a[2])
    }

    /// Runs the section over `x` in place (transposed direct form II), starting
    /// in the steady state for a constant input equal to `x[0]`.
    ///
    /// Implemented as `y = x[0] + H(x − x[0])` with zero initial state. By
    /// linearity this is scipy's `lfilter(b, a, x, zi = lfilter_zi(b, a)·x[0])`
    /// with the DC gain taken as exactly 1 (the ideal low-pass) rather than the
    /// rounded coefficients' `Σb/Σa`, which differs from 1 by up to ~1e-11 at very
    /// low `fc/fs`. A constant then passes bit-exactly, and the recursion's
    /// rounding errors scale with the signal's excursions from `x[0]` rather than
    /// with its offset (e.g. a 700 MW operating point with ±5 MW swings).
    fn run_in_place(&self, x: &mut [f64]) {
        let Some(&x0) = x.first() else { return };
        let [b0, b1, b2] = self.b;
        let [_, a1, a2] = self.a;
        let (mut z1, mut z2) = (0.0, 0.0);
        for v in x.iter_mut() {
            let xin = *v - x0;
            let y = b0 * xin + z1;
            z1 = b1 * xin - a1 * y + z2;
            z2 = b2 * xin - a2 * y;
            *v = y + x0;
        }
    }
}

/// Zero-phase Butterworth low-pass (order 2, applied forward and backward, so
/// effective order 4 and zero phase) of a uniformly sampled signal.
///
/// * `x` — samples, any unit; must have more than [`PAD_LEN`] (= 9) samples,
///   otherwise [`FilterError::TooShort`].
/// * `sample_rate_hz` — sampling rate `fs` in Hz (see [`sample_rate`]).
/// * `cutoff_hz` — −3 dB frequency of **one** pass, `0 < fc < fs/2`, otherwise
///   [`FilterError::BadCutoff`]. The forward–backward result has magnitude
///   `|H(f)|²`, i.e. −6.02 dB at `fc`, and zero phase at every frequency.
///
/// Edges are treated as scipy's `filtfilt(b, a, x)` does with its defaults
/// (odd padding of [`PAD_LEN`] samples, steady-state initial conditions), so a
/// constant signal is returned unchanged and the result agrees with
/// `filtfilt(*butter(2, fc, fs=fs), x)` to rounding. Non-finite samples
/// propagate (NaN in gives NaN out); they are not an error.
///
/// # Errors
///
/// [`FilterError::BadCutoff`] for an invalid `cutoff_hz`/`sample_rate_hz`
/// (checked first), [`FilterError::TooShort`] if `x.len() <= PAD_LEN`.
pub fn lowpass_zero_phase(
    x: &[f64],
    sample_rate_hz: f64,
    cutoff_hz: f64,
) -> Result<Vec<f64>, FilterError> {
    lowpass_zero_phase_padded(x, sample_rate_hz, cutoff_hz, PAD_LEN)
}

/// [`lowpass_zero_phase`] with `pad` samples of odd padding at each end instead of
/// [`PAD_LEN`]. The odd padding continues a linear trend, but each pass starts from the state of
/// a constant, so a trend leaves a start-up transient (the filter's lag of the trend) that decays
/// as `exp(−ζ ω_c t)`, `ζ = 1/√2`: after scipy's 9 samples a 4 Hz cut-off at 60 samples/s has
/// only reached 7 % of it. A padding of `3 fs/f_c` samples takes it below 2e-6.
///
/// # Errors
/// As [`lowpass_zero_phase`], with `x.len() <= pad` too short.
pub fn lowpass_zero_phase_padded(
    x: &[f64],
    sample_rate_hz: f64,
    cutoff_hz: f64,
    pad: usize,
) -> Result<Vec<f64>, FilterError> {
    let section = Biquad::butterworth_lowpass(sample_rate_hz, cutoff_hz)?;
    let n = x.len();
    if n <= pad {
        return Err(FilterError::TooShort {
            len: n,
            min: pad + 1,
        });
    }

    // Odd extension: [2x0 − x[pad..1], x, 2x[n−1] − x[n−2..n−1−pad]].
    let mut ext = Vec::with_capacity(n + 2 * pad);
    let (first, last) = (x[0], x[n - 1]);
    ext.extend((1..=pad).rev().map(|k| 2.0 * first - x[k]));
    ext.extend_from_slice(x);
    ext.extend((1..=pad).map(|k| 2.0 * last - x[n - 1 - k]));

    // Forward pass, then backward pass (reverse, filter, reverse).
    section.run_in_place(&mut ext);
    ext.reverse();
    section.run_in_place(&mut ext);
    ext.reverse();

    Ok(ext[pad..pad + n].to_vec())
}

/// Sampling rate in Hz of the time stamps `t` (seconds), `1 / mean(dt)` with
/// `mean(dt) = (t[n−1] − t[0]) / (n − 1)`.
///
/// PMU time stamps jitter slightly, so each step `t[i+1] − t[i]` may deviate
/// from the mean step by up to [`SPACING_TOLERANCE`] (1 %) of it; a larger
/// deviation is an error.
///
/// # Errors
///
/// [`FilterError::NonUniform`] (with the first offending step) for a step off
/// the mean by more than 1 %, or a non-increasing or non-finite time column;
/// [`FilterError::TooShort`] for fewer than two samples.
pub fn sample_rate(t: &[f64]) -> Result<f64, FilterError> {
    let n = t.len();
    if n < 2 {
        return Err(FilterError::TooShort { len: n, min: 2 });
    }
    let mean_dt = (t[n - 1] - t[0]) / (n - 1) as f64;
    if !(mean_dt.is_finite() && mean_dt > 0.0) {
        return Err(FilterError::NonUniform {
            index: 0,
            dt: t[1] - t[0],
            mean_dt,
        });
    }
    for (i, w) in t.windows(2).enumerate() {
        let dt = w[1] - w[0];
        if dt.is_nan() || (dt - mean_dt).abs() > SPACING_TOLERANCE * mean_dt {
            return Err(FilterError::NonUniform {
                index: i,
                dt,
                mean_dt,
            });
        }
    }
    Ok(1.0 / mean_dt)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Least-squares amplitude and phase of the component at `f` in `y[range]`.
    fn fit_sine(y: &[f64], fs: f64, f: f64, range: std::ops::Range<usize>) -> (f64, f64) {
        // Fit y ≈ c·cos(wt) + s·sin(wt) by the 2x2 normal equations.
        let w = 2.0 * PI * f / fs;
        let (mut cc, mut ss, mut cs, mut yc, mut ys) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for k in range {
            let (c, s) = ((w * k as f64).cos(), (w * k as f64).sin());
            cc += c * c;
            ss += s * s;
            cs += c * s;
            yc += y[k] * c;
            ys += y[k] * s;
        }
        let det = cc * ss - cs * cs;
        let c = (yc * ss - ys * cs) / det;
        let s = (ys * cc - yc * cs) / det;
        (c.hypot(s), c.atan2(s))
    }

    fn sine(n: usize, fs: f64, f: f64, amp: f64) -> Vec<f64> {
        (0..n)
            .map(|k| amp * (2.0 * PI * f * k as f64 / fs).sin())
            .collect()
    }

    #[test]
    fn coefficients_match_scipy_butter() {
        // scipy.signal.butter(2, 15, fs=50)
        let bq = Biquad::butterworth_lowpass(50.0, 15.0).unwrap();
        let b = [0.39133577250176854, 0.7826715450035371, 0.39133577250176854];
        let a = [1.0, 0.3695273773512411, 0.19581571265583297];
        for i in 0..3 {
            assert!(
                (bq.b[i] - b[i]).abs() < 1e-14,
                "b{i}: {} vs {}",
                bq.b[i],
                b[i]
            );
            assert!(
                (bq.a[i] - a[i]).abs() < 1e-14,
                "a{i}: {} vs {}",
                bq.a[i],
                a[i]
            );
        }
    }

    #[test]
    fn prewarping_puts_minus_3db_exactly_at_cutoff() {
        for &(fs, fc) in &[(50.0, 15.0), (100.0, 15.0), (1000.0, 15.0), (60.0, 29.0)] {
            let bq = Biquad::butterworth_lowpass(fs, fc).unwrap();
            assert!((bq.gain_at(fc, fs) - SQRT_2.recip()).abs() < 1e-12);
            assert!((bq.gain_at(0.0, fs) - 1.0).abs() < 1e-12);
            assert!((bq.dc_gain() - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn matches_scipy_filtfilt_reference() {
        // Reference: scipy 1.17.1,
        //   fs, fc = 50.0, 15.0; t = np.arange(40)/fs
        //   x = 1 + 0.3*t + np.sin(2*np.pi*3*t) + 0.5*np.sin(2*np.pi*20*t) + 0.2*np.cos(2*np.pi*11*t)
        //   y = filtfilt(*butter(2, fc, fs=fs), x)
        let (fs, fc) = (50.0, 15.0);
        let x: Vec<f64> = (0..40)
            .map(|k| {
                let t = k as f64 / fs;
                1.0 + 0.3 * t
                    + (2.0 * PI * 3.0 * t).sin()
                    + 0.5 * (2.0 * PI * 20.0 * t).sin()
                    + 0.2 * (2.0 * PI * 11.0 * t).cos()
            })
            .collect();
        let y = lowpass_zero_phase(&x, fs, fc).unwrap();
        let reference = SCIPY_FILTFILT_REF;
        assert_eq!(y.len(), reference.len());
        for (k, (a, b)) in y.iter().zip(reference.iter()).enumerate() {
            assert!((a - b).abs() < 1e-12, "sample {k}: {a} vs scipy {b}");
        }
    }

    /// `scipy.signal.filtfilt` output for the signal in `matches_scipy_filtfilt_reference`.
    #[rustfmt::skip]
    const SCIPY_FILTFILT_REF: [f64; 40] = [
        1.2000091097391663,
        1.3884785618949922,
        1.5200663730186916,
        1.8494360107846664,
        2.1367617558682106,
        2.1240998550664942,
        1.7426082437335149,
        1.3337318797031696,
        1.2026806748081094,
        0.9696558045073845,
        0.5270859496023633,
        0.07825549985516189,
        -0.04097839009912785,
        0.2271314333453393,
        0.3837083320174839,
        0.4477631790233684,
        0.6831887577117467,
        1.1978890309287542,
        1.77921916526153,
        1.9482508086029773,
        1.9275811804370497,
        2.005999143291931,
        2.1129980464681943,
        2.0050720027994595,
        1.4675345587390423,
        0.9730918914794902,
        0.7661619493930187,
        0.6238917024963747,
        0.3766284338133977,
        0.03606591339991648,
        0.08599135121229838,
        0.5027819282636868,
        0.8636781384903066,
        1.077584089569295,
        1.2691667427797593,
        1.7483020068674158,
        2.198848396130866,
        2.3227113700275774,
        2.2100149198596366,
        1.6090843916267858,
    ];

    #[test]
    fn constant_passes_unchanged() {
        for &(fs, fc) in &[(50.0, 15.0), (1000.0, 0.5), (60.0, 29.9)] {
            for &c in &[0.0, 3.7, -1234.5] {
                let x = vec![c; 300];
                let y = lowpass_zero_phase(&x, fs, fc).unwrap();
                let err = y.iter().map(|v| (v - c).abs()).fold(0.0, f64::max);
                assert!(
                    err <= 1e-12 * c.abs().max(1.0),
                    "fs={fs} fc={fc} c={c}: {err}"
                );
            }
        }
    }

    #[test]
    fn low_frequency_sine_passes_without_phase_shift() {
        let (fs, fc, amp) = (100.0, 15.0, 2.0);
        let f = fc / 10.0;
        let n = 1000;
        let x = sine(n, fs, f, amp);
        let y = lowpass_zero_phase(&x, fs, fc).unwrap();
        let interior = 50..n - 50;
        let (a_in, ph_in) = fit_sine(&x, fs, f, interior.clone());
        let (a_out, ph_out) = fit_sine(&y, fs, f, interior.clone());
        assert!(
            (a_out / a_in - 1.0).abs() < 0.01,
            "amplitude ratio {}",
            a_out / a_in
        );
        assert!(
            (ph_out - ph_in).abs() < 1e-6,
            "phase shift {} rad",
            ph_out - ph_in
        );
        // Direct comparison with the input away from the edges.
        let max_err = interior.map(|k| (y[k] - x[k]).abs()).fold(0.0, f64::max);
        assert!(max_err < 0.01 * amp, "max error {max_err}");
        // A single causal pass would lag by ~0.14 rad here and fail that check.
        let bq = Biquad::butterworth_lowpass(fs, fc).unwrap();
        let mut single = x.clone();
        bq.run_in_place(&mut single);
        let single_err = (50..n - 50)
            .map(|k| (single[k] - x[k]).abs())
            .fold(0.0, f64::max);
        assert!(single_err > 0.1 * amp, "single pass error {single_err}");
    }

    #[test]
    fn three_times_cutoff_is_attenuated_twice_single_pass_db() {
        for &(fs, fc) in &[(1000.0, 15.0), (100.0, 15.0), (120.0, 15.0)] {
            let f = 3.0 * fc;
            let n = 4000;
            let x = sine(n, fs, f, 1.0);
            let y = lowpass_zero_phase(&x, fs, fc).unwrap();
            let interior = 200..n - 200;
            let (a_in, _) = fit_sine(&x, fs, f, interior.clone());
            let (a_out, _) = fit_sine(&y, fs, f, interior);
            let att_db = -20.0 * (a_out / a_in).log10();
            let single_db = -20.0
                * Biquad::butterworth_lowpass(fs, fc)
                    .unwrap()
                    .gain_at(f, fs)
                    .log10();
            assert!(att_db > 20.0, "fs={fs}: attenuation {att_db} dB");
            assert!(
                (att_db - 2.0 * single_db).abs() < 0.05,
                "fs={fs}: {att_db} dB vs 2 x {single_db} dB"
            );
        }
    }

    #[test]
    fn step_response_is_symmetric_about_the_step() {
        let (fs, fc) = (50.0, 15.0);
        for &(fs, fc) in &[(fs, fc), (1000.0, 15.0)] {
            let n = 2000;
            let m = n / 2; // first sample at the high level; the step is at t0 = m − ½
            let x: Vec<f64> = (0..n).map(|k| if k < m { 0.0 } else { 1.0 }).collect();
            let y = lowpass_zero_phase(&x, fs, fc).unwrap();
            for d in 0..m - 1 {
                let upper = y[m + d] - 0.5;
                let lower = 0.5 - y[m - 1 - d];
                assert!(
                    (upper - lower).abs() < 1e-12,
                    "fs={fs} d={d}: {upper} vs {lower}"
                );
            }
            // The transition really is smoothed (not a pass-through) and ends settled.
            assert!(y[m] > 0.5 && y[m] < 1.0);
            assert!((y[0]).abs() < 1e-12 && (y[n - 1] - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn short_input_errors() {
        assert_eq!(
            lowpass_zero_phase(&[1.0; 9], 50.0, 15.0),
            Err(FilterError::TooShort { len: 9, min: 10 })
        );
        assert_eq!(
            lowpass_zero_phase(&[], 50.0, 15.0),
            Err(FilterError::TooShort { len: 0, min: 10 })
        );
        assert!(lowpass_zero_phase(&[1.0; 10], 50.0, 15.0).is_ok());
        assert_eq!(
            sample_rate(&[0.0]),
            Err(FilterError::TooShort { len: 1, min: 2 })
        );
    }

    #[test]
    fn bad_cutoff_errors_name_both_numbers() {
        for &(fs, fc) in &[
            (50.0, 25.0),
            (50.0, 30.0),
            (50.0, 0.0),
            (50.0, -1.0),
            (50.0, f64::NAN),
            (0.0, 15.0),
            (f64::INFINITY, 15.0),
        ] {
            let err = lowpass_zero_phase(&[0.0; 20], fs, fc).unwrap_err();
            assert!(matches!(err, FilterError::BadCutoff { .. }), "{err:?}");
            let msg = err.to_string();
            assert!(
                msg.contains(&format!("{fc} Hz")) && msg.contains(&format!("{fs} Hz")),
                "{msg}"
            );
        }
    }

    #[test]
    fn sample_rate_of_jittered_pmu_time_stamps() {
        // 50 frames/s; time stamps jitter by up to ±0.25 % of a step, steps by up to ±0.5 %.
        let t: Vec<f64> = (0..500)
            .map(|k| 12.0 + k as f64 * 0.02 + 0.00005 * (((k * 7919) % 3) as f64 - 1.0))
            .collect();
        let fs = sample_rate(&t).unwrap();
        assert!((fs - 50.0).abs() < 0.01, "{fs}");
        let exact: Vec<f64> = (0..100).map(|k| k as f64 / 60.0).collect();
        assert!((sample_rate(&exact).unwrap() - 60.0).abs() < 1e-9);
    }

    #[test]
    fn non_uniform_time_errors() {
        let mut t: Vec<f64> = (0..100).map(|k| k as f64 * 0.02).collect();
        t[40] += 0.001; // 5 % of a step
        match sample_rate(&t) {
            Err(FilterError::NonUniform { index, dt, mean_dt }) => {
                assert_eq!(index, 39);
                assert!((dt - 0.021).abs() < 1e-12 && (mean_dt - 0.02).abs() < 1e-12);
            }
            other => panic!("expected NonUniform, got {other:?}"),
        }
        // A gap (missing frame) is non-uniform.
        let gap: Vec<f64> = (0..100)
            .filter(|&k| k != 50)
            .map(|k| k as f64 * 0.02)
            .collect();
        assert!(matches!(
            sample_rate(&gap),
            Err(FilterError::NonUniform { .. })
        ));
        // Decreasing, constant and non-finite time columns.
        assert!(matches!(
            sample_rate(&[1.0, 0.5, 0.0]),
            Err(FilterError::NonUniform { .. })
        ));
        assert!(matches!(
            sample_rate(&[1.0, 1.0]),
            Err(FilterError::NonUniform { .. })
        ));
        assert!(matches!(
            sample_rate(&[0.0, f64::NAN, 2.0]),
            Err(FilterError::NonUniform { .. })
        ));
        assert!(matches!(
            sample_rate(&[0.0, 1.0, f64::INFINITY]),
            Err(FilterError::NonUniform { .. })
        ));
        assert!(!FilterError::NonUniform {
            index: 3,
            dt: 0.021,
            mean_dt: 0.02
        }
        .to_string()
        .is_empty());
    }

    #[test]
    fn nan_samples_propagate_without_panic() {
        let mut x = vec![1.0; 50];
        x[20] = f64::NAN;
        let y = lowpass_zero_phase(&x, 50.0, 15.0).unwrap();
        assert_eq!(y.len(), 50);
        assert!(y.iter().any(|v| v.is_nan()));
    }
}

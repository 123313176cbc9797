//! Smoothing of the played-back terminal voltage: the input's noise without its edges.
//!
//! **Why.** Playback drives the model with the *measured* |V| and angle. Their measurement noise
//! is not in the unit's true input, yet the model answers it, most of all through the stator's
//! algebraic response behind X''_d: ∂Q/∂|V| and ∂P/∂θ are a few pu per pu, so a PMU's white
//! voltage noise of 5e-4 pu per component becomes a simulated P and Q noise of about 1.5e-3 pu,
//! as large as the P and Q channels' own (a PMU's 2e-3 pu). That simulated noise is absent from
//! the recorded P and Q, and a least-squares fit lowers it by weakening the fast response:
//! X''_d rises (up to X'_d, its order bound), X_q and X_d bend to keep the slow response. This is the attenuation bias of errors in variables;
//! no amount of data removes it.
//!
//! **What.** A zero-phase low-pass ([`crate::filter::lowpass_zero_phase`], Butterworth run
//! forward and backward) of |V| and of the unwrapped angle, applied piecewise between the
//! record's discontinuities, which are kept as recorded so that a fault's or a step's edge
//! stays sharp and at its time stamp. A discontinuity is a sample whose second difference
//! departs from the record's by more than [`EDGE_Z`] robust standard deviations (the median
//! absolute deviation of the second differences, which a white noise of σ gives as √6 σ and a
//! swing below a few hertz barely moves); the flagged samples and their neighbours stay raw,
//! and every stretch between them is smoothed on its own, with [`SETTLE`] cut-off periods of
//! odd padding at each end so that a trend (an angle turning at an off-nominal frequency)
//! passes without a start-up transient; a stretch shorter than that stays raw.
//!
//! The cut-off is the event's `input_lowpass_hz` ([`super::Event::input_lowpass_hz`]): what the
//! playback should keep of the voltage. The electromechanical band ends near 2-3 Hz; above it,
//! away from the edges, a terminal voltage recorded by a PMU is mostly its noise. A phasor
//! record is played back smoothed at [`DEFAULT_CUTOFF_HZ`] unless its event says otherwise
//! ([`default_cutoff`]).

use crate::filter::{lowpass_zero_phase_padded, sample_rate, FilterError};

/// Robust z-score of a second difference above which its sample is a discontinuity. The rule: a
/// missed edge is smeared by the filter (a misfit at the edge), a false one only leaves a few
/// samples raw, so the test is loose: a Gaussian second difference passes 4 standard
/// deviations once in 16 000 samples (two-sided 6.3e-5).
pub const EDGE_Z: f64 = 4.0;

/// Relative size below which a second difference is rounding, not an edge: far above a
/// double's rounding of values of order 1 to 100 (1e-16 to 1e-14), far below any recorder's
/// resolution (a 16-bit sample of a 2 pu range: 3e-5).
pub const RESOLUTION: f64 = 1e-9;

/// Samples kept raw on each side of a flagged one: a step between samples k − 1 and k flags
/// the second differences at k − 1 and k; one more on each side covers a PMU's phasor filter
/// spreading the step over a further sample.
pub const EDGE_MARGIN: usize = 1;

/// Odd padding at each end of a smoothed stretch, and its shortest length, in cut-off periods
/// (`SETTLE · fs/f_c` samples): a trend's start-up transient decays as `exp(−2π f_c t/√2)`, so
/// after 3 periods it is below 2e-6 of the filter's lag of the trend
/// ([`crate::filter::lowpass_zero_phase_padded`]).
pub const SETTLE: f64 = 3.0;

/// The cut-off a phasor record is played back at unless its event names another or `"none"`
/// [Hz]: twice the upper edge of the electromechanical band (2 Hz, where the swing modes the
/// machine, AVR, PSS and governor models are calibrated on end). The zero-phase filter's gain
/// `1/(1 + (f/f_c)⁴)` is 0.996 at 1 Hz and 0.94 at 2 Hz, and it keeps `1.11 f_c/f_Nyquist` of a
/// white noise's variance: 15 % at 60 samples/s (a 30 Hz Nyquist frequency), so the simulated
/// P and Q noise the played-back voltage brings falls by √(1/0.15) ≈ 2.6 and with it the bias of
/// X''_d. A mode the model must reproduce above the cut-off (a shaft's
/// torsional mode) needs the record as recorded: the diagnosis plays it so for the causes that
/// add one.
pub const DEFAULT_CUTOFF_HZ: f64 = 4.0;

/// The cut-off an event with the record's `time_s` gets by default: [`DEFAULT_CUTOFF_HZ`] for a
/// phasor record (`has_angle`) whose stamps are uniform and whose Nyquist frequency is above it;
/// otherwise `None`, played back as recorded (a record the filter cannot run on, and a record
/// without an angle, whose playback modes impose other channels).
pub fn default_cutoff(time_s: &[f64], has_angle: bool) -> Option<f64> {
    (has_angle && check(time_s, DEFAULT_CUTOFF_HZ).is_ok()).then_some(DEFAULT_CUTOFF_HZ)
}

/// Which samples of `x` sit at a discontinuity ([`EDGE_Z`], [`EDGE_MARGIN`]).
pub fn edge_samples(x: &[f64]) -> Vec<bool> {
    let n = x.len();
    let mut raw = vec![false; n];
    if n < 3 {
        return vec![true; n];
    }
    let d2: Vec<f64> = (1..n - 1)
        .map(|k| x[k + 1] - 2.0 * x[k] + x[k - 1])
        .collect();
    let med = median(&d2);
    let mad = median(&d2.iter().map(|v| (v - med).abs()).collect::<Vec<_>>());
    // 1.4826 · MAD: the standard deviation of a Gaussian. Below [`RESOLUTION`] of the signal's
    // scale a departure is rounding (a computed, noise-free channel), not an edge.
    let scale = x.iter().fold(1.0_f64, |m, v| m.max(v.abs()));
    let limit = (EDGE_Z * 1.4826 * mad).max(RESOLUTION * scale);
    for (i, v) in d2.iter().enumerate() {
        if (v - med).abs() > limit {
            let k = i + 1;
            let (lo, hi) = (k.saturating_sub(EDGE_MARGIN), (k + EDGE_MARGIN).min(n - 1));
            raw[lo..=hi].iter_mut().for_each(|r| *r = true);
        }
    }
    raw
}

fn median(v: &[f64]) -> f64 {
    let mut s: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if s.is_empty() {
        return 0.0;
    }
    s.sort_by(|a, b| a.total_cmp(b));
    let m = s.len() / 2;
    if s.len() % 2 == 1 {
        s[m]
    } else {
        0.5 * (s[m - 1] + s[m])
    }
}

/// `x` low-passed at `cutoff_hz` (sample rate `fs`) between the samples `raw` marks, which keep
/// their values; a stretch no longer than the padding ([`SETTLE`]) stays raw too.
fn smooth_between(
    x: &[f64],
    raw: &[bool],
    fs: f64,
    cutoff_hz: f64,
) -> Result<Vec<f64>, FilterError> {
    let pad = pad_samples(fs, cutoff_hz);
    let mut out = x.to_vec();
    for (start, k) in stretches(raw) {
        if k - start > pad {
            out[start..k].copy_from_slice(&lowpass_zero_phase_padded(
                &x[start..k],
                fs,
                cutoff_hz,
                pad,
            )?);
        }
    }
    Ok(out)
}

/// The sample rate of `time_s`, when [`smoothed_input`] can smooth at `cutoff_hz`: its only
/// failures are these two checks (a stretch too short for the filter stays raw).
///
/// # Errors
/// As [`smoothed_input`].
pub fn check(time_s: &[f64], cutoff_hz: f64) -> Result<f64, FilterError> {
    let fs = sample_rate(time_s)?;
    crate::filter::Biquad::butterworth_lowpass(fs, cutoff_hz)?;
    Ok(fs)
}

/// The played-back |V| and angle of a record (`time_s`, `v_mag`, `v_ang` unwrapped), each
/// low-passed at `cutoff_hz` between the discontinuities of either ([`edge_samples`]).
///
/// # Errors
/// [`FilterError`] when the time stamps are not uniform within 1 % or the cut-off is not below
/// the Nyquist frequency.
pub fn smoothed_input(
    time_s: &[f64],
    v_mag: &[f64],
    v_ang: &[f64],
    cutoff_hz: f64,
) -> Result<(Vec<f64>, Vec<f64>), FilterError> {
    smoothed_input_marked(time_s, v_mag, v_ang, cutoff_hz).map(|(m, a, _)| (m, a))
}

/// [`smoothed_input`] with the samples it smoothed marked `true` (those it kept raw: the
/// edges, their margins and the stretches too short to filter, `false`).
///
/// # Errors
/// The smoothed |V| and angle, and which samples were kept raw (an edge).
pub type MarkedInput = (Vec<f64>, Vec<f64>, Vec<bool>);

/// As [`smoothed_input`].
pub fn smoothed_input_marked(
    time_s: &[f64],
    v_mag: &[f64],
    v_ang: &[f64],
    cutoff_hz: f64,
) -> Result<MarkedInput, FilterError> {
    let fs = check(time_s, cutoff_hz)?;
    // An edge in either channel (a fault moves both) keeps both raw there.
    let raw: Vec<bool> = edge_samples(v_mag)
        .iter()
        .zip(edge_samples(v_ang))
        .map(|(a, b)| *a || b)
        .collect();
    let pad = pad_samples(fs, cutoff_hz);
    let mut smoothed = vec![false; raw.len()];
    for (a, b) in stretches(&raw) {
        if b - a > pad {
            smoothed[a..b].iter_mut().for_each(|s| *s = true);
        }
    }
    Ok((
        smooth_between(v_mag, &raw, fs, cutoff_hz)?,
        smooth_between(v_ang, &raw, fs, cutoff_hz)?,
        smoothed,
    ))
}

/// The padding and shortest smoothed stretch in samples ([`SETTLE`] cut-off periods).
fn pad_samples(fs: f64, cutoff_hz: f64) -> usize {
    (SETTLE * fs / cutoff_hz).ceil() as usize
}

/// The runs `[a, b)` of samples not marked `raw`.
fn stretches(raw: &[bool]) -> Vec<(usize, usize)> {
    let mut out = vec![];
    let mut k = 0;
    while k < raw.len() {
        if raw[k] {
            k += 1;
            continue;
        }
        let start = k;
        while k < raw.len() && !raw[k] {
            k += 1;
        }
        out.push((start, k));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Normal;

    fn sd(v: &[f64]) -> f64 {
        let m = v.iter().sum::<f64>() / v.len() as f64;
        (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len() as f64).sqrt()
    }

    /// A 30 s, 60 sample/s record: |V| 1.0 with a 0.05 pu step down at 10 s and a 0.3 Hz swing;
    /// the angle ramping (a 0.05 Hz frequency offset) with a 0.2 rad jump at 10 s; white noise
    /// of 5e-4 on both (the practice records' PMU).
    /// Time, clean |V|, clean angle, recorded |V|, recorded angle.
    type Record = (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>);

    fn record(seed: u64) -> Record {
        let mut rng = Normal::new(seed);
        let t: Vec<f64> = (0..1800).map(|k| k as f64 / 60.0).collect();
        let m0: Vec<f64> = t
            .iter()
            .map(|&t| {
                1.0 - if t >= 10.0 { 0.05 } else { 0.0 }
                    + 0.004 * (std::f64::consts::TAU * 0.3 * t).sin()
            })
            .collect();
        let a0: Vec<f64> = t
            .iter()
            .map(|&t| std::f64::consts::TAU * 0.05 * t + if t >= 10.0 { 0.2 } else { 0.0 })
            .collect();
        let m = m0.iter().map(|v| v + 5e-4 * rng.sample()).collect();
        let a = a0.iter().map(|v| v + 5e-4 * rng.sample()).collect();
        (t, m0, a0, m, a)
    }

    #[test]
    fn the_noise_goes_and_the_edge_stays() {
        let (t, m0, a0, m, a) = record(7);
        let (ms, as_) = smoothed_input(&t, &m, &a, 4.0).unwrap();
        // The step's samples are the recorded ones: the edge is neither smeared nor moved.
        for k in 599..=600 {
            assert_eq!(ms[k], m[k], "|V| sample {k}");
            assert_eq!(as_[k], a[k], "angle sample {k}");
        }
        // Away from the edge the error against the clean signal falls by more than 2 (a 4 Hz
        // zero-phase low-pass keeps about 4/30 of a white noise's variance at 60 samples/s).
        let away: Vec<usize> = (20..1780).filter(|k| !(590..610).contains(k)).collect();
        let err = |s: &[f64], c: &[f64]| sd(&away.iter().map(|&k| s[k] - c[k]).collect::<Vec<_>>());
        assert!(
            err(&ms, &m0) < 0.5 * err(&m, &m0),
            "|V|: {} vs {}",
            err(&ms, &m0),
            err(&m, &m0)
        );
        assert!(
            err(&as_, &a0) < 0.5 * err(&a, &a0),
            "angle: {} vs {}",
            err(&as_, &a0),
            err(&a, &a0)
        );
        // The swing and the ramp pass: the smoothed signal follows the clean one within the
        // noise left.
        let worst = away
            .iter()
            .map(|&k| (ms[k] - m0[k]).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1.5e-3, "worst |V| departure {worst}");
    }

    #[test]
    fn only_the_edges_are_flagged() {
        let (_, _, _, m, a) = record(11);
        for x in [&m, &a] {
            let raw = edge_samples(x);
            assert!(raw[599] && raw[600], "the step is flagged");
            // Besides the step's few samples, at most a handful of noise flags.
            let others = raw
                .iter()
                .enumerate()
                .filter(|(k, r)| **r && !(597..=602).contains(k))
                .count();
            assert!(others <= 6, "{others} samples flagged away from the step");
        }
    }

    #[test]
    fn a_noise_free_record_barely_moves() {
        let (t, m0, a0, _, _) = record(3);
        let (ms, as_) = smoothed_input(&t, &m0, &a0, 4.0).unwrap();
        let worst = |s: &[f64], c: &[f64]| {
            s.iter()
                .zip(c)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0, f64::max)
        };
        // Within a tenth of the noise the smoothing is for (the odd padding at a stretch's
        // ends continues the swing's curve as a straight line: 2.7e-5 at most).
        assert!(worst(&ms, &m0) < 5e-5, "|V| moved by {}", worst(&ms, &m0));
        assert!(
            worst(&as_, &a0) < 5e-5,
            "angle moved by {}",
            worst(&as_, &a0)
        );
    }

    #[test]
    fn uneven_stamps_and_a_cutoff_above_nyquist_are_errors() {
        let (mut t, _, _, m, a) = record(5);
        assert!(matches!(
            smoothed_input(&t, &m, &a, 31.0),
            Err(FilterError::BadCutoff { .. })
        ));
        t[100] += 0.005;
        assert!(matches!(
            smoothed_input(&t, &m, &a, 4.0),
            Err(FilterError::NonUniform { .. })
        ));
    }
}

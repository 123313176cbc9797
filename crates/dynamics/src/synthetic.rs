//! Synthetic events: a terminal-voltage profile played into a "true" unit, whose simulated P and
//! Q (with optional PMU-like noise and quantisation) become the measurement.
//!
//! Used by benchmarks, tests and (later) `itaipu-calib synth`. Deterministic: the noise comes
//! from a seeded SplitMix64 generator with Box-Muller normals, identical on every platform.

use crate::event::{Event, EventError, Record, Window};
use crate::simulate::{simulate_pq, PreparedEvent, SimError, SimOptions};
use crate::unit::Unit;

/// Shape of the played-back terminal voltage.
#[derive(Debug, Clone, PartialEq)]
pub struct VoltageProfile {
    /// Record length [s] and sampling rate [samples/s].
    pub duration_s: f64,
    pub rate_hz: f64,
    /// Pre-event voltage magnitude [pu] and angle [rad].
    pub v0: f64,
    pub angle0: f64,
    /// Fault-like dip: start [s], duration [s], depth (|V| during the dip) [pu]. `depth >= v0`
    /// disables it.
    pub dip_start_s: f64,
    pub dip_duration_s: f64,
    pub dip_v: f64,
    /// Angle jump at clearing [rad] (a post-fault angle swing follows from the grid).
    pub angle_step: f64,
    /// Electromechanical swing of the grid angle after the dip: amplitude [rad], frequency
    /// [Hz], damping ratio.
    pub swing_amp: f64,
    pub swing_hz: f64,
    pub swing_zeta: f64,
    /// Grid frequency deviation reached after the event [Hz] (ramped with time constant
    /// `freq_tau_s`), shown as an angle drift in the nominal-frequency frame.
    pub freq_dev_hz: f64,
    pub freq_tau_s: f64,
    /// Pre-event active and reactive power of the true unit [pu on its machine base].
    pub p0_mach: f64,
    pub q0_mach: f64,
    /// Step of |V| at the event instant [pu] (0: none).
    pub v_step: f64,
    /// Ambient fluctuations over the whole record: Ornstein-Uhlenbeck processes on |V| [pu] and
    /// the angle [rad] with these stationary standard deviations and correlation time (0: none),
    /// band-limited by [`AMBIENT_BAND_HZ`].
    pub ambient_v_sigma: f64,
    pub ambient_angle_sigma: f64,
    pub ambient_tau_s: f64,
    /// Seed of the ambient fluctuations.
    pub seed: u64,
}

/// Upper edge of the ambient fluctuations' band [Hz]: the grid's voltage at a unit's terminal
/// wanders with the loads, filtered by the grid's electromechanical dynamics (modes of 0.1-2 Hz,
/// `models.md` §12.1), so its spectrum falls off above about 2 Hz. The Ornstein-Uhlenbeck
/// samples pass through two first-order low-passes at this corner (critically damped, −40 dB a
/// decade above it); without them the process steps at every sample (about 1.5 mrad of angle a
/// sample at 60 samples/s, three times a PMU's angle noise), content a grid voltage does not
/// have, which a playback that smooths its input as noise above 4 Hz could not follow.
pub const AMBIENT_BAND_HZ: f64 = 2.0;

impl Default for VoltageProfile {
    /// A 20 s, 60 samples/s event: 0.1 s dip to 0.7 pu at 1 s, a 0.8 Hz grid swing and a fall
    /// of 0.2 Hz.
    fn default() -> Self {
        Self {
            duration_s: 20.0,
            rate_hz: 60.0,
            v0: 1.0,
            angle0: 0.3,
            dip_start_s: 1.0,
            dip_duration_s: 0.1,
            dip_v: 0.7,
            angle_step: 0.05,
            swing_amp: 0.08,
            swing_hz: 0.8,
            swing_zeta: 0.1,
            freq_dev_hz: -0.2,
            freq_tau_s: 3.0,
            p0_mach: 0.8,
            q0_mach: 0.2,
            v_step: 0.0,
            ambient_v_sigma: 0.0,
            ambient_angle_sigma: 0.0,
            ambient_tau_s: 1.0,
            seed: 0,
        }
    }
}

/// The kinds of event `synth` makes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EventKind {
    /// Fault-like dip to 0.7 pu for 0.1 s, angle jump and 0.8 Hz grid swing, 0.2 Hz frequency fall.
    FaultDip,
    /// No dip: a 0.3 Hz frequency fall (τ = 4 s) with a small 0.6 Hz swing.
    FrequencyExcursion,
    /// A +0.5 % step of the terminal voltage (a nearby tap change) with a small swing. (A
    /// persistent step much larger than 1/K_AVR of E_fd0 drives a high-gain AVR without
    /// integral action onto its floor, and the unit then slips: not an event a PMU records.)
    VoltageStep,
    /// Ambient: only small random fluctuations of |V| and angle (no discrete event).
    Ambient,
}

impl VoltageProfile {
    /// A preset for `kind`, `duration_s` long at `rate_hz`, with the event at 1 s.
    pub fn preset(kind: EventKind, duration_s: f64, rate_hz: f64, seed: u64) -> Self {
        let base = Self {
            duration_s,
            rate_hz,
            seed,
            ..Default::default()
        };
        match kind {
            EventKind::FaultDip => base,
            EventKind::FrequencyExcursion => Self {
                dip_v: base.v0,
                dip_duration_s: 0.0,
                angle_step: 0.0,
                swing_amp: 0.02,
                swing_hz: 0.6,
                freq_dev_hz: -0.3,
                freq_tau_s: 4.0,
                ..base
            },
            EventKind::VoltageStep => Self {
                dip_v: base.v0,
                dip_duration_s: 0.0,
                angle_step: 0.0,
                swing_amp: 0.01,
                freq_dev_hz: 0.0,
                v_step: 0.005,
                ..base
            },
            EventKind::Ambient => Self {
                dip_v: base.v0,
                dip_duration_s: 0.0,
                angle_step: 0.0,
                swing_amp: 0.0,
                freq_dev_hz: 0.0,
                ambient_v_sigma: 0.003,
                ambient_angle_sigma: 0.01,
                ambient_tau_s: 1.5,
                ..base
            },
        }
    }
}

impl VoltageProfile {
    /// Sample times, magnitudes and unwrapped angles.
    pub fn samples(&self) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let n = (self.duration_s * self.rate_hz).round() as usize + 1;
        let mut t = Vec::with_capacity(n);
        let mut v = Vec::with_capacity(n);
        let mut a = Vec::with_capacity(n);
        let t_clear = self.dip_start_s + self.dip_duration_s;
        let mut rng = Normal::new(self.seed ^ 0xA5A5_5A5A);
        let dt = 1.0 / self.rate_hz;
        let phi = if self.ambient_tau_s > 0.0 {
            (-dt / self.ambient_tau_s).exp()
        } else {
            0.0
        };
        let innov = (1.0 - phi * phi).sqrt();
        let (mut ou_v, mut ou_a) = (0.0, 0.0);
        // Two first-order low-passes at AMBIENT_BAND_HZ (exact discretisation of e^{−t/τ_f}).
        let lp = (-2.0 * std::f64::consts::PI * AMBIENT_BAND_HZ * dt).exp();
        let (mut v1, mut v2, mut a1, mut a2) = (0.0, 0.0, 0.0, 0.0);
        for k in 0..n {
            let tk = k as f64 / self.rate_hz;
            let in_dip = self.dip_v < self.v0 && tk >= self.dip_start_s && tk < t_clear;
            let mut mag = if in_dip { self.dip_v } else { self.v0 };
            let mut ang = self.angle0;
            if tk >= t_clear {
                let s = tk - t_clear;
                let wd = 2.0 * std::f64::consts::PI * self.swing_hz;
                let decay = (-self.swing_zeta * wd * s).exp();
                ang += self.angle_step + self.swing_amp * decay * (wd * s).sin();
                // A slight voltage recovery transient.
                mag += 0.02 * decay * (wd * s).cos();
                // Frequency ramp f(t) = Δf (1 − e^{−s/τ}); the angle is its integral × 2π.
                let tau = self.freq_tau_s.max(1e-6);
                ang += 2.0
                    * std::f64::consts::PI
                    * self.freq_dev_hz
                    * (s - tau * (1.0 - (-s / tau).exp()));
                mag += self.v_step;
            }
            if self.ambient_v_sigma > 0.0 || self.ambient_angle_sigma > 0.0 {
                ou_v = phi * ou_v + innov * self.ambient_v_sigma * rng.sample();
                ou_a = phi * ou_a + innov * self.ambient_angle_sigma * rng.sample();
                v1 = lp * v1 + (1.0 - lp) * ou_v;
                v2 = lp * v2 + (1.0 - lp) * v1;
                a1 = lp * a1 + (1.0 - lp) * ou_a;
                a2 = lp * a2 + (1.0 - lp) * a1;
                mag += v2;
                ang += a2;
            }
            t.push(tk);
            v.push(mag);
            a.push(ang);
        }
        (t, v, a)
    }
}

/// PMU measurement imperfections applied to the simulated P and Q.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PmuNoise {
    /// Standard deviation of white noise on P and Q [pu, system base].
    pub pq_sigma: f64,
    /// Standard deviation of white noise on |V| [pu] and on the angle [rad].
    pub v_sigma: f64,
    pub angle_sigma: f64,
    /// Quantisation step of P and Q [pu] (0 = none).
    pub pq_quantum: f64,
    /// Time skew of the power channels: the recorded P and Q at t are the true ones at
    /// t − `pq_delay_s` ([`delayed`]) [s].
    pub pq_delay_s: f64,
    pub seed: u64,
}

impl PmuNoise {
    /// No noise.
    pub fn none() -> Self {
        Self {
            pq_sigma: 0.0,
            v_sigma: 0.0,
            angle_sigma: 0.0,
            pq_quantum: 0.0,
            pq_delay_s: 0.0,
            seed: 0,
        }
    }
    /// Typical M-class PMU: 0.002 pu on P and Q, 0.0005 pu on |V|, 0.0005 rad on the angle,
    /// P and Q quantised at 0.0014 pu (as in the Itaipu record).
    pub fn typical(seed: u64) -> Self {
        Self {
            pq_sigma: 0.002,
            v_sigma: 0.0005,
            angle_sigma: 0.0005,
            pq_quantum: 0.0014,
            pq_delay_s: 0.0,
            seed,
        }
    }
}

/// The PMU noise generator (the workspace's one random source, re-exported here).
pub use crate::rng::Normal;

/// Why a synthetic event could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SynthError {
    #[error("{0}")]
    Event(String),
    #[error("simulating the true unit: {0}")]
    Sim(#[from] SimError),
}

impl From<EventError> for SynthError {
    fn from(e: EventError) -> Self {
        SynthError::Event(e.to_string())
    }
}

/// Plays `profile` into `truth` and returns an event whose P and Q are the simulated ones with
/// `noise` applied (the voltage channels get their noise after the simulation, as a PMU's would).
pub fn synthesize(
    name: &str,
    truth: &Unit,
    profile: &VoltageProfile,
    system_mva: f64,
    noise: &PmuNoise,
    opts: &SimOptions,
) -> Result<Event, SynthError> {
    let (t, v, a) = profile.samples();
    let n = t.len();
    let pre = (profile.dip_start_s - 0.05).max(3.0 / profile.rate_hz);
    // The true unit starts from the exact pre-event operating point: build a provisional event
    // with P, Q placeholders, simulate, then take the simulated initial P, Q as the measured ones.
    let mut unit = truth.clone();
    let machine_to_sys = truth.machine_mva / system_mva;
    let op_p = profile.p0_mach * machine_to_sys;
    let op_q = profile.q0_mach * machine_to_sys;
    let record = Record {
        time_s: t.clone(),
        v_mag_pu: v.clone(),
        v_ang_rad: a.clone(),
        p_pu: vec![op_p; n],
        q_pu: vec![op_q; n],
        freq_hz: None,
        efd_pu: None,
        ifd_pu: None,
    };
    let init = Window {
        start_s: 0.0,
        end_s: pre,
    };
    let mut ev = Event::from_record(name, record, system_mva, truth.nominal_hz, Some(init), None)?;
    // The true unit answers the true voltage, every frequency of it: the playback's default
    // smoothing of a measured input ([`Event::playback_voltage`]) is for the noisy record the
    // event becomes, not for the truth.
    ev.input_lowpass_hz = None;
    let prepared = PreparedEvent::new(&ev);
    let (p, q) = simulate_pq(&mut unit, &prepared, opts)?;
    let mut rng = Normal::new(noise.seed);
    let quant = |x: f64| {
        if noise.pq_quantum > 0.0 {
            (x / noise.pq_quantum).round() * noise.pq_quantum
        } else {
            x
        }
    };
    let (p, q) = (
        delayed(&t, &p, noise.pq_delay_s),
        delayed(&t, &q, noise.pq_delay_s),
    );
    let mut rec = ev.record.clone();
    for k in 0..n {
        rec.p_pu[k] = quant(p[k] + noise.pq_sigma * rng.sample());
        rec.q_pu[k] = quant(q[k] + noise.pq_sigma * rng.sample());
        rec.v_mag_pu[k] += noise.v_sigma * rng.sample();
        rec.v_ang_rad[k] += noise.angle_sigma * rng.sample();
    }
    Ok(Event::from_record(
        name,
        rec,
        system_mva,
        truth.nominal_hz,
        Some(init),
        None,
    )?)
}

/// Half-width, in samples, of the fractional-delay kernel of [`delayed`] (32 taps).
pub const DELAY_HALF_WIDTH: usize = 16;

/// `y` delayed by `tau` seconds on the sample times `t`: y(t_k − τ), held at the first (last)
/// sample beyond the record's ends.
///
/// On a uniform grid (every time within a tenth of a sample interval of the regular grid, which
/// timestamps rounded to the millisecond are) the fractional part is a band-limited
/// interpolation: a Hann-windowed sinc of [`DELAY_HALF_WIDTH`] samples each side, normalised to
/// unit gain at DC,
///
/// ```text
/// y(i + u) = Σ_j h(j − u) y[i + j] / Σ_j h(j − u),   h(x) = sinc(x) · ½ (1 + cos(π x / M)),  j = −M+1 … M
/// ```
///
/// which keeps the amplitude within 0.3 % and the delay within 1e-4 sample up to 0.4 × the
/// sample rate, and the variance of white noise within 5 % at every fraction. A PMU's channels
/// are band-limited (IEEE C37.118 filters), so this is a time shift of the signal, and the fit
/// sees no other effect of it. Linear interpolation is not: at a fraction u it keeps
/// (1 − u)² + u² of white noise's variance, half at half a sample, so the simulated P and Q
/// (noisy where they follow the measured voltage's noise) fit χ² better near every half sample
/// whatever the real skew: a delay re-fit then settles near half a sample on records with no
/// skew at all.
///
/// A whole number of samples is an exact shift. A non-uniform grid (gaps, a changed rate) is
/// delayed by linear interpolation on its times.
pub fn delayed(t: &[f64], y: &[f64], tau: f64) -> Vec<f64> {
    if tau == 0.0 || y.len() < 2 {
        return y.to_vec();
    }
    match uniform_step(t) {
        Some(dt) => delayed_uniform(y, tau / dt),
        None => delayed_linear(t, y, tau),
    }
}

/// The sample interval of a uniform grid (see [`delayed`]), `None` otherwise.
fn uniform_step(t: &[f64]) -> Option<f64> {
    let n = t.len();
    let dt = (t[n - 1] - t[0]) / (n - 1) as f64;
    (dt > 0.0
        && t.iter()
            .enumerate()
            .all(|(k, tk)| (tk - t[0] - k as f64 * dt).abs() <= 0.1 * dt))
    .then_some(dt)
}

/// `y` delayed by `d` samples with the band-limited kernel of [`delayed`].
fn delayed_uniform(y: &[f64], d: f64) -> Vec<f64> {
    let n = y.len() as i64;
    // Sample k reads position k − d = i + u with the same fraction u for every k.
    let shift = (-d).floor();
    let u = -d - shift;
    let at = |i: i64| y[i.clamp(0, n - 1) as usize];
    if !(1e-12..=1.0 - 1e-12).contains(&u) {
        let whole = shift as i64 + i64::from(u > 0.5);
        return (0..n).map(|k| at(k + whole)).collect();
    }
    let taps = delay_taps(u);
    let gain: f64 = taps.iter().map(|t| t.1).sum();
    let first = shift as i64;
    (0..n)
        .map(|k| {
            // Position i + u, 0 < u < 1: before the record (i < 0) held at the first
            // sample, beyond it at the last, as the linear delay holds them.
            let i = k + first;
            if i < 0 {
                return y[0];
            }
            if i >= n - 1 {
                return y[(n - 1) as usize];
            }
            taps.iter().map(|(j, h, _)| h * at(i + j)).sum::<f64>() / gain
        })
        .collect()
}

/// The taps of [`delayed`]'s kernel at the fraction `u`: `(j, h(j − u), ∂h(j − u)/∂u)` for
/// `j = −M+1 … M` (M = [`DELAY_HALF_WIDTH`]), `h(x) = sinc(x) · ½ (1 + cos(π x / M))`; the
/// slope near x = 0 from sinc's series (the quotient cancels there).
fn delay_taps(u: f64) -> Vec<(i64, f64, f64)> {
    let m = DELAY_HALF_WIDTH as i64;
    let pi = std::f64::consts::PI;
    (-m + 1..=m)
        .map(|j| {
            let x = j as f64 - u;
            let (s, c) = (pi * x).sin_cos();
            let sinc = if x == 0.0 { 1.0 } else { s / (pi * x) };
            let dsinc = if x.abs() < 1e-6 {
                -pi * pi * x / 3.0
            } else {
                (c * pi * x - s) / (pi * x * x)
            };
            let (ws, wc) = (pi * x / m as f64).sin_cos();
            let w = 0.5 * (1.0 + wc);
            let dw = -0.5 * ws * pi / m as f64;
            // x = j − u: d/du = −d/dx.
            (j, sinc * w, -(dsinc * w + sinc * dw))
        })
        .collect()
}

/// [`delayed`] on dual numbers: the values are [`delayed`]'s; the derivatives are those of the
/// same interpolation, with respect to the series (a linear map: the delay applied to each
/// tangent lane) and to `tau` (the kernel's slope in the fraction, at whole samples too: a
/// whole-sample shift is the kernel at u = 0, whose slope is the band-limited signal's).
pub(crate) fn delayed_dual(
    t: &[f64],
    y: &[crate::sens::D],
    tau: crate::sens::D,
) -> Vec<crate::sens::D> {
    use crate::sens::{Scalar, D, LANES};
    let n = y.len();
    let values: Vec<f64> = y.iter().map(|v| v.v).collect();
    let out_v = delayed(t, &values, tau.v);
    // The series' lanes, delayed as the values.
    let mut out: Vec<D> = out_v.iter().map(|&v| D::cst(v)).collect();
    for lane in 0..LANES {
        let col: Vec<f64> = y.iter().map(|v| v.d[lane]).collect();
        if col.iter().all(|&c| c == 0.0) {
            continue;
        }
        for (o, c) in out.iter_mut().zip(delayed(t, &col, tau.v)) {
            o.d[lane] = c;
        }
    }
    if tau.d.iter().all(|&d| d == 0.0) || n < 2 {
        return out;
    }
    // ∂/∂τ: the interpolation's slope at t_k − τ, times −1, chained with τ's tangent.
    let slope: Vec<f64> = match uniform_step(t) {
        Some(dt) => {
            let d = tau.v / dt;
            let shift = (-d).floor();
            let u = -d - shift;
            // A whole-sample delay is the kernel at u = 0 or, from the previous sample, at u = 1:
            // the two differ at the record's end (held samples) and their slopes are one-sided.
            // A delay grows with τ, the position k − d falls: the slope from below, u = 1.
            let (shift, u) = if u < 1e-12 {
                (shift - 1.0, u + 1.0)
            } else {
                (shift, u)
            };
            let taps = delay_taps(u);
            let gain: f64 = taps.iter().map(|t| t.1).sum();
            let dgain: f64 = taps.iter().map(|t| t.2).sum();
            let ni = n as i64;
            let at = |i: i64| values[i.clamp(0, ni - 1) as usize];
            let first = shift as i64;
            (0..ni)
                .map(|k| {
                    let i = k + first;
                    if i < 0 || i >= ni - 1 {
                        return 0.0;
                    }
                    let (num, dnum) = taps.iter().fold((0.0, 0.0), |(a, b), (j, hv, dh)| {
                        (a + hv * at(i + j), b + dh * at(i + j))
                    });
                    // y(u) = num/gain; du/dτ = −1/dt.
                    let dydu = (dnum * gain - num * dgain) / (gain * gain);
                    -dydu / dt
                })
                .collect()
        }
        None => {
            // Linear interpolation: the slope of the segment holding t_k − τ.
            let mut cursor = 0usize;
            t.iter()
                .map(|&tk| {
                    let ts = tk - tau.v;
                    if ts <= t[0] || ts >= t[n - 1] {
                        return 0.0;
                    }
                    while t[cursor + 1] < ts {
                        cursor += 1;
                    }
                    while t[cursor] > ts {
                        cursor -= 1;
                    }
                    -(values[cursor + 1] - values[cursor]) / (t[cursor + 1] - t[cursor])
                })
                .collect()
        }
    };
    for (o, s) in out.iter_mut().zip(slope) {
        for lane in 0..LANES {
            o.d[lane] += s * tau.d[lane];
        }
    }
    out
}

/// `y` delayed by `tau` seconds by linear interpolation on the times `t` (a non-uniform grid).
fn delayed_linear(t: &[f64], y: &[f64], tau: f64) -> Vec<f64> {
    let mut cursor = 0usize;
    t.iter()
        .map(|&tk| {
            let ts = tk - tau;
            if ts <= t[0] {
                return y[0];
            }
            if ts >= t[t.len() - 1] {
                return y[y.len() - 1];
            }
            while t[cursor + 1] < ts {
                cursor += 1;
            }
            while t[cursor] > ts {
                cursor -= 1;
            }
            let w = (ts - t[cursor]) / (t[cursor + 1] - t[cursor]);
            y[cursor] + w * (y[cursor + 1] - y[cursor])
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn normal_is_deterministic_and_standard() {
        let mut a = Normal::new(7);
        let mut b = Normal::new(7);
        let xs: Vec<f64> = (0..20000).map(|_| a.sample()).collect();
        assert!(xs
            .iter()
            .zip((0..20000).map(|_| b.sample()))
            .all(|(x, y)| *x == y));
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / xs.len() as f64;
        assert!(
            mean.abs() < 0.03 && (var - 1.0).abs() < 0.04,
            "mean {mean} var {var}"
        );
    }

    #[test]
    fn delay_shifts_a_ramp_by_tau() {
        let t: Vec<f64> = (0..200).map(|k| k as f64 / 60.0).collect();
        let y: Vec<f64> = t.iter().map(|t| 2.0 * t).collect();
        let d = delayed(&t, &y, 0.005);
        // Away from the ends (where the kernel reads held samples) within 1e-4 of a sample.
        for k in DELAY_HALF_WIDTH..200 - DELAY_HALF_WIDTH {
            assert!(
                (d[k] - 2.0 * (t[k] - 0.005)).abs() < 2.0 * 1e-4 / 60.0,
                "{k}: {} against {}",
                d[k],
                2.0 * (t[k] - 0.005)
            );
        }
        assert_eq!(delayed(&t, &y, 0.0), y);
        // Before the record: the first sample held.
        assert_eq!(delayed(&t, &y, 0.05)[..3], [0.0, 0.0, 0.0]);
    }

    #[test]
    fn a_whole_number_of_samples_is_an_exact_shift() {
        let t: Vec<f64> = (0..50).map(|k| 10.0 + k as f64 * 0.02).collect();
        let y: Vec<f64> = (0..50).map(|k| ((k * k) % 7) as f64).collect();
        let d = delayed(&t, &y, 0.04);
        assert_eq!(d[..2], [y[0], y[0]]);
        assert_eq!(d[2..], y[..48]);
    }

    /// A band-limited signal keeps its amplitude and takes the delay, to well within what a
    /// fit resolves, at a fraction of a sample.
    #[test]
    fn a_fractional_delay_shifts_a_sinusoid() {
        let fs = 60.0;
        let t: Vec<f64> = (0..600).map(|k| k as f64 / fs).collect();
        for (f_hz, tau) in [(0.68, 0.0269), (6.0, 0.0219), (15.0, 0.0083)] {
            let y: Vec<f64> = t.iter().map(|t| (2.0 * PI * f_hz * t).sin()).collect();
            let d = delayed(&t, &y, tau);
            for k in 2 * DELAY_HALF_WIDTH..600 - 2 * DELAY_HALF_WIDTH {
                let want = (2.0 * PI * f_hz * (t[k] - tau)).sin();
                assert!(
                    (d[k] - want).abs() < 3e-3,
                    "{f_hz} Hz, {k}: {} against {want}",
                    d[k]
                );
            }
        }
    }

    /// The reason for the kernel: delayed white noise keeps its variance at every fraction
    /// (linear interpolation keeps half of it at half a sample), so a delay fit to noisy
    /// playback gains nothing by smoothing.
    #[test]
    fn a_fractional_delay_keeps_white_noise_variance() {
        let n = 20_000;
        let t: Vec<f64> = (0..n).map(|k| k as f64 / 60.0).collect();
        let mut rng = Normal::new(11);
        let y: Vec<f64> = (0..n).map(|_| rng.sample()).collect();
        let var = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64;
        let v0 = var(&y);
        for frac in [0.1, 0.25, 0.5, 0.75] {
            let d = delayed(&t, &y, (1.0 + frac) / 60.0);
            let kept = var(&d[100..n - 100]) / v0;
            assert!(kept > 0.93 && kept < 1.02, "fraction {frac}: kept {kept}");
        }
        // Linear interpolation on the same noise, for contrast (a non-uniform grid takes it).
        let mut t2 = t.clone();
        t2[n / 2] += 0.5 / 60.0;
        let lin = delayed(&t2, &y, 1.5 / 60.0);
        let kept = var(&lin[100..n / 2 - 100]) / v0;
        assert!((kept - 0.5).abs() < 0.03, "linear kept {kept}");
    }

    /// The true unit answers its voltage as it is: the record's default playback smooths the
    /// voltage at 4 Hz (for the measured input's noise), the truth must not. An ambient profile
    /// has content above 4 Hz (little, band-limited at [`AMBIENT_BAND_HZ`]); the unit played
    /// back on the noiseless record as recorded gives the record's P and Q, but for the slow
    /// start from the pre-event means (P and Q wander there too): the difference's
    /// sample-to-sample steps are below 1e-5 pu. With the truth played smoothed they are
    /// 2.7e-4 pu here (6e-3 pu, three times a PMU's P noise, on the ambient profile before it was
    /// band-limited, shaped by the unit's modes into a peak a diagnosis read as a shaft mode).
    #[test]
    fn the_truth_answers_every_frequency_of_its_voltage() {
        let unit = crate::unit_file::parse_unit(
            include_str!("../../../data/synthetic/unit_gensae_sexs_stab3_hygov.toml"),
            std::path::Path::new("data/synthetic/unit_gensae_sexs_stab3_hygov.toml"),
        )
        .unwrap();
        let profile = VoltageProfile::preset(EventKind::Ambient, 20.0, 60.0, 101);
        let sim = SimOptions::default();
        let ev = synthesize("ambient", &unit, &profile, 737.0, &PmuNoise::none(), &sim).unwrap();
        assert_eq!(
            ev.input_lowpass_hz,
            Some(crate::event::smoothing::DEFAULT_CUTOFF_HZ)
        );
        let mut raw = ev.clone();
        raw.set_input_lowpass(None).unwrap();
        let (p, q) = simulate_pq(&mut unit.clone(), &PreparedEvent::new(&raw), &sim).unwrap();
        let r = &ev.record;
        for (name, sim, rec) in [("P", &p, &r.p_pu), ("Q", &q, &r.q_pu)] {
            let d: Vec<f64> = sim.iter().zip(rec).map(|(a, b)| a - b).collect();
            let steps =
                d.windows(2).map(|w| (w[1] - w[0]).powi(2)).sum::<f64>() / (d.len() - 1) as f64;
            assert!(
                steps.sqrt() < 1e-5,
                "{name}: steps of the difference {:.2e} pu",
                steps.sqrt()
            );
        }
    }

    #[test]
    fn presets_make_their_event() {
        let (_, v, a) = VoltageProfile::preset(EventKind::VoltageStep, 5.0, 60.0, 1).samples();
        assert!((v[0] - 1.0).abs() < 1e-12 && (v[v.len() - 1] - 1.005).abs() < 1e-3);
        assert!(a.iter().all(|x| (x - 0.3).abs() < 0.02));
        let (t, v, a) =
            VoltageProfile::preset(EventKind::FrequencyExcursion, 10.0, 30.0, 1).samples();
        assert_eq!(t.len(), 301);
        assert!(v.iter().all(|x| (x - 1.0).abs() < 0.03), "no dip");
        let n = t.len();
        let slope = (a[n - 1] - a[n - 31]) / (t[n - 1] - t[n - 31]) / (2.0 * std::f64::consts::PI);
        assert!((slope + 0.3).abs() < 0.05, "frequency fall {slope}");
        let (_, v, a) = VoltageProfile::preset(EventKind::Ambient, 20.0, 60.0, 3).samples();
        let sd = |x: &[f64]| {
            let m = x.iter().sum::<f64>() / x.len() as f64;
            (x.iter().map(|v| (v - m).powi(2)).sum::<f64>() / x.len() as f64).sqrt()
        };
        assert!(
            sd(&v) > 0.001 && sd(&v) < 0.006,
            "ambient |V| spread {}",
            sd(&v)
        );
        assert!(sd(&a) > 0.003, "ambient angle spread {}", sd(&a));
        // Band-limited (AMBIENT_BAND_HZ): the fluctuation's own sample-to-sample steps stay
        // below a typical PMU's angle noise (5e-4 rad), so what a 4 Hz playback smooths away is
        // the noise's; the raw process steps by about 1.5e-3 rad a sample.
        let steps: Vec<f64> = a.windows(2).map(|w| w[1] - w[0]).collect();
        let rms = (steps.iter().map(|d| d * d).sum::<f64>() / steps.len() as f64).sqrt();
        assert!(
            rms < PmuNoise::typical(0).angle_sigma,
            "ambient angle steps {rms:.2e}"
        );
    }

    #[test]
    fn profile_has_the_dip_and_the_frequency_drift() {
        let p = VoltageProfile::default();
        let (t, v, a) = p.samples();
        assert_eq!(t.len(), 1201);
        let k_dip = (1.05 * 60.0) as usize;
        assert_eq!(v[k_dip], 0.7);
        // Late slope of the angle: 2π Δf.
        let n = t.len();
        let slope = (a[n - 1] - a[n - 61]) / (t[n - 1] - t[n - 61]);
        assert!(
            (slope / (2.0 * std::f64::consts::PI) + 0.2).abs() < 0.01,
            "slope {slope}"
        );
    }
}
#[cfg(test)]
mod delay_dual_tests {
    use super::*;
    use crate::sens::D;

    /// The delay's derivative against differences of [`delayed`], at a fraction of a sample
    /// and at no delay (one-sided: the delay cannot be negative).
    #[test]
    fn the_delay_s_derivative_is_the_interpolation_s_slope() {
        let t: Vec<f64> = (0..300).map(|k| k as f64 / 60.0).collect();
        let y: Vec<f64> = t
            .iter()
            .map(|t| (2.0 * t).sin() + 0.3 * (7.0 * t).cos())
            .collect();
        let yd: Vec<D> = y
            .iter()
            .map(|&v| D::new(v, [0.0; crate::sens::LANES]))
            .collect();
        for tau0 in [0.0, 0.004, 1.0 / 60.0, 0.025] {
            let out = delayed_dual(&t, &yd, D::var(tau0, 0));
            let h = 1e-7;
            let (f0, f1, f2) = (
                delayed(&t, &y, tau0),
                delayed(&t, &y, tau0 + h),
                delayed(&t, &y, tau0 + 2.0 * h),
            );
            for k in 0..300 {
                let fd = (-3.0 * f0[k] + 4.0 * f1[k] - f2[k]) / (2.0 * h);
                assert!(
                    (out[k].d[0] - fd).abs() < 1e-5 * 2.0,
                    "tau {tau0} k {k}: {} for {fd}",
                    out[k].d[0]
                );
            }
        }
    }
}

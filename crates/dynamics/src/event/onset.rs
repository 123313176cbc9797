//! The onset of an event's disturbance, found in the data: [`detect_onset`].
//!
//! One definition for every path (an event TOML, a COMTRADE or C37 import, an in-memory event,
//! the practice cases) and every user of it (the default init window, the diagnosis' windows,
//! its noise estimate and its fit/held-out split): the first sample at which the record departs
//! from its pre-event course in a way that its own noise and ambient background do not explain,
//! or none (ambient data).
//!
//! # The rule
//!
//! **Channels.** |V|, the unwrapped voltage angle, P and Q. A fault dips |V| (and steps the
//! angle), a voltage step steps |V|, a frequency event (generation lost elsewhere) bends the angle
//! (its rate is the frequency) and moves P while barely moving |V|. The angle is used, not a
//! `freq_hz` column: a PMU's frequency is a filtered derivative of the angle (the practice
//! records' is a centred 5-sample average, which shows a change before it happens), so its
//! timing is not the measurement's.
//!
//! **Statistics, one per channel and window length L.** For |V|, P and Q the two-window
//! difference `median(x[k..k+L]) − median(x[k−L..k])`: a level change at sample k. Medians make
//! the departure *sustained*: a window's median moves only when most of its samples have moved,
//! so one bad sample (a spike, a drop-out) cannot trigger it. For the angle the change of slope
//! `(a[k+L] − 2 a[k] + a[k−L]) / L`: a change of frequency at k. The windows are 3 samples (the
//! shortest whose median ignores one bad sample), doubling while `L` lasts at most
//! [`ONSET_MAX_WINDOW_S`] (0.25 s): short against the slow ambient background (frequency wander
//! over seconds, inter-area swings below 1 Hz), which is then nearly linear across the two
//! windows, and long enough to add up the slow start of a frequency event.
//!
//! **Their scale under "no event".** The measurement noise alone (the MAD of first differences,
//! which the slow background barely moves) is not enough: on the practice set's ambient records
//! the 3-sample statistics spread 1.5 to 3.5 times, the 12-sample ones 3 to 10 times, more than
//! white noise would make them; the ambient background moves them. So each statistic's scale is
//! measured on the record itself: 1.4826 × its median absolute deviation over every position,
//! which the few positions an onset touches cannot move. (The disturbance's own aftermath, a
//! swing lasting seconds, can only make it larger: conservative.) The scale is floored at the
//! quantisation step's contribution (`q/√12`; P and Q of some PMUs move in steps) and at 1e-9,
//! below any instrument's resolution, so a noiseless record has no false onsets from rounding.
//!
//! **The threshold, from a false-alarm probability.** Standardised, each statistic is close to
//! a standard normal under "no event" (a median or a sum of noise and background). With `n`
//! statistics evaluated over the record (every channel, window and position), the threshold `h`
//! solves `2 n (1 − Φ(h)) = α` with α = [`ONSET_FALSE_ALARM`] = 1 %: by the union bound, the
//! probability that pure noise and background cross it anywhere in the record is at most 1 %
//! (h ≈ 4.8-5.1 for records of 20-30 s at 30-60 samples/s). The first position at which any
//! standardised statistic crosses ±h is the detection.
//!
//! **Back-dating to where the departure starts.** A crossing is not the start: a long window
//! crosses before the change (it looks ahead) and a short one where the change is steepest. So
//! the start is located near the detection (within the detecting window on either side):
//! 1. at the shortest window at which some channel also crosses ±h there, taking |V| first, then
//!    the angle, then P or Q (the larger crossing): |V| and the angle are the measured input the
//!    playback drives the model with, and by causality the unit's P and Q answer them, not lead
//!    them (an output channel is used only when the inputs do not cross, as in a frequency event
//!    that barely moves |V|);
//! 2. on that channel, the pre-event course is the mean (the angle: the least-squares line) of
//!    the [`ONSET_REFERENCE_S`] (0.5 s) ending one window before the crossing, and the onset is
//!    the first sample from there on that, together with the next one, departs from it by more
//!    than [`ONSET_LOCATE_SD`] (3) white-noise standard deviations in the crossing's direction
//!    (two in a row: a single sample beyond 3 sd happens by chance once in 370, two in 10⁵).
//!
//! `crates/calib/examples/onset.rs` scores the rule on a set of records with known event times.

use serde::Serialize;

use super::Record;

/// Probability that a record of noise and ambient background alone gets an onset (the union
/// bound over every statistic evaluated; see the module documentation).
pub const ONSET_FALSE_ALARM: f64 = 0.01;

/// The shortest window of the statistics, samples: the shortest whose median ignores one bad
/// sample.
pub const ONSET_MIN_WINDOW: usize = 3;

/// The windows double from [`ONSET_MIN_WINDOW`] while they last at most this long, s.
pub const ONSET_MAX_WINDOW_S: f64 = 0.25;

/// Length of the pre-event reference the onset is back-dated against, s.
pub const ONSET_REFERENCE_S: f64 = 0.5;

/// A sample departs from the pre-event reference when it lies this many white-noise standard
/// deviations away (and the next one too).
pub const ONSET_LOCATE_SD: f64 = 3.0;

/// Resolution floor of every scale (pu, rad): below any instrument's, above rounding.
const RESOLUTION: f64 = 1e-9;

/// A channel the detector watches.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum OnsetChannel {
    /// |V|, level changes.
    VoltageMagnitude,
    /// The voltage angle, changes of its slope (the frequency).
    Angle,
    /// P, level changes.
    ActivePower,
    /// Q, level changes.
    ReactivePower,
}

impl OnsetChannel {
    const ALL: [OnsetChannel; 4] = [
        OnsetChannel::VoltageMagnitude,
        OnsetChannel::Angle,
        OnsetChannel::ActivePower,
        OnsetChannel::ReactivePower,
    ];

    /// Short name: `|V|`, `angle`, `P`, `Q`.
    pub fn label(&self) -> &'static str {
        match self {
            OnsetChannel::VoltageMagnitude => "|V|",
            OnsetChannel::Angle => "angle",
            OnsetChannel::ActivePower => "P",
            OnsetChannel::ReactivePower => "Q",
        }
    }

    /// What the statistic measures on this channel.
    fn statistic(&self) -> &'static str {
        match self {
            OnsetChannel::Angle => "slope change",
            _ => "level change",
        }
    }

    /// Localisation preference: the measured input (|V|, then the angle) before the unit's
    /// answer (P, Q).
    fn priority(&self) -> u8 {
        match self {
            OnsetChannel::VoltageMagnitude => 0,
            OnsetChannel::Angle => 1,
            OnsetChannel::ActivePower | OnsetChannel::ReactivePower => 2,
        }
    }

    fn series<'a>(&self, r: &'a Record) -> &'a [f64] {
        match self {
            OnsetChannel::VoltageMagnitude => &r.v_mag_pu,
            OnsetChannel::Angle => &r.v_ang_rad,
            OnsetChannel::ActivePower => &r.p_pu,
            OnsetChannel::ReactivePower => &r.q_pu,
        }
    }
}

/// A standardised statistic at one position: which channel, which window, how large.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Crossing {
    pub channel: OnsetChannel,
    /// Window length, samples, and in seconds (at the record's median interval).
    pub window_samples: usize,
    pub window_s: f64,
    /// The statistic in units of its scale under "no event" (signed).
    pub size_sd: f64,
    /// Time of the position (the first sample of the window after it), s.
    pub time_s: f64,
}

/// What [`detect_onset`] found, and the numbers behind it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OnsetDetection {
    /// Time of the first sample of the disturbance, s; `None`: no statistic crossed the
    /// threshold (ambient data, or too short a record).
    pub onset_s: Option<f64>,
    /// Index of that sample in the record.
    pub index: Option<usize>,
    /// The first crossing of the threshold (what detected the disturbance).
    pub trigger: Option<Crossing>,
    /// The crossing the onset was back-dated from (see the module documentation).
    pub located_on: Option<Crossing>,
    /// White-noise standard deviation of `located_on`'s channel (pu or rad).
    pub noise_sd: Option<f64>,
    /// The largest standardised statistic anywhere in the record (with no onset: how far below
    /// the threshold the record stayed).
    pub largest: Option<Crossing>,
    /// The threshold, in standard deviations of each statistic.
    pub threshold_sd: f64,
    /// The false-alarm probability it was derived from.
    pub false_alarm: f64,
    /// Number of statistics evaluated (the union bound's n).
    pub tests: usize,
}

impl OnsetDetection {
    /// One line for a report: when and why, or why not.
    pub fn describe(&self) -> String {
        let cross = |c: &Crossing| {
            format!(
                "the {} of {} over {}-sample windows ({:.3} s) reached {:.1} sd at {:.4} s",
                c.channel.statistic(),
                c.channel.label(),
                c.window_samples,
                c.window_s,
                c.size_sd,
                c.time_s
            )
        };
        match (self.onset_s, &self.trigger, &self.located_on) {
            (Some(t), Some(trig), Some(loc)) => {
                let mut s = format!(
                    "onset {t:.4} s: {} (threshold {:.2} sd: {} % false-alarm probability over {} statistics)",
                    cross(trig),
                    self.threshold_sd,
                    self.false_alarm * 100.0,
                    self.tests
                );
                if loc.channel != trig.channel || loc.window_samples != trig.window_samples {
                    s.push_str(&format!(
                        "; back-dated on {} ({}-sample windows, {:.1} sd)",
                        loc.channel.label(),
                        loc.window_samples,
                        loc.size_sd
                    ));
                } else {
                    s.push_str("; back-dated on the same channel");
                }
                s.push_str(&format!(
                    " to the first of two samples beyond {ONSET_LOCATE_SD} noise sd of the pre-event course"
                ));
                s
            }
            _ => match &self.largest {
                Some(l) => format!(
                    "no onset: no statistic reached the threshold {:.2} sd ({} % false-alarm probability over {} statistics); the largest, {}",
                    self.threshold_sd,
                    self.false_alarm * 100.0,
                    self.tests,
                    cross(l)
                ),
                None => "no onset: the record is too short for the detector".into(),
            },
        }
    }
}

/// Upper tail of the standard normal, `1 − Φ(z)`, for z ≥ 0 (relative error below 1.2e-7:
/// the Chebyshev fit of `erfc` in Numerical Recipes).
fn normal_upper_tail(z: f64) -> f64 {
    let x = z / std::f64::consts::SQRT_2;
    let t = 1.0 / (1.0 + 0.5 * x.abs());
    let erfc = t
        * (-x * x - 1.26551223
            + t * (1.00002368
                + t * (0.37409196
                    + t * (0.09678418
                        + t * (-0.18628806
                            + t * (0.27886807
                                + t * (-1.13520398
                                    + t * (1.48851587 + t * (-0.82215223 + t * 0.17087277)))))))))
            .exp();
    0.5 * erfc
}

/// The z with `1 − Φ(z) = p` (0 < p < 0.5), by bisection.
pub(crate) fn normal_upper_quantile(p: f64) -> f64 {
    let (mut lo, mut hi) = (0.0_f64, 40.0_f64);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if normal_upper_tail(mid) > p {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

fn median_of(v: &mut [f64]) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len();
    if n == 0 {
        f64::NAN
    } else if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// 1.4826 × the median absolute deviation about the median: the standard deviation of
/// Gaussian data, unmoved by a minority of outliers.
pub(crate) fn robust_sd(v: &[f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let mut w = v.to_vec();
    let m = median_of(&mut w);
    let mut d: Vec<f64> = v.iter().map(|x| (x - m).abs()).collect();
    1.4826 * median_of(&mut d)
}

/// The smallest non-zero step between consecutive samples (the quantum of a quantised channel;
/// a tiny number for an unquantised one).
pub(crate) fn quantum(x: &[f64]) -> f64 {
    let q = x
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .filter(|d| *d > 0.0)
        .fold(f64::INFINITY, f64::min);
    if q.is_finite() {
        q
    } else {
        0.0
    }
}

/// Medians of every window `x[k..k+len]`, k = 0..=n−len (a sorted window slid along).
fn sliding_medians(x: &[f64], len: usize) -> Vec<f64> {
    let n = x.len();
    if len == 0 || n < len {
        return vec![];
    }
    let mut win: Vec<f64> = x[..len].to_vec();
    win.sort_by(|a, b| a.total_cmp(b));
    let med = |w: &[f64]| {
        if len % 2 == 1 {
            w[len / 2]
        } else {
            0.5 * (w[len / 2 - 1] + w[len / 2])
        }
    };
    let mut out = Vec::with_capacity(n - len + 1);
    out.push(med(&win));
    for k in len..n {
        let old = x[k - len];
        let pos = win.partition_point(|v| v.total_cmp(&old).is_lt());
        win.remove(pos);
        let new = x[k];
        let pos = win.partition_point(|v| v.total_cmp(&new).is_lt());
        win.insert(pos, new);
        out.push(med(&win));
    }
    out
}

/// One standardised statistic series: `z[k]` for positions `k` (None where undefined).
struct Series {
    channel: OnsetChannel,
    window: usize,
    z: Vec<Option<f64>>,
}

/// The raw statistic of `channel` at window `len` for every position (None where the windows
/// do not fit in the record).
fn statistic(channel: OnsetChannel, x: &[f64], len: usize) -> Vec<Option<f64>> {
    let n = x.len();
    let mut s = vec![None; n];
    if n < 2 * len + 1 {
        return s;
    }
    match channel {
        OnsetChannel::Angle => {
            for (k, sk) in s.iter_mut().enumerate().take(n - len).skip(len) {
                *sk = Some((x[k + len] - 2.0 * x[k] + x[k - len]) / len as f64);
            }
        }
        _ => {
            // m[j] = median of x[j..j+len]; after k: m[k], before k: m[k-len].
            let m = sliding_medians(x, len);
            for (k, sk) in s.iter_mut().enumerate().take(n - len + 1).skip(len) {
                *sk = Some(m[k] - m[k - len]);
            }
        }
    }
    s
}

/// Quantisation and resolution floor of the scale of `channel`'s statistic at window `len`.
fn scale_floor(channel: OnsetChannel, x: &[f64], len: usize) -> f64 {
    let sq = quantum(x) / 12f64.sqrt();
    let f = match channel {
        OnsetChannel::Angle => sq * 6f64.sqrt() / len as f64,
        _ => sq * (2.0 / len as f64).sqrt(),
    };
    f.max(RESOLUTION)
}

/// White-noise standard deviation of a channel: from first differences (|V|, P, Q) or second
/// differences (the angle, whose slope is the frequency), floored as the statistics are.
fn white_sd(channel: OnsetChannel, x: &[f64]) -> f64 {
    let sd = match channel {
        OnsetChannel::Angle => {
            let d2: Vec<f64> = x.windows(3).map(|w| w[2] - 2.0 * w[1] + w[0]).collect();
            robust_sd(&d2) / 6f64.sqrt()
        }
        _ => {
            let d: Vec<f64> = x.windows(2).map(|w| w[1] - w[0]).collect();
            robust_sd(&d) / 2f64.sqrt()
        }
    };
    sd.max(quantum(x) / 12f64.sqrt()).max(RESOLUTION)
}

/// Finds the onset of the disturbance in `record` (see the module documentation for the rule
/// and its justification). Never fails: a record too short for the shortest windows, or whose
/// statistics all stay below the threshold, has no onset.
pub fn detect_onset(record: &Record) -> OnsetDetection {
    let n = record.len();
    let t = &record.time_s;
    let mut out = OnsetDetection {
        onset_s: None,
        index: None,
        trigger: None,
        located_on: None,
        noise_sd: None,
        largest: None,
        threshold_sd: f64::INFINITY,
        false_alarm: ONSET_FALSE_ALARM,
        tests: 0,
    };
    if n < 2 * ONSET_MIN_WINDOW + 2 {
        return out;
    }
    let mut dts: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    let dt = median_of(&mut dts);
    let mut windows = vec![];
    let mut len = ONSET_MIN_WINDOW;
    while (len as f64) * dt <= ONSET_MAX_WINDOW_S * (1.0 + 1e-9) || len == ONSET_MIN_WINDOW {
        if n < 2 * len + 2 {
            break;
        }
        windows.push(len);
        len *= 2;
    }

    // Standardised statistics.
    let mut series = vec![];
    for ch in OnsetChannel::ALL {
        let x = ch.series(record);
        for &l in &windows {
            let raw = statistic(ch, x, l);
            let vals: Vec<f64> = raw.iter().flatten().copied().collect();
            if vals.is_empty() {
                continue;
            }
            let scale = robust_sd(&vals).max(scale_floor(ch, x, l));
            out.tests += vals.len();
            series.push(Series {
                channel: ch,
                window: l,
                z: raw.iter().map(|v| v.map(|v| v / scale)).collect(),
            });
        }
    }
    if out.tests == 0 {
        return out;
    }
    let h = normal_upper_quantile(ONSET_FALSE_ALARM / (2.0 * out.tests as f64));
    out.threshold_sd = h;
    let crossing = |s: &Series, k: usize| Crossing {
        channel: s.channel,
        window_samples: s.window,
        window_s: s.window as f64 * dt,
        size_sd: s.z[k].unwrap_or(0.0),
        time_s: t[k],
    };

    // The largest statistic, and the detection: the earliest crossing of ±h (of two at the
    // same position, the larger).
    let size = |(i, k): (usize, usize)| series[i].z[k].map_or(0.0, f64::abs);
    let mut largest: Option<(usize, usize)> = None; // (series, position)
    let mut first: Option<(usize, usize)> = None;
    for (i, s) in series.iter().enumerate() {
        let mut crossed = false;
        for (k, z) in s.z.iter().enumerate() {
            let Some(z) = z else { continue };
            if !matches!(largest, Some(l) if z.abs() <= size(l)) {
                largest = Some((i, k));
            }
            if !crossed && z.abs() > h {
                crossed = true;
                let better = match first {
                    None => true,
                    Some((j, m)) => k < m || (k == m && z.abs() > size((j, m))),
                };
                if better {
                    first = Some((i, k));
                }
            }
        }
    }
    out.largest = largest.map(|(i, k)| crossing(&series[i], k));
    let Some((di, dk)) = first else {
        return out;
    };
    out.trigger = Some(crossing(&series[di], dk));

    // Where the departure starts: the shortest window at which a channel crosses near the
    // detection, |V| before the angle before P and Q.
    let dl = series[di].window;
    let (lo, hi) = (dk.saturating_sub(dl), (dk + dl + 1).min(n));
    let mut located: Option<(usize, usize, f64)> = None; // (series, first crossing, sign)
    for &l in windows.iter().filter(|&&l| l <= dl) {
        // (priority, -|peak|, series, first crossing, sign)
        let mut best: Option<(u8, f64, usize, usize, f64)> = None;
        for (i, s) in series.iter().enumerate().filter(|(_, s)| s.window == l) {
            let Some(k1) = (lo..hi).find(|&k| s.z[k].is_some_and(|z| z.abs() > h)) else {
                continue;
            };
            let sign = s.z[k1].unwrap_or(0.0).signum();
            let peak = (k1..n)
                .map_while(|k| s.z[k].filter(|z| sign * z > h))
                .fold(0.0_f64, |m, z| m.max(z.abs()));
            let key = (s.channel.priority(), -peak);
            if !matches!(best, Some(b) if key >= (b.0, b.1)) {
                best = Some((key.0, key.1, i, k1, sign));
            }
        }
        if let Some((_, _, i, k1, sign)) = best {
            located = Some((i, k1, sign));
            break;
        }
    }
    let (li, k1, sign) = located.unwrap_or((di, dk, series[di].z[dk].unwrap_or(0.0).signum()));
    let s = &series[li];
    out.located_on = Some(crossing(s, k1));
    let x = s.channel.series(record);
    let sd = white_sd(s.channel, x);
    out.noise_sd = Some(sd);

    // The pre-event course: ONSET_REFERENCE_S ending one window before the crossing.
    let w = ((ONSET_REFERENCE_S / dt).round() as usize).max(3);
    let r1 = k1.saturating_sub(s.window);
    let r0 = r1.saturating_sub(w);
    let onset = if r1 - r0 >= 2 {
        let tr = &t[r0..r1];
        let xr = &x[r0..r1];
        let m = tr.len() as f64;
        let (tm, xm) = (tr.iter().sum::<f64>() / m, xr.iter().sum::<f64>() / m);
        let slope = if s.channel == OnsetChannel::Angle && tr.len() >= 3 {
            let sxx: f64 = tr.iter().map(|v| (v - tm).powi(2)).sum();
            let sxy: f64 = tr.iter().zip(xr).map(|(a, b)| (a - tm) * (b - xm)).sum();
            if sxx > 0.0 {
                sxy / sxx
            } else {
                0.0
            }
        } else {
            0.0
        };
        let dep = |j: usize| sign * (x[j] - (xm + slope * (t[j] - tm))) / sd;
        let end = (k1 + 2 * s.window).min(n - 1);
        (r1..end)
            .find(|&j| dep(j) > ONSET_LOCATE_SD && dep(j + 1) > ONSET_LOCATE_SD)
            .unwrap_or(k1)
    } else {
        k1
    };
    out.index = Some(onset);
    out.onset_s = Some(t[onset]);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_quantile_matches_known_values() {
        for (p, z) in [(0.025, 1.959964), (1e-3, 3.090232), (1e-7, 5.199338)] {
            let q = normal_upper_quantile(p);
            assert!((q - z).abs() < 1e-5, "{p}: {q} vs {z}");
        }
    }

    #[test]
    fn sliding_medians_equal_direct_medians() {
        let x: Vec<f64> = (0..40)
            .map(|i| ((i * 37 % 11) as f64) - 0.5 * i as f64)
            .collect();
        for len in [1, 2, 3, 4, 7] {
            let m = sliding_medians(&x, len);
            assert_eq!(m.len(), x.len() - len + 1);
            for (k, v) in m.iter().enumerate() {
                let mut w = x[k..k + len].to_vec();
                assert_eq!(*v, median_of(&mut w), "len {len} k {k}");
            }
        }
    }

    #[test]
    fn quantum_is_the_smallest_step() {
        assert_eq!(quantum(&[1.0, 1.0, 1.0]), 0.0);
        assert!((quantum(&[0.0, 0.0028, 0.0014, 0.0014]) - 0.0014).abs() < 1e-15);
    }
}

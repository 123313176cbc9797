//! The noise floor of a measured channel: one definition, used by the fit's report (its noise
//! table and fit statistics), the diagnosis (its χ² weights, the evidence's RMS/noise, the
//! verdict's "at the noise floor") and every front end that shows them.
//!
//! **Definition.** The noise floor σ of channel `y` (P or Q) of an event, for a unit, is the
//! standard deviation of the unit's residual `r = simulated − measured` over the event's
//! pre-event samples (before [`itaipu_dynamics::event::Event::onset_s`], or the end of the init
//! window for a record with no disturbance): there a right model is in steady state, so the
//! residual holds the measurement noise and the played-back input noise propagated through the
//! model, white or not, and nothing of the event. With fewer than [`MIN_PRE_SAMPLES`] pre-event
//! samples, the difference-based floor of the residual over the whole record
//! ([`crate::evidence::noise_floor`]). And never below the quantisation floor `q/√12` of a
//! channel recorded with a quantum `q` ([`quantum`]): a quantiser adds at least that much
//! uniform noise, even where the signal happens not to cross a level (the Itaipu record's P
//! before the fault, constant to the last digit for 57 samples, would otherwise report a noise
//! of 1e-5 pu).
//!
//! **The headline.** [`assess`] plays a unit back once per event and gives every compared
//! channel's floor and the unit's residual RMS over the event's fit window against it
//! ([`NoiseRow`]), and the one sentence every front end shows ([`Headline`]): the largest
//! RMS/σ over the events and channels, "at most X × the noise σ". The fit's report (for the
//! calibrated unit), the diagnosis (for the unit it is given), the command line and Python all
//! read it from here, so that one unit on one record gets one number.

use itaipu_dynamics::event::{Channel, Event};
use itaipu_dynamics::mode::PlaybackMode;
use itaipu_dynamics::unit::Unit;
use serde::{Deserialize, Serialize};

/// What the reports call the noise σ ([`noise_floor`]), in one phrase.
pub const NOISE_DEFINITION: &str = "the noise σ of a channel is the standard deviation of the \
unit's residual before the event's onset (with fewer than 10 pre-event samples, the residual's \
difference-based floor; never below a quantised channel's q/√12)";

/// A residual is at the noise floor when its RMS is at most this multiple of the noise σ: a
/// model that reproduces the record leaves the noise (ratio 1) plus the played-back input's
/// noise propagated through it and the estimation error of σ from a few dozen pre-event
/// samples (about 1/√(2·60) ≈ 10 % for a second at 60 samples/s), well inside 1.5.
pub const AT_NOISE: f64 = 1.5;
/// A residual above this multiple of the noise σ is far above it: nine times the noise
/// variance is a misfit no noise estimate's error explains.
pub const FAR_ABOVE_NOISE: f64 = 3.0;

/// Pre-event samples needed for the pre-event standard deviation (below, the difference-based
/// floor over the record): with 10 samples the standard deviation's relative standard error is
/// about 1/√(2·9) = 24 %, about what a noise floor may be off by and still order the evidence.
pub const MIN_PRE_SAMPLES: usize = 10;

/// The smallest noise floor reported [pu]: a residual of exactly zero (a model playing back its
/// own noiseless output) must not divide by zero.
pub const SIGMA_MIN: f64 = 1e-6;

/// How a noise floor was obtained.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NoiseMethod {
    /// Standard deviation of the residual before the onset.
    PreEvent,
    /// Difference-based floor of the residual over the record (too few pre-event samples).
    Differences,
    /// The quantisation floor `q/√12` (the estimate fell below it).
    Quantum,
}

/// The noise floor of one channel of one event ([`noise_floor`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct NoiseFloor {
    pub sigma: f64,
    /// Samples the estimate was taken over.
    pub samples: usize,
    pub method: NoiseMethod,
    /// The channel's quantum, when it is quantised ([`quantum`]).
    pub quantum: Option<f64>,
}

/// The quantum `q` of a quantised channel: the smallest non-zero change between consecutive
/// samples, when at least 90 % of the non-zero changes are whole multiples of it (within 1 %)
/// and there are at least 10 of them; `None` for a channel that is not quantised (continuous
/// noise makes the ratios of its changes anything).
pub fn quantum(y: &[f64]) -> Option<f64> {
    let d: Vec<f64> = y
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .filter(|x| *x > 0.0 && x.is_finite())
        .collect();
    if d.len() < 10 {
        return None;
    }
    let q = d.iter().copied().fold(f64::INFINITY, f64::min);
    // A level step is at least a few ulps of the value; smaller is rounding, not a quantiser.
    let scale = y.iter().map(|v| v.abs()).fold(0.0, f64::max).max(1.0);
    if !(q > 1e-9 * scale) {
        return None;
    }
    let whole = d
        .iter()
        .filter(|x| {
            let r = *x / q;
            (r - r.round()).abs() < 0.01
        })
        .count();
    (whole as f64 >= 0.9 * d.len() as f64).then_some(q)
}

/// The noise floor of channel `measured` of `event` for a unit whose simulated channel is
/// `simulated` (both at the event's samples): see the module documentation.
pub fn noise_floor(event: &Event, simulated: &[f64], measured: &[f64]) -> NoiseFloor {
    let residual: Vec<f64> = simulated.iter().zip(measured).map(|(s, m)| s - m).collect();
    let onset = pre_event_end(event);
    let pre: Vec<f64> = event
        .record
        .time_s
        .iter()
        .zip(&residual)
        .filter(|(t, _)| **t < onset)
        .map(|(_, r)| *r)
        .collect();
    let (mut sigma, mut samples, mut method) = if pre.len() >= MIN_PRE_SAMPLES {
        (std_dev(&pre), pre.len(), NoiseMethod::PreEvent)
    } else {
        (
            crate::evidence::noise_floor(&residual),
            residual.len(),
            NoiseMethod::Differences,
        )
    };
    let q = quantum(measured);
    if let Some(q) = q {
        let floor = q / 12f64.sqrt();
        if !(sigma >= floor) {
            sigma = floor;
            method = NoiseMethod::Quantum;
            samples = measured.len();
        }
    }
    NoiseFloor {
        sigma: sigma.max(SIGMA_MIN),
        samples,
        method,
        quantum: q,
    }
}

/// The weights of `channels = "recorded"` ([`crate::spec::Channels::Recorded`]) for the fitted
/// `events`: each field channel ([`itaipu_dynamics::event::FIELD_CHANNELS`]) that every event
/// records (the `held_out` ones too: a held-out event is compared on the same channels), with `w_c = σ_PQ²/σ_c²` against P and Q at weight 1. Each σ² is the mean over the events of
/// the squared difference-based floor ([`crate::evidence::noise_floor`]) of the measured
/// channel over the event's init window (the measurement alone: the weights are set before any
/// model is calibrated), and σ_PQ² the mean of σ_P² and σ_Q². Weighting each channel by its
/// inverse noise variance makes the objective the likelihood of independent Gaussian noise.
/// A channel whose floor is zero (constant over the window) is left out.
pub fn field_weights(
    events: &[&Event],
    held_out: &[&Event],
) -> Vec<(itaipu_dynamics::event::Channel, f64)> {
    use itaipu_dynamics::event::Channel;
    if events.is_empty() {
        return vec![];
    }
    let floor = |e: &Event, c: Channel| -> f64 {
        let Some(y) = e.series(c) else { return 0.0 };
        let init: Vec<f64> = e
            .record
            .time_s
            .iter()
            .zip(y)
            .filter(|(t, _)| **t >= e.init.start_s && **t <= e.init.end_s)
            .map(|(_, v)| *v)
            .collect();
        crate::evidence::noise_floor(&init)
    };
    let n = events.len() as f64;
    let mean_var = |c: Channel| {
        events
            .iter()
            .map(|e| {
                let s = floor(e, c);
                s * s
            })
            .sum::<f64>()
            / n
    };
    let pq = events
        .iter()
        .map(|e| 0.5 * (floor(e, Channel::P).powi(2) + floor(e, Channel::Q).powi(2)))
        .sum::<f64>()
        / n;
    itaipu_dynamics::event::field_recorded_by_all(events.iter().chain(held_out).copied())
        .into_iter()
        .filter_map(|c| {
            let s2 = mean_var(c);
            (s2 > 0.0 && pq > 0.0).then(|| (c, pq / s2))
        })
        .collect()
}

/// One compared channel of one event: its noise floor and the unit's residual against it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChannelNoise {
    /// The channel as the reports name it (`P`, `Q`, `|V|`, `Efd`, `Ifd`).
    pub signal: String,
    pub floor: NoiseFloor,
    /// RMS of the residual `simulated − measured` over the event's fit window [pu].
    pub rms: f64,
    /// `rms / floor.sigma`.
    pub ratio: f64,
}

/// The noise of one event for a unit ([`assess`]): every compared channel's floor and the
/// residual against it. `sigma_p`, `sigma_q` (and `p`, `q`) repeat P's and Q's floors when
/// they are compared (`null` otherwise).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NoiseRow {
    pub event: String,
    pub held_out: bool,
    /// Samples in the event's fit window (what each RMS is taken over).
    pub samples: usize,
    pub sigma_p: Option<f64>,
    pub sigma_q: Option<f64>,
    pub p: Option<NoiseFloor>,
    pub q: Option<NoiseFloor>,
    pub channels: Vec<ChannelNoise>,
    /// Why the unit could not be played back on the event (no floor then).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

impl NoiseRow {
    /// The floor σ of `signal` (`P`, `Q`, `|V|`, `Efd`, `Ifd`), when compared.
    pub fn sigma(&self, signal: &str) -> Option<f64> {
        self.channels
            .iter()
            .find(|c| c.signal == signal)
            .map(|c| c.floor.sigma)
    }
}

/// The one sentence on how far a unit's residual lies above the noise ([`assess`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Headline {
    /// The unit it is about.
    pub unit: String,
    /// The playback and its compared channels (`"phasor: P, Q"`).
    pub playback: String,
    /// The playback's mode (what a report's figures play the events back in).
    pub mode: PlaybackMode,
    /// The largest RMS/σ over the events (fitted and held out) and compared channels; `None`
    /// when a noise floor or a residual could not be measured.
    pub worst: Option<f64>,
    /// Where it is: event and signal, the residual's RMS and the floor σ [pu].
    pub event: String,
    pub signal: String,
    pub rms: f64,
    pub sigma: f64,
    /// [`AT_NOISE`] and [`FAR_ABOVE_NOISE`], as the sentence quotes them.
    pub at_noise: f64,
    pub far_above_noise: f64,
    /// The sentence ([`Headline::text`]).
    pub sentence: String,
}

impl Headline {
    /// `worst` as the sentence prints it (two decimals).
    pub fn worst_text(&self) -> Option<String> {
        self.worst.map(|w| format!("{w:.2}"))
    }

    /// The sentence split around the printed `worst` (`(before, worst, after)`), for a page that
    /// marks the number up; `None` when there is no number.
    pub fn parts(&self) -> Option<(&str, String, &str)> {
        let w = self.worst_text()?;
        let k = self.sentence.find(&format!("at most {w} "))? + "at most ".len();
        let end = k + w.len();
        Some((&self.sentence[..k], w, &self.sentence[end..]))
    }

    fn text(
        unit: &str,
        worst: Option<f64>,
        at: Option<(&str, &str, f64, f64)>,
        why: &str,
    ) -> String {
        match (worst, at) {
            (Some(w), Some((event, signal, rms, sigma))) => format!(
                "Residual of {unit}: at most {w:.2} × the noise σ ({signal} on {event}: RMS \
                 {} pu over the fit window, σ {} pu). At most {AT_NOISE} × is at the noise \
                 floor; above {FAR_ABOVE_NOISE} × is far above it.",
                num(rms),
                num(sigma)
            ),
            _ => format!(
                "Residual of {unit}: not compared with the noise ({why}); the report cannot say \
                 whether it lies at the noise floor."
            ),
        }
    }
}

/// A number for the sentence: 4 significant digits.
fn num(v: f64) -> String {
    if v != 0.0 && (v.abs() < 1e-2 || v.abs() >= 1e4) {
        format!("{v:.3e}")
    } else {
        format!("{v:.4}")
    }
}

/// The noise of `unit` on `events` (fitted) and `held_out`, in the playback `mode` on the
/// compared `channels` ([`NoiseRow`] per event, fitted first), and the [`Headline`]. One
/// playback per event (accurate integrator): the phasor playback of P and Q alone is
/// [`crate::fit::fitness`]'s (the fit's J), any other the mode's channels
/// ([`itaipu_dynamics::mode::simulate_mode`]). An event the unit does not play back on gets a
/// row with its error and no floor.
pub fn assess(
    unit: &Unit,
    events: &[Event],
    held_out: &[Event],
    mode: PlaybackMode,
    channels: &[Channel],
) -> (Vec<NoiseRow>, Headline) {
    let rows: Vec<NoiseRow> = events
        .iter()
        .map(|e| (e, false))
        .chain(held_out.iter().map(|e| (e, true)))
        .map(|(e, h)| row(unit, e, h, mode, channels))
        .collect();
    let playback = format!(
        "{mode}: {}",
        channels
            .iter()
            .map(|c| crate::diagnose::playback::signal_name(*c))
            .collect::<Vec<_>>()
            .join(", ")
    );
    let mut worst: Option<(f64, &str, &ChannelNoise)> = None;
    let mut why = String::new();
    for r in &rows {
        if let Some(err) = &r.error {
            why = format!("the unit does not play back on {}: {err}", r.event);
            break;
        }
        for c in &r.channels {
            if !(c.ratio.is_finite() && c.floor.sigma > 0.0) {
                why = format!(
                    "{} on {}: σ {} pu, RMS {} pu",
                    c.signal, r.event, c.floor.sigma, c.rms
                );
                worst = None;
                break;
            }
            if worst.is_none_or(|(w, _, _)| c.ratio > w) {
                worst = Some((c.ratio, &r.event, c));
            }
        }
        if !why.is_empty() {
            break;
        }
    }
    if rows.is_empty()
        || rows
            .iter()
            .all(|r| r.channels.is_empty() && r.error.is_none())
    {
        why = "no compared channel".into();
        worst = None;
    }
    let w = if why.is_empty() { worst } else { None };
    let headline = Headline {
        unit: unit.name.clone(),
        playback,
        mode,
        worst: w.map(|x| x.0),
        event: w.map(|x| x.1.to_string()).unwrap_or_default(),
        signal: w.map(|x| x.2.signal.clone()).unwrap_or_default(),
        rms: w.map_or(f64::NAN, |x| x.2.rms),
        sigma: w.map_or(f64::NAN, |x| x.2.floor.sigma),
        at_noise: AT_NOISE,
        far_above_noise: FAR_ABOVE_NOISE,
        sentence: Headline::text(
            &format!("unit {}", unit.name),
            w.map(|x| x.0),
            w.map(|x| (x.1, x.2.signal.as_str(), x.2.rms, x.2.floor.sigma)),
            &why,
        ),
    };
    (rows, headline)
}

/// One event's [`NoiseRow`] ([`assess`]).
fn row(
    unit: &Unit,
    e: &Event,
    held_out: bool,
    mode: PlaybackMode,
    channels: &[Channel],
) -> NoiseRow {
    let samples = e
        .record
        .time_s
        .iter()
        .filter(|t| e.fit.contains(**t))
        .count();
    let mut out = NoiseRow {
        event: e.name.clone(),
        held_out,
        samples,
        sigma_p: None,
        sigma_q: None,
        p: None,
        q: None,
        channels: vec![],
        error: None,
    };
    let pq_phasor = mode == PlaybackMode::Phasor && channels == [Channel::P, Channel::Q];
    let sims: Vec<Vec<f64>> = if pq_phasor {
        match crate::fit::fitness(unit, e, held_out) {
            Ok((_, tr)) => match (tr.get("p_pu"), tr.get("q_pu")) {
                (Some(p), Some(q)) => vec![p.to_vec(), q.to_vec()],
                _ => {
                    out.error = Some("no simulated P or Q".into());
                    return out;
                }
            },
            Err(err) => {
                out.error = Some(err.to_string());
                return out;
            }
        }
    } else {
        let prepared = itaipu_dynamics::simulate::PreparedEvent::new(e);
        match itaipu_dynamics::mode::simulate_mode(
            unit,
            &prepared,
            mode,
            &crate::problem::accurate_integrator(),
        ) {
            Ok(o) => {
                let mut v = vec![];
                for c in channels {
                    match o.channel(*c) {
                        Some(x) => v.push(x.to_vec()),
                        None => {
                            out.error = Some(format!("channel {} is not simulated", c.name()));
                            return out;
                        }
                    }
                }
                v
            }
            Err(err) => {
                out.error = Some(err.to_string());
                return out;
            }
        }
    };
    for (c, sim) in channels.iter().zip(&sims) {
        let Some(meas) = e.series(*c) else {
            out.error = Some(format!("channel {} is not recorded", c.name()));
            return out;
        };
        let floor = noise_floor(e, sim, meas);
        let (mut sse, mut n) = (0.0, 0usize);
        for ((t, s), m) in e.record.time_s.iter().zip(sim).zip(meas) {
            if e.fit.contains(*t) {
                sse += (s - m).powi(2);
                n += 1;
            }
        }
        let rms = (sse / n.max(1) as f64).sqrt();
        match c {
            Channel::P => (out.sigma_p, out.p) = (Some(floor.sigma), Some(floor)),
            Channel::Q => (out.sigma_q, out.q) = (Some(floor.sigma), Some(floor)),
            _ => {}
        }
        out.channels.push(ChannelNoise {
            signal: crate::diagnose::playback::signal_name(*c).to_string(),
            floor,
            rms,
            ratio: rms / floor.sigma,
        });
    }
    out
}

/// Where an event's pre-event samples end: its onset, or for a record with no disturbance the
/// end of its init window.
pub fn pre_event_end(event: &Event) -> f64 {
    event.onset_s().unwrap_or(event.init.end_s)
}

/// Standard deviation about the mean (N − 1).
pub fn std_dev(y: &[f64]) -> f64 {
    let n = y.len().max(1) as f64;
    let m = y.iter().sum::<f64>() / n;
    (y.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1.0).max(1.0)).sqrt()
}

/// Noise floors pooled over events by their number of samples (`(σ, samples)` each):
/// `√(Σ nₖ σₖ² / Σ nₖ)`.
pub fn pooled(floors: &[(f64, usize)]) -> f64 {
    let n: f64 = floors.iter().map(|(_, k)| *k as f64).sum();
    if n == 0.0 {
        return f64::NAN;
    }
    (floors.iter().map(|(s, k)| s * s * *k as f64).sum::<f64>() / n).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use itaipu_dynamics::rng::Normal;

    #[test]
    fn a_quantised_channel_is_recognised_and_a_continuous_one_is_not() {
        let mut rng = Normal::new(7);
        let q = 0.0014;
        let noisy: Vec<f64> = (0..300)
            .map(|k| 0.6 + 0.01 * (k as f64 * 0.05).sin() + 0.002 * rng.sample())
            .collect();
        let quantised: Vec<f64> = noisy.iter().map(|v| (v / q).round() * q).collect();
        let found = quantum(&quantised).unwrap();
        assert!((found - q).abs() < 1e-9, "{found}");
        assert_eq!(quantum(&noisy), None);
        // Constant: no change, no quantum.
        assert_eq!(quantum(&[0.62; 50]), None);
    }

    #[test]
    fn the_floor_of_a_quantised_constant_channel_is_the_quantisation_noise() {
        // A channel that sits on one level but for a few toggles: the pre-event standard
        // deviation is far below what a quantiser adds; the floor is q/√12.
        let q = 0.0014;
        let n = 300;
        let mut y = vec![0.6234; n];
        for k in (0..n).step_by(25) {
            y[k] += q;
        }
        let t: Vec<f64> = (0..n).map(|k| k as f64 / 60.0).collect();
        let rec = itaipu_dynamics::event::Record::from_rectangular(
            t,
            &vec![1.0; n],
            &vec![0.0; n],
            y.clone(),
            vec![0.0; n],
        );
        let ev = Event::from_record("q", rec, 100.0, 60.0, None, None).unwrap();
        let sim = vec![0.6234; n];
        let f = noise_floor(&ev, &sim, &y);
        assert_eq!(f.method, NoiseMethod::Quantum);
        assert!((f.sigma - q / 12f64.sqrt()).abs() < 1e-12);
        assert_eq!(f.quantum.map(|x| (x - q).abs() < 1e-12), Some(true));
    }

    #[test]
    fn pooling_weights_by_samples() {
        assert!((pooled(&[(1.0, 100), (3.0, 100)]) - 5f64.sqrt()).abs() < 1e-12);
        assert!(pooled(&[]).is_nan());
    }
}

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

use itaipu_dynamics::event::Event;
use serde::{Deserialize, Serialize};

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

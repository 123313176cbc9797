//! The evidence windows of an event (pre-event, dip, recovery, tail), the residual evidence
//! read in them, and how hard the events drive the unit (deepest dip, sustained frequency
//! change).

use crate::evidence::{self, EvidenceOptions};
use crate::problem::accurate_integrator;
use itaipu_dynamics::event::Channel;
use itaipu_dynamics::event::Event;
use itaipu_dynamics::mode::{simulate_mode_both, ModeOutputs};
use itaipu_dynamics::simulate::{trace_columns, Traces};

use super::error::DiagnoseError;
use super::playback::{self, Playback};
use super::report::{EventEvidence, SHAFT_BAND_HZ};

/// Width of the "dip" window after the onset [s].
pub(super) const DIP_S: f64 = 1.0;
/// Width of the "recovery" window after the dip [s].
pub(super) const RECOVERY_S: f64 = 4.0;

/// The event's onset for the diagnosis [s]: the event's own ([`Event::onset`]: found in the
/// data by the one detector every path uses, or given in the event file), clamped to the record.
/// An event without an onset (ambient data: no disturbance) keeps the older reference: the end
/// of its init window, so its "pre-event" segment is the init window and the windows after it
/// are measured from there.
pub(super) fn onset_s(event: &Event) -> f64 {
    let t = &event.record.time_s;
    let (t0, t1) = (t[0], *t.last().expect("events have samples"));
    event.onset_s().unwrap_or(event.init.end_s).clamp(t0, t1)
}

/// The evidence windows of an event: pre-event up to the onset ([`onset_s`]), dip, recovery,
/// tail.
pub fn windows(event: &Event) -> (f64, Vec<(String, f64, f64)>) {
    let t = &event.record.time_s;
    let t1 = *t.last().expect("events have samples");
    let t0 = t[0];
    let onset = onset_s(event);
    let w = vec![
        ("pre-event".to_string(), t0, onset),
        ("dip".to_string(), onset, (onset + DIP_S).min(t1)),
        (
            "recovery".to_string(),
            (onset + DIP_S).min(t1),
            (onset + DIP_S + RECOVERY_S).min(t1),
        ),
        (
            "tail".to_string(),
            (onset + DIP_S + RECOVERY_S).min(t1),
            t1 + 1e-9,
        ),
    ];
    (onset, w.into_iter().filter(|(_, a, b)| b > a).collect())
}

/// How hard the events drive the unit, for [`Context`]: the deepest voltage dip after the
/// onset as a fraction of the pre-event |V|, and the largest sustained frequency change (mean
/// of the last quarter of the record against the pre-event mean) [Hz], over all events.
pub(super) fn regime(events: &[Event]) -> (f64, f64) {
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let (mut dip, mut df) = (0.0_f64, 0.0_f64);
    for e in events {
        let (pre, v0) = pre_event_v(e);
        let v = &e.record.v_mag_pu;
        let v_min = v[pre..].iter().copied().fold(v0, f64::min);
        dip = dip.max(1.0 - v_min / v0);
        let f = frequency_deviation(e);
        let tail = f.len() - f.len() / 4;
        df = df.max((mean(&f[tail..]) - mean(&f[..pre.min(f.len())])).abs());
    }
    (dip, df)
}

/// The pre-event samples, those before the onset ([`onset_s`]; at least one), and their mean
/// |V|: the pre-event voltage against which dips and disturbances are measured.
pub(super) fn pre_event_v(event: &Event) -> (usize, f64) {
    let r = &event.record;
    let pre = pre_event_count(event);
    let v = &r.v_mag_pu[..pre];
    (pre, v.iter().sum::<f64>() / pre as f64)
}

/// Number of samples before the onset ([`onset_s`]), at least one.
fn pre_event_count(event: &Event) -> usize {
    let onset = onset_s(event);
    let r = &event.record;
    r.time_s
        .iter()
        .take_while(|&&t| t < onset)
        .count()
        .clamp(1, r.v_mag_pu.len())
}

/// Grid frequency deviation [Hz] from the record (`freq_hz` if present, else the derivative of
/// the unwrapped angle).
pub(super) fn frequency_deviation(event: &Event) -> Vec<f64> {
    let r = &event.record;
    if let Some(f) = &r.freq_hz {
        return f.iter().map(|v| v - event.nominal_hz).collect();
    }
    let (t, a) = (&r.time_s, &r.v_ang_rad);
    let n = t.len();
    (0..n)
        .map(|k| {
            let (i, j) = (k.saturating_sub(1), (k + 1).min(n - 1));
            if j > i {
                (a[j] - a[i]) / (t[j] - t[i]) / (2.0 * std::f64::consts::PI)
            } else {
                0.0
            }
        })
        .collect()
}

/// The onset and the evidence options of `event`: its windows ([`windows`]) and the pre-event
/// segment as the noise window.
fn evidence_options(event: &Event) -> (f64, EvidenceOptions) {
    let (onset, win) = windows(event);
    let opts = EvidenceOptions {
        windows: win,
        noise_window: (event.record.time_s[0], onset),
        ..Default::default()
    };
    (onset, opts)
}

/// Residual evidence of `traces` (simulated with the unit) against `event`.
pub fn event_evidence(event: &Event, traces: &Traces) -> EventEvidence {
    let (onset, opts) = evidence_options(event);
    let r = &event.record;
    let fdev = frequency_deviation(event);
    let inputs: Vec<(&str, &[f64])> = vec![("|V|", &r.v_mag_pu), ("frequency", &fdev)];
    let mut signals = vec![];
    let col = |n: &str| traces.get(n).map(|c| c.to_vec());
    let mut add = |name: &str, sim: Option<Vec<f64>>, meas: &[f64]| {
        if let Some(s) = sim {
            let res: Vec<f64> = s.iter().zip(meas).map(|(a, b)| a - b).collect();
            // The channel's noise floor: the library's one definition.
            let opts = EvidenceOptions {
                noise_sigma: Some(crate::noise::noise_floor(event, &s, meas).sigma),
                ..opts.clone()
            };
            signals.push(evidence::analyse(
                name, &r.time_s, &res, meas, &inputs, &opts,
            ));
        }
    };
    for (c, meas) in [
        (Channel::P, Some(&r.p_pu)),
        (Channel::Q, Some(&r.q_pu)),
        (Channel::Efd, r.efd_pu.as_ref()),
        (Channel::Ifd, r.ifd_pu.as_ref()),
    ] {
        if let (Some(meas), Some((sim, _))) = (meas, trace_columns(c)) {
            add(playback::signal_name(c), col(sim), meas);
        }
    }
    let p_peak = traces.get("p_pu").and_then(|sim| {
        let res: Vec<f64> = sim.iter().zip(&r.p_pu).map(|(a, b)| a - b).collect();
        shaft_peak(&r.time_s, &res)
    });
    EventEvidence {
        event: event.name.clone(),
        onset_s: onset,
        signals,
        p_peak,
    }
}

/// The strongest resonance of a P residual in the shaft band ([`SHAFT_BAND_HZ`], below 0.95 ×
/// Nyquist of the mean sample interval).
fn shaft_peak(time_s: &[f64], residual: &[f64]) -> Option<evidence::SpectralPeak> {
    let n = time_s.len();
    let dt = (time_s[n - 1] - time_s[0]) / (n.max(2) - 1) as f64;
    evidence::spectral_peak(
        residual,
        dt,
        SHAFT_BAND_HZ.0,
        SHAFT_BAND_HZ.1.min(0.95 * 0.5 / dt),
    )
}

/// Residual evidence of a playback mode's simulation `outs` of `event` ([`Playback`]): the
/// compared channels' residuals (named as in [`playback::signal_name`]), against the inputs the
/// mode imposes that a residual may follow: the measured |V| (when not compared) and the
/// declared set point (when the mode plays the steps). No shaft-band line unless P is compared.
pub(super) fn event_evidence_in_mode(
    event: &Event,
    outs: &itaipu_dynamics::mode::ModeOutputs,
    pb: &Playback,
) -> EventEvidence {
    let (onset, opts) = evidence_options(event);
    let r = &event.record;
    let setpoint: Vec<f64> = r
        .time_s
        .iter()
        .map(|t| itaipu_dynamics::event::step_level(&event.steps, *t))
        .collect();
    let mut inputs: Vec<(&str, &[f64])> = vec![];
    if !pb.channels.contains(&Channel::V) {
        inputs.push(("|V|", &r.v_mag_pu));
    }
    if !event.steps.is_empty() && pb.mode.applies_steps() {
        inputs.push(("set point", &setpoint));
    }
    let mut signals = vec![];
    let mut p_peak = None;
    for &c in &pb.channels {
        let (Some(sim), Some(meas)) = (outs.channel(c), event.series(c)) else {
            continue;
        };
        let res: Vec<f64> = sim.iter().zip(meas).map(|(a, b)| a - b).collect();
        let opts = EvidenceOptions {
            noise_sigma: Some(crate::noise::noise_floor(event, sim, meas).sigma),
            ..opts.clone()
        };
        signals.push(evidence::analyse(
            playback::signal_name(c),
            &r.time_s,
            &res,
            meas,
            &inputs,
            &opts,
        ));
        if c == Channel::P {
            p_peak = shaft_peak(&r.time_s, &res);
        }
    }
    EventEvidence {
        event: event.name.clone(),
        onset_s: onset,
        signals,
        p_peak,
    }
}

impl Playback {
    /// The evidence of `unit` on `event`, with the traces it comes from: the phasor playback's
    /// [`event_evidence`] on [`fitness`]'s traces; in a mode, the compared channels'
    /// residuals ([`event_evidence_in_mode`]), with those channels, all from one
    /// simulation ([`simulate_mode_both`]: what [`Self::traces`] and [`Self::outputs`] give).
    pub(super) fn evidence(
        &self,
        unit: &itaipu_dynamics::unit::Unit,
        event: &Event,
    ) -> Result<(Traces, EventEvidence, Option<ModeOutputs>), DiagnoseError> {
        if self.is_pq_phasor() {
            let tr = self.traces(unit, event)?;
            let ev = event_evidence(event, &tr);
            return Ok((tr, ev, None));
        }
        let (tr, outs) = simulate_mode_both(unit, event, self.mode, &accurate_integrator())
            .map_err(|error| DiagnoseError::engine(&event.name, error))?;
        let ev = event_evidence_in_mode(event, &outs, self);
        Ok((tr, ev, Some(outs)))
    }
}

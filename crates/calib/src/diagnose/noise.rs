//! Step 1, the noise: σ_P, σ_Q from the pre-event residual of the unit as given; and the
//! surrogate events (the reference's simulation with the noise drawn again) that measure what
//! pure noise fitting gains.

use crate::evidence;
use itaipu_dynamics::event::Event;
use itaipu_dynamics::simulate::Traces;
use itaipu_dynamics::unit::Unit;

use super::error::DiagnoseError;
use super::playback::Playback;
use super::report::EventEvidence;
use super::windows::onset_s;

/// A surrogate record that cannot be made, as a setup error.
fn setup(why: impl std::fmt::Display) -> DiagnoseError {
    DiagnoseError::Setup(why.to_string())
}

/// The samples of `y` (a series at the event's sample times) before the event's onset
/// ([`onset_s`]: the event's own, or the end of the init window for ambient data).
fn pre_event(event: &Event, y: &[f64]) -> Vec<f64> {
    let onset = onset_s(event);
    event
        .record
        .time_s
        .iter()
        .zip(y)
        .filter(|(t, _)| **t < onset)
        .map(|(_, v)| *v)
        .collect()
}

/// A surrogate of `event`: P and Q simulated by the reference (`traces`) on the measured input,
/// plus fresh white noise at the record's own noise levels (difference-based floors of the
/// pre-event P, Q, |V| and angle), the input channels getting theirs too.
pub(super) fn surrogate(event: &Event, traces: &Traces, seed: u64) -> Result<Event, DiagnoseError> {
    let r = &event.record;
    let pre = |y: &[f64]| {
        let v = pre_event(event, y);
        if v.len() >= 10 {
            evidence::noise_floor(&v)
        } else {
            evidence::noise_floor(y)
        }
    };
    let (sp, sq, sv, sa) = (
        pre(&r.p_pu),
        pre(&r.q_pu),
        pre(&r.v_mag_pu),
        pre(&r.v_ang_rad),
    );
    let (p, q) = (
        traces.get("p_pu").ok_or_else(|| setup("no simulated P"))?,
        traces.get("q_pu").ok_or_else(|| setup("no simulated Q"))?,
    );
    let mut rng = itaipu_dynamics::synthetic::Normal::new(seed ^ 0x005E_ED0F_5A11);
    let mut rec = r.clone();
    for k in 0..rec.time_s.len() {
        rec.p_pu[k] = p[k] + sp * rng.sample();
        rec.q_pu[k] = q[k] + sq * rng.sample();
        rec.v_mag_pu[k] += sv * rng.sample();
        rec.v_ang_rad[k] += sa * rng.sample();
    }
    let mut s = Event::from_record(
        &format!("{} (surrogate)", event.name),
        rec,
        event.system_mva,
        event.nominal_hz,
        Some(event.init),
        Some(event.fit),
    )
    .map_err(setup)?;
    // The event's onset, not one detected again on the redrawn noise: the same windows.
    s.onset = event.onset.clone();
    // Played back as the record is (its input smoothed alike).
    s.set_input_lowpass(event.input_lowpass_hz).map_err(setup)?;
    Ok(s)
}

/// A surrogate of `event` for a playback mode ([`Playback`] other than the phasor one): the
/// compared channels simulated by the reference (`outputs`) plus fresh white noise at the
/// record's own levels, every other recorded channel (the inputs the mode imposes) with its own
/// noise drawn again, the declared steps and windows kept.
pub(super) fn surrogate_in_mode(
    event: &Event,
    pb: &Playback,
    outputs: &itaipu_dynamics::mode::ModeOutputs,
    seed: u64,
) -> Result<Event, DiagnoseError> {
    let mut rng = itaipu_dynamics::synthetic::Normal::new(seed ^ 0x005E_ED0F_5A11);
    let mut s = event.clone();
    s.name = format!("{} (surrogate)", event.name);
    for &c in &event.channels {
        let Some(y) = event.series(c) else { continue };
        let v = pre_event(event, y);
        let sigma = if v.len() >= 10 {
            evidence::noise_floor(&v)
        } else {
            evidence::noise_floor(y)
        };
        let sim = if pb.channels.contains(&c) {
            Some(
                outputs
                    .channel(c)
                    .ok_or_else(|| setup(format!("no simulated {}", c.name())))?,
            )
        } else {
            None
        };
        let out = s.series_mut(c).expect("a recorded channel");
        for (k, y) in out.iter_mut().enumerate() {
            let base = sim.map_or(*y, |x| x[k]);
            *y = base + sigma * rng.sample();
        }
    }
    Ok(s)
}

/// The noise of the unit as given on `events` and `held_out` in the playback `pb`
/// ([`crate::noise::assess`]: each event's floors and residual, and the headline every report
/// shows), and the floor σ_c of each compared channel (in `pb`'s order) pooled over the fitted
/// events by their number of samples: the χ² weights `1/σ_c²`.
pub(super) fn assess(
    unit: &Unit,
    events: &[Event],
    held_out: &[Event],
    pb: &Playback,
) -> Result<
    (
        Vec<f64>,
        Vec<crate::noise::NoiseRow>,
        crate::noise::Headline,
    ),
    DiagnoseError,
> {
    let (rows, headline) = crate::noise::assess(unit, events, held_out, pb.mode, &pb.channels);
    if let Some(r) = rows.iter().find(|r| r.error.is_some()) {
        return Err(DiagnoseError::Simulation {
            event: r.event.clone(),
            msg: r.error.clone().unwrap_or_default(),
            error: None,
        });
    }
    let sigmas = (0..pb.channels.len())
        .map(|j| {
            let floors: Vec<(f64, usize)> = rows
                .iter()
                .zip(events)
                .filter(|(r, _)| !r.held_out)
                .map(|(r, e)| (r.channels[j].floor.sigma, e.record.time_s.len()))
                .collect();
            crate::noise::pooled(&floors)
        })
        .collect();
    Ok((sigmas, rows, headline))
}

/// Each signal's RMS/noise of `evidence` against the noise floor of its event and channel in
/// `rows` (the unit as given's, [`assess`]): one σ per event and channel for the noise table,
/// the χ² weights, the evidence and the verdict.
pub(super) fn against_noise(evidence: &mut [EventEvidence], rows: &[crate::noise::NoiseRow]) {
    for ev in evidence {
        let Some(row) = rows.iter().find(|r| r.event == ev.event) else {
            continue;
        };
        for s in &mut ev.signals {
            if let Some(sigma) = row.sigma(&s.signal) {
                s.noise_floor_rms = sigma;
                s.rms_over_noise = if sigma > 0.0 {
                    s.rms / sigma
                } else if s.rms > 0.0 {
                    f64::INFINITY
                } else {
                    1.0
                };
            }
        }
    }
}

/// Why a candidate's RMS (its baseline's and its extension's) may lie above the reference's, as
/// the reports say it under their candidate tables.
pub const REFIT_RMS_NOTE: &str = "A candidate's RMS (its baseline's and its extension's) is over \
the whole record, fitted and held-out blocks alike, while its re-fit sees only the fitted blocks \
(every re-freed parameter free, with a short search): on a record whose misfit the model cannot \
follow, the re-fit bends to the fitted blocks and predicts the held-out ones worse, so its RMS \
can lie above the reference's (the unit as given, calibrated on the whole record). The held-out \
χ² columns say by how much.";

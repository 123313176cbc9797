//! Step 1, the noise: σ_P, σ_Q from the pre-event residual of the unit as given; and the
//! surrogate events (the reference's simulation with the noise drawn again) that measure what
//! pure noise fitting gains.

use crate::evidence;
use crate::fit::fitness;
use itaipu_dynamics::event::Event;
use itaipu_dynamics::simulate::Traces;
use itaipu_dynamics::unit::Unit;

use super::error::DiagnoseError;
use super::playback::Playback;
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

/// The noise floor σ_c of each compared channel of `pb` (in its order) for the unit as given
/// on `events`: σ_P, σ_Q of [`sigma_pq`] for the phasor playback; in a mode, each compared
/// channel's [`crate::noise::noise_floor`] of the mode's simulation, pooled likewise.
pub(super) fn sigmas(
    unit: &Unit,
    events: &[Event],
    pb: &Playback,
) -> Result<Vec<f64>, DiagnoseError> {
    if pb.is_pq_phasor() {
        let (p, q) = sigma_pq(unit, events)?;
        return Ok(vec![p, q]);
    }
    let mut floors: Vec<Vec<(f64, usize)>> = vec![vec![]; pb.channels.len()];
    for e in events {
        let out = pb.outputs(unit, e)?;
        let n = e.record.time_s.len();
        for (j, &c) in pb.channels.iter().enumerate() {
            let (Some(sim), Some(meas)) = (out.channel(c), e.series(c)) else {
                return Err(DiagnoseError::Setup(format!(
                    "event '{}': channel {} is neither simulated nor recorded",
                    e.name,
                    c.name()
                )));
            };
            floors[j].push((crate::noise::noise_floor(e, sim, meas).sigma, n));
        }
    }
    Ok(floors.iter().map(|f| crate::noise::pooled(f)).collect())
}

/// σ_P, σ_Q of the unit as given on `events`: each event's noise floor
/// ([`crate::noise::noise_floor`]: the pre-event residual's standard deviation, the one
/// definition every report shows), pooled over the events by their number of samples.
pub(super) fn sigma_pq(unit: &Unit, events: &[Event]) -> Result<(f64, f64), DiagnoseError> {
    let (mut fp, mut fq) = (vec![], vec![]);
    for e in events {
        let (_, tr) =
            fitness(unit, e, false).map_err(|err| DiagnoseError::simulation(&e.name, &err))?;
        let n = e.record.time_s.len();
        for (sim, meas, out) in [
            ("p_pu", &e.record.p_pu, &mut fp),
            ("q_pu", &e.record.q_pu, &mut fq),
        ] {
            let s = tr.get(sim).ok_or_else(|| DiagnoseError::Simulation {
                event: e.name.clone(),
                msg: format!("no simulated {sim}"),
                error: None,
            })?;
            out.push((crate::noise::noise_floor(e, s, meas).sigma, n));
        }
    }
    Ok((crate::noise::pooled(&fp), crate::noise::pooled(&fq)))
}

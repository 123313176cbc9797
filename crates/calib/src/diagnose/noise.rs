//! Step 1, the noise: σ_P, σ_Q from the pre-event residual of the unit as given; and the
//! surrogate events (the reference's simulation with the noise drawn again) that measure what
//! pure noise fitting gains.

use crate::evidence;
use crate::fit::fitness;
use itaipu_dynamics::event::Event;
use itaipu_dynamics::simulate::Traces;
use itaipu_dynamics::unit::Unit;

use super::*;

/// Noise σ of a residual series: its standard deviation over the pre-event segment, where a
/// right model is in steady state (the difference-based floor of the whole record when the
/// pre-event is too short). Taken on the residual rather than the measurement, it also holds the
/// noise of the played-back voltage propagated through the model, white or not.
pub(super) fn pre_event_noise(event: &Event, y: &[f64]) -> f64 {
    let pre = pre_event(event, y);
    let s = if pre.len() >= 10 {
        std_dev(&pre)
    } else {
        evidence::noise_floor(y)
    };
    s.max(1e-6)
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

/// Standard deviation about the mean.
pub(super) fn std_dev(y: &[f64]) -> f64 {
    let n = y.len().max(1) as f64;
    let m = y.iter().sum::<f64>() / n;
    (y.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (n - 1.0).max(1.0)).sqrt()
}

/// A surrogate of `event`: P and Q simulated by the reference (`traces`) on the measured input,
/// plus fresh white noise at the record's own noise levels (difference-based floors of the
/// pre-event P, Q, |V| and angle), the input channels getting theirs too.
pub(super) fn surrogate(event: &Event, traces: &Traces, seed: u64) -> Result<Event, String> {
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
        traces.get("p_pu").ok_or("no simulated P")?,
        traces.get("q_pu").ok_or("no simulated Q")?,
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
    .map_err(|e| e.to_string())?;
    // The event's onset, not one detected again on the redrawn noise: the same windows.
    s.onset = event.onset.clone();
    Ok(s)
}

/// σ_P, σ_Q of the unit as given on `events`: the pre-event residual's standard deviation of
/// each event ([`pre_event_noise`]), pooled over the events by their number of samples.
pub(super) fn sigma_pq(unit: &Unit, events: &[Event]) -> Result<(f64, f64), DiagnoseError> {
    let mut given = vec![];
    for e in events {
        let (_, tr) =
            fitness(unit, e, false).map_err(|err| DiagnoseError::simulation(&e.name, &err))?;
        given.push(tr);
    }
    let n_all: f64 = events.iter().map(|e| e.record.time_s.len() as f64).sum();
    let residual = |k: usize, sim: &str, meas: &[f64]| -> Vec<f64> {
        given[k]
            .get(sim)
            .map(|s| s.iter().zip(meas).map(|(a, b)| a - b).collect())
            .unwrap_or_default()
    };
    let sigma = |sim: &str, pick: fn(&Event) -> &[f64]| {
        let v: Vec<f64> = events
            .iter()
            .enumerate()
            .map(|(k, e)| pre_event_noise(e, &residual(k, sim, pick(e))))
            .collect();
        (events
            .iter()
            .zip(&v)
            .map(|(e, s)| s * s * e.record.time_s.len() as f64)
            .sum::<f64>()
            / n_all)
            .sqrt()
    };
    let sigma_p = sigma("p_pu", |e| &e.record.p_pu);
    let sigma_q = sigma("q_pu", |e| &e.record.q_pu);
    Ok((sigma_p, sigma_q))
}

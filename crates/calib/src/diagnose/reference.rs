//! Step 2, the reference: the unit with its set-point offsets (nuisance) re-fitted, its traces
//! and evidence, the surrogate events; and the catalog context read from them.

use crate::fit::{fitness, Progress};
use itaipu_dynamics::event::Event;
use itaipu_dynamics::mode::ModeOutputs;
use itaipu_dynamics::simulate::Traces;
use itaipu_dynamics::unit::Unit;

use super::*;

/// The dominant oscillatory mode above 1 Hz in the P residuals (matrix pencil), if any.
pub(super) fn mode_hint(ev: &[EventEvidence], rate_hz: f64) -> Option<f64> {
    ev.iter()
        .flat_map(|e| e.signals.iter().filter(|s| s.signal == "P"))
        .flat_map(|s| s.modes.iter())
        .filter(|m| {
            m.freq_hz > 1.0
                && m.freq_hz < 0.45 * rate_hz
                && m.damping_ratio > -0.05
                && m.damping_ratio < 0.5
        })
        .max_by(|a, b| a.amplitude.total_cmp(&b.amplitude))
        .map(|m| m.freq_hz)
}

/// The catalog context of `unit` on `event` (operating-point field voltage and current, PMU
/// rate), without evidence hints. Used to hide a cause in a synthetic truth.
///
/// # Errors
///
/// [`DiagnoseError::Simulation`] when the unit does not simulate on the event.
pub fn context(unit: &Unit, event: &Event) -> Result<Context, DiagnoseError> {
    let (_, tr) =
        fitness(unit, event, false).map_err(|e| DiagnoseError::simulation(&event.name, &e))?;
    Ok(context_from(&tr, event))
}

/// The catalog context read from a unit's traces on `event` (no evidence hints).
pub(super) fn context_from(traces: &Traces, event: &Event) -> Context {
    let t = &event.record.time_s;
    Context {
        efd0: traces.get("efd").and_then(|c| c.first().copied()),
        xadifd0: traces.get("xadifd").and_then(|c| c.first().copied()),
        rate_hz: match (t.first(), t.last()) {
            (Some(a), Some(b)) if b > a => (t.len() - 1) as f64 / (b - a),
            _ => 0.0,
        },
        ..Default::default()
    }
}

/// The reference of a diagnosis and what is read from it.
pub(super) struct Reference {
    /// The nuisance parameters re-fitted ([`catalog::nuisance`]).
    pub nuisance: Vec<FreeBound>,
    /// The re-fit: the reference unit.
    pub refit: Refit,
    /// Per event: the reference's traces.
    pub before: Vec<(String, Traces)>,
    /// Per event: the reference's evidence.
    pub evidence: Vec<EventEvidence>,
    /// The splits of the surrogate records, one per draw ([`DiagnoseOptions::null_draws`]):
    /// each the surrogate events and surrogate held-out events.
    pub sp_null: Vec<Split>,
    /// The surrogate events and surrogate held-out events themselves, per draw.
    pub surrogates: Vec<(Vec<Event>, Vec<Event>)>,
}

/// The unit with its set-point offsets (nuisance) re-fitted on the split `sp`, its traces and
/// evidence on `events`, and the split of the surrogate events.
pub(super) fn reference(
    unit: &Unit,
    events: &[Event],
    held_out: &[Event],
    sp: &Split,
    (pb, weights, compare): playback::Scoring,
    opts: &DiagnoseOptions,
    progress: &dyn Progress,
    profile: &Profile,
) -> Result<Reference, DiagnoseError> {
    let nuisance = catalog::nuisance(unit);
    let env = RefitEnv {
        sp,
        weights,
        compare,
        opts,
        progress,
        profile: Some(profile),
    };
    let reference = refit(
        &env,
        unit,
        &nuisance,
        &[],
        &Label::new(RefitKind::Reference, "nuisance offsets"),
    )
    .map_err(|msg| DiagnoseError::Simulation {
        event: events[0].name.clone(),
        msg,
        error: None,
    })?;
    let t_evidence = std::time::Instant::now();
    let mut before = vec![];
    let mut evidence_before = vec![];
    // In a playback mode, the compared channels of the same playbacks (for the surrogates).
    let mut outputs_before = vec![];
    for e in events {
        let (tr, ev, outs) = pb.evidence(&reference.unit, e)?;
        evidence_before.push(ev);
        before.push((e.name.clone(), tr));
        outputs_before.push(outs);
    }
    // Surrogate events: what the reference unit would give on these inputs, with measurement
    // noise on P, Q and input noise on |V| and the angle drawn again at the levels the record
    // shows. The reference is exact there, so a re-fit's gain on them is pure noise fitting.
    // In a playback mode, the compared channels are the simulated ones and every imposed
    // channel gets its noise drawn again.
    let in_mode = |e: &Event, outs: Option<&ModeOutputs>, seed: u64| {
        let played;
        let outs = match outs {
            Some(o) => o,
            None => {
                played = pb.outputs(&reference.unit, e)?;
                &played
            }
        };
        surrogate_in_mode(e, pb, outs, seed).map_err(DiagnoseError::Setup)
    };
    // The reference's playback of each held-out event (its traces, or in a playback mode its
    // compared channels), once for every draw.
    let mut held_played = vec![];
    for e in held_out {
        held_played.push(if pb.is_pq_phasor() {
            let (_, tr) = fitness(&reference.unit, e, true)
                .map_err(|err| DiagnoseError::simulation(&e.name, &err))?;
            (Some(tr), None)
        } else {
            (None, Some(pb.outputs(&reference.unit, e)?))
        });
    }
    let mut sp_null = vec![];
    let mut surrogates = vec![];
    for draw in 0..opts.null_draws.max(1) {
        // The first draw's seeds are the diagnosis's own (one draw: as before); each further
        // draw shifts them by a large odd stride.
        let shift = (draw as u64).wrapping_mul(1_000_003);
        let mut surrogate_held = vec![];
        for (k, (e, (tr, outs))) in held_out.iter().zip(&held_played).enumerate() {
            let seed = opts.seed.wrapping_add(1000 + k as u64).wrapping_add(shift);
            surrogate_held.push(match tr {
                Some(tr) => surrogate(e, tr, seed).map_err(DiagnoseError::Setup)?,
                None => in_mode(e, outs.as_ref(), seed)?,
            });
        }
        let surrogate_events: Vec<Event> = events
            .iter()
            .zip(before.iter().zip(&outputs_before))
            .enumerate()
            .map(|(k, (e, ((_, tr), outs)))| {
                let seed = opts.seed.wrapping_add(k as u64).wrapping_add(shift);
                if pb.is_pq_phasor() {
                    surrogate(e, tr, seed).map_err(DiagnoseError::Setup)
                } else {
                    in_mode(e, outs.as_ref(), seed)
                }
            })
            .collect::<Result<_, _>>()?;
        sp_null.push(split(&surrogate_events, &surrogate_held, opts.block_s)?);
        surrogates.push((surrogate_events, surrogate_held));
    }
    profile.add(
        "diagnosis",
        "evidence and surrogate records",
        t_evidence.elapsed().as_secs_f64(),
        0,
        0,
    );
    Ok(Reference {
        nuisance,
        refit: reference,
        before,
        evidence: evidence_before,
        sp_null,
        surrogates,
    })
}

/// The catalog context of the reference on `events` (its traces `before` and evidence
/// `evidence_before`): operating point, PMU rate, mode hint, shaft resonance, regime, field
/// current rise.
pub(super) fn catalog_context(
    events: &[Event],
    before: &[(String, Traces)],
    evidence_before: &[EventEvidence],
    pb: &Playback,
) -> Context {
    // `diagnose` refuses an empty event list, and `before` holds every event's traces.
    let mut ctx = context_from(&before[0].1, &events[0]);
    ctx.mode = pb.mode;
    ctx.compared = pb.channels.clone();
    ctx.setpoint_step = events
        .iter()
        .filter(|_| pb.mode.applies_steps())
        .flat_map(|e| &e.steps)
        .map(|s| s.size_pu.abs())
        .reduce(f64::max);
    ctx.mode_hint_hz = mode_hint(evidence_before, ctx.rate_hz);
    ctx.shaft_resonance = evidence_before
        .iter()
        .filter_map(|e| e.p_peak.clone())
        .filter(catalog::resonance_stands_out)
        .min_by(|a, b| a.p_value.total_cmp(&b.p_value));
    let (dip, df) = regime(events);
    (ctx.deepest_dip, ctx.sustained_df_hz) = (Some(dip), Some(df));
    ctx.field_current_rise = before
        .iter()
        .filter_map(|(_, tr)| {
            let i = tr.get("xadifd")?;
            let i0 = *i.first()?;
            (i0 > 0.0).then(|| i.iter().copied().fold(i0, f64::max) / i0 - 1.0)
        })
        .reduce(f64::max);
    ctx
}

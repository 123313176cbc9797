//! Step 2, the reference: the unit with its set-point offsets (nuisance) re-fitted, its traces
//! and evidence, the surrogate events; and the catalog context read from them.

use crate::fit::{fitness, Progress};
use itaipu_dynamics::event::Event;
use itaipu_dynamics::mode::ModeOutputs;
use itaipu_dynamics::simulate::Traces;
use itaipu_dynamics::unit::Unit;

use super::cause::{nuisance, Context};
use super::context::resonance_stands_out;
use super::error::DiagnoseError;
use super::noise::{surrogate, surrogate_in_mode};
use super::options::DiagnoseOptions;
use super::playback::{self, Playback};
use super::profile::{Label, Profile, RefitKind};
use super::refit::{refit, Refit, RefitEnv};
use super::report::EventEvidence;
use super::split::{split, Split};
use super::windows::regime;
use crate::bounds::FreeBound;

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
    /// The nuisance parameters re-fitted ([`nuisance`]).
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
/// evidence on `events`, and the surrogate records.
#[allow(clippy::too_many_arguments)]
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
    let nuisance = nuisance(unit);
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
        msg: msg.to_string(),
        error: None,
    })?;
    let t_evidence = std::time::Instant::now();
    let played = Played::new(&reference.unit, events, held_out, pb)?;
    let mut sp_null = vec![];
    let mut surrogates = vec![];
    for draw in 0..opts.null_draws.max(1) {
        let (surrogate_events, surrogate_held) = played.surrogates(draw, opts.seed)?;
        sp_null.push(split(
            &surrogate_events,
            &surrogate_held,
            opts.block_s,
            opts.fold,
        )?);
        surrogates.push((surrogate_events, surrogate_held));
    }
    profile.add(
        "diagnosis",
        "evidence and surrogate records",
        t_evidence.elapsed().as_secs_f64(),
        0,
        0,
    );
    let Played {
        before, evidence, ..
    } = played;
    Ok(Reference {
        nuisance,
        refit: reference,
        before,
        evidence,
        sp_null,
        surrogates,
    })
}

/// The reference unit played back on the events and the held-out events: what its evidence
/// and its surrogate records are read from.
struct Played<'r> {
    unit: &'r Unit,
    pb: &'r Playback,
    events: &'r [Event],
    held_out: &'r [Event],
    /// Per event: the reference's traces.
    before: Vec<(String, Traces)>,
    /// Per event: the reference's evidence.
    evidence: Vec<EventEvidence>,
    /// Per event, in a playback mode: the compared channels of the same playbacks.
    outputs: Vec<Option<ModeOutputs>>,
    /// Per held-out event: the reference's traces, or in a playback mode its compared channels.
    held: Vec<(Option<Traces>, Option<ModeOutputs>)>,
}

impl<'r> Played<'r> {
    fn new(
        unit: &'r Unit,
        events: &'r [Event],
        held_out: &'r [Event],
        pb: &'r Playback,
    ) -> Result<Self, DiagnoseError> {
        let (mut before, mut evidence, mut outputs) = (vec![], vec![], vec![]);
        for e in events {
            let (tr, ev, outs) = pb.evidence(unit, e)?;
            evidence.push(ev);
            before.push((e.name.clone(), tr));
            outputs.push(outs);
        }
        let mut held = vec![];
        for e in held_out {
            held.push(if pb.is_pq_phasor() {
                let (_, tr) = fitness(unit, e, true)
                    .map_err(|err| DiagnoseError::simulation(&e.name, &err))?;
                (Some(tr), None)
            } else {
                (None, Some(pb.outputs(unit, e)?))
            });
        }
        Ok(Self {
            unit,
            pb,
            events,
            held_out,
            before,
            evidence,
            outputs,
            held,
        })
    }

    /// Surrogate events of draw `draw` (the events and the held-out events): what the reference
    /// unit gives on these inputs, with measurement noise on P, Q and input noise on |V| and the
    /// angle drawn again at the levels the record shows. The reference is exact there, so a
    /// re-fit's gain on them is pure noise fitting. In a playback mode, the compared channels
    /// are the simulated ones and every imposed channel gets its noise drawn again. The first
    /// draw's seeds are the diagnosis's own (`seed`); each further draw shifts them by a large
    /// odd stride.
    fn surrogates(
        &self,
        draw: usize,
        seed: u64,
    ) -> Result<(Vec<Event>, Vec<Event>), DiagnoseError> {
        let shift = (draw as u64).wrapping_mul(1_000_003);
        let mut held = vec![];
        for (k, (e, (tr, outs))) in self.held_out.iter().zip(&self.held).enumerate() {
            let seed = seed.wrapping_add(1000 + k as u64).wrapping_add(shift);
            held.push(match tr {
                Some(tr) => surrogate(e, tr, seed)?,
                None => self.in_mode(e, outs.as_ref(), seed)?,
            });
        }
        let events: Vec<Event> = self
            .events
            .iter()
            .zip(self.before.iter().zip(&self.outputs))
            .enumerate()
            .map(|(k, (e, ((_, tr), outs)))| {
                let seed = seed.wrapping_add(k as u64).wrapping_add(shift);
                if self.pb.is_pq_phasor() {
                    surrogate(e, tr, seed)
                } else {
                    self.in_mode(e, outs.as_ref(), seed)
                }
            })
            .collect::<Result<_, _>>()?;
        Ok((events, held))
    }

    /// A playback mode's surrogate of `e` from the reference's compared channels `outs`
    /// (played again when not kept).
    fn in_mode(
        &self,
        e: &Event,
        outs: Option<&ModeOutputs>,
        seed: u64,
    ) -> Result<Event, DiagnoseError> {
        let played;
        let outs = match outs {
            Some(o) => o,
            None => {
                played = self.pb.outputs(self.unit, e)?;
                &played
            }
        };
        surrogate_in_mode(e, self.pb, outs, seed)
    }
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
        .filter(resonance_stands_out)
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

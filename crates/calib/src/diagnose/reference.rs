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
use serde::Serialize;

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

/// What the reference re-fitted beyond the nuisance offsets, and why ([`reference`]): in the
/// diagnosis's report (`reference`), one sentence and the numbers behind it.
#[derive(Debug, Clone, Serialize)]
pub struct ReferenceRefit {
    /// The sentence the report shows.
    pub sentence: String,
    /// The calibrated parameters re-fitted with the global search.
    pub freed: Vec<String>,
    /// Per compared channel: its noise σ and its RMS over the fitted events [pu] with the
    /// offsets alone re-fitted and after the global re-fit.
    pub channels: Vec<ReferenceChannel>,
    /// Why the global re-fit could not be used (the reference then re-fits the offsets alone).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub failed: Option<String>,
}

/// One compared channel of a [`ReferenceRefit`].
#[derive(Debug, Clone, Serialize)]
pub struct ReferenceChannel {
    pub signal: String,
    pub sigma: f64,
    pub rms_offsets: f64,
    pub rms_reference: f64,
}

/// The reference of a diagnosis and what is read from it.
pub(super) struct Reference {
    /// The parameters the reference re-fitted: the nuisance offsets ([`nuisance`]), and the
    /// calibrated set where [`refits_calibrated_set`] says.
    pub bounds: Vec<FreeBound>,
    /// The re-fit: the reference unit.
    pub refit: Refit,
    /// What the reference re-fitted beyond the offsets (`None`: the offsets alone).
    pub note: Option<ReferenceRefit>,
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

/// Whether the reference re-fits the calibrated set ([`DiagnoseOptions::refit`]) with the
/// global search besides the offsets: when the playback compares a field channel
/// ([`playback::FIELD_CHANNELS`], in the phasor playback: every event records it) and there is
/// a calibrated set to re-free. The calibration may have left that channel out (a spec with
/// `objective = "pq"`), so the unit was never fitted to it and its calibrated values can sit
/// in a valley P and Q allow and the field does not: every baseline, re-freeing the set by
/// local steps only, would stay there, leave the field far off and make a clean unit look
/// `unexplained`, or name whichever cause happens to free the exciter's gain. One global re-fit
/// on every compared channel puts the reference, and so every candidate's start, where the
/// record's own channels put it, whatever the calibration compared; after a calibration that
/// did compare the field it starts in that valley and stays there, so the verdict does not
/// depend on what the spec said.
pub(super) fn refits_calibrated_set(pb: &Playback, opts: &DiagnoseOptions) -> bool {
    pb.mode == itaipu_dynamics::mode::PlaybackMode::Phasor
        && pb
            .channels
            .iter()
            .any(|c| playback::FIELD_CHANNELS.contains(c))
        && !opts.refit.is_empty()
}

/// The unit with its set-point offsets (nuisance) re-fitted on the split `sp` (and the
/// calibrated set with the global search where [`refits_calibrated_set`] says), its traces and
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
    let offsets = refit(
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
    let (bounds, reference, note) = if refits_calibrated_set(pb, opts) {
        with_calibrated_set(&env, pb, nuisance, offsets)
    } else {
        (nuisance, offsets, None)
    };
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
        bounds,
        refit: reference,
        note,
        before,
        evidence,
        sp_null,
        surrogates,
    })
}

/// The reference re-fitted over the offsets and the calibrated set together
/// ([`refits_calibrated_set`]) with the global search (swarm and local method, the diagnosis's
/// own settings; no parameter polish-only), from where the offsets' re-fit `offsets` ended, on
/// every compared channel: its bounds, its re-fit and the note. When that re-fit fails, the
/// offsets' re-fit, with the note saying why.
fn with_calibrated_set(
    env: &RefitEnv,
    pb: &Playback,
    nuisance: Vec<FreeBound>,
    offsets: Refit,
) -> (Vec<FreeBound>, Refit, Option<ReferenceRefit>) {
    let opts = env.opts;
    let start = &offsets.unit;
    let calibrated: Vec<FreeBound> = opts
        .refit
        .iter()
        .filter(|b| !nuisance.iter().any(|n| n.param == b.param))
        .map(|b| FreeBound {
            polish_only: false,
            scan: 0,
            ..b.starting_in(start)
        })
        .collect();
    let bounds: Vec<FreeBound> = nuisance
        .iter()
        .map(|b| b.starting_in(start))
        .chain(calibrated.iter().cloned())
        .collect();
    let label = Label::new(
        RefitKind::Reference,
        "calibrated set on every compared channel",
    );
    let global = refit(env, start, &bounds, &[], &label);
    let sigmas: Vec<f64> = match env.compare {
        Some(c) => c.weights.iter().map(|(_, w)| 1.0 / w.sqrt()).collect(),
        None => vec![1.0 / env.weights.0.sqrt(), 1.0 / env.weights.1.sqrt()],
    };
    let channels = |after: &Refit| -> Vec<ReferenceChannel> {
        pb.channels
            .iter()
            .enumerate()
            .map(|(j, c)| ReferenceChannel {
                signal: playback::signal_name(*c).to_string(),
                sigma: sigmas.get(j).copied().unwrap_or(f64::NAN),
                rms_offsets: offsets.rms.get(j).copied().unwrap_or(f64::NAN),
                rms_reference: after.rms.get(j).copied().unwrap_or(f64::NAN),
            })
            .collect()
    };
    let names = pb
        .channels
        .iter()
        .map(|c| playback::signal_name(*c))
        .collect::<Vec<_>>()
        .join(", ");
    let freed: Vec<String> = calibrated.iter().map(|b| b.param.clone()).collect();
    match global {
        Ok(r) => {
            let chans = channels(&r);
            let moved = chans
                .iter()
                .map(|c| {
                    format!(
                        "{} {} -> {} x σ",
                        c.signal,
                        ratio(c.rms_offsets, c.sigma),
                        ratio(c.rms_reference, c.sigma)
                    )
                })
                .collect::<Vec<_>>()
                .join(", ");
            let note = ReferenceRefit {
                sentence: format!(
                    "the reference re-fitted the calibrated set ({} parameters) with the \
                     nuisance offsets on {names} with a global search (swarm and local \
                     method), because the record holds the field and a calibration may have \
                     left it out: every candidate is judged against it (RMS {moved})",
                    freed.len()
                ),
                freed,
                channels: chans,
                failed: None,
            };
            (bounds, r, Some(note))
        }
        Err(e) => {
            let chans = channels(&offsets);
            let note = ReferenceRefit {
                sentence: format!(
                    "the reference's re-fit of the calibrated set on {names} failed ({e}); \
                     the candidates are judged against the offsets' re-fit alone"
                ),
                freed,
                channels: chans,
                failed: Some(e.to_string()),
            };
            (nuisance, offsets, Some(note))
        }
    }
}

/// `rms / sigma` to one decimal (`-` when unknown).
fn ratio(rms: f64, sigma: f64) -> String {
    let r = rms / sigma;
    if r.is_finite() {
        format!("{r:.1}")
    } else {
        "-".into()
    }
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

//! What a diagnosis plays back and compares.
//!
//! A phasor record (the voltage angle recorded): the measured phasor imposed at the terminal,
//! P and Q compared, each weighted by the inverse of its noise variance: the diagnosis as it
//! was first written, bit for bit. When every event also records the field ([`FIELD_CHANNELS`]:
//! E_fd, X_ad I_fd), the phasor playback compares those too, each weighted by `1/σ_c²` as a
//! mode's channels are (below), through the same [`Compare`]. A record without an angle (a staged test recorded by the
//! excitation system's recorder: |V|, P, Q, E_fd) cannot be played back that way; the user names
//! one of the playback modes of [`itaipu_dynamics::mode`] and the diagnosis compares that mode's
//! default channels (`exciter_alone`: E_fd; `machine_from_efd`: Q; `closed_loop`: |V|, Q, E_fd),
//! each weighted by `1/σ_c²` with σ_c its own noise floor, so that every χ² of the diagnosis is
//! still in units of the noise variance whatever the channel. The mode is the engineer's
//! choice, not guessed: each mode imposes different channels and assumes different things (the
//! grid equivalent of `closed_loop`, the measured E_fd of `machine_from_efd`).

use itaipu_dynamics::event::{Channel, Event};
use itaipu_dynamics::mode::{simulate_mode, simulate_mode_traces, ModeOutputs, PlaybackMode};
use itaipu_dynamics::simulate::{PreparedEvent, Traces};

use crate::fit::fitness;
use crate::problem::accurate_integrator;
use crate::spec::Compare;

use super::error::DiagnoseError;

/// The field channels a phasor playback compares besides P and Q, and which of them every event
/// records (declared with the events).
pub use itaipu_dynamics::event::{field_recorded_by_all, FIELD_CHANNELS};

/// The playback of a diagnosis and its compared channels (see the module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct Playback {
    pub mode: PlaybackMode,
    /// The compared channels, in canonical order.
    pub channels: Vec<Channel>,
}

impl Playback {
    /// The phasor playback, P and Q compared.
    pub fn phasor() -> Self {
        Self::new(PlaybackMode::Phasor)
    }

    /// `mode` with its default compared channels ([`PlaybackMode::default_channels`]).
    pub fn new(mode: PlaybackMode) -> Self {
        Self {
            mode,
            channels: mode.default_channels().to_vec(),
        }
    }

    /// The phasor playback comparing P and Q alone: the diagnosis as first written, with its
    /// own `(w_P, w_Q)` weights and evidence. Any other (a mode, or the phasor playback with
    /// field channels) compares through a [`Compare`].
    pub fn is_pq_phasor(&self) -> bool {
        self.mode == PlaybackMode::Phasor && self.channels == [Channel::P, Channel::Q]
    }

    /// The playback a diagnosis of `events` uses: `mode` when given (every event must hold what
    /// it plays back and compares), else the phasor playback, which needs every event's angle.
    /// The phasor playback also compares each field channel ([`FIELD_CHANNELS`]) that every
    /// event records. The error names the event and what it lacks.
    pub fn for_events(
        mode: Option<PlaybackMode>,
        events: &[&Event],
    ) -> Result<Self, DiagnoseError> {
        let mut pb = Self::new(mode.unwrap_or_default());
        if pb.mode == PlaybackMode::Phasor && !events.is_empty() {
            pb.channels
                .extend(field_recorded_by_all(events.iter().copied()));
        }
        for e in events {
            if let Some(why) = pb.mode.missing(e, &pb.channels) {
                let file = e.toml_path.as_ref().map_or_else(
                    || format!("<in-memory event '{}'>", e.name),
                    |p| p.display().to_string(),
                );
                let asked = match mode {
                    None => "the diagnosis's playback (none asked: the phasor playback; name \
                             one with --mode, Python mode=)"
                        .to_string(),
                    Some(m) => format!("the diagnosis's playback mode {m}"),
                };
                return Err(DiagnoseError::Event(format!(
                    "{file}: event '{}' {why}; {asked} needs it",
                    e.name
                )));
            }
        }
        Ok(pb)
    }

    /// The [`Compare`] of every re-fit's problem with the noise weights `1/σ_c²` (`sigmas` in
    /// the order of [`Playback::channels`]); `None` for the phasor playback, whose problems
    /// weigh P and Q by their `(w_P, w_Q)` pair.
    pub(super) fn compare(&self, sigmas: &[f64]) -> Option<Compare> {
        (!self.is_pq_phasor()).then(|| Compare {
            mode: self.mode,
            weights: self
                .channels
                .iter()
                .zip(sigmas)
                .map(|(c, s)| (*c, 1.0 / (s * s)))
                .collect(),
        })
    }

    /// The channels of `unit` played back on `event` (accurate integrator).
    pub(super) fn outputs(
        &self,
        unit: &itaipu_dynamics::unit::Unit,
        event: &Event,
    ) -> Result<ModeOutputs, DiagnoseError> {
        let ev = PreparedEvent::new(event);
        simulate_mode(unit, &ev, self.mode, &accurate_integrator())
            .map_err(|error| DiagnoseError::engine(&event.name, error))
    }

    /// Every trace of `unit` played back on `event` (accurate integrator): the phasor
    /// playback's are [`fitness`]'s.
    pub(super) fn traces(
        &self,
        unit: &itaipu_dynamics::unit::Unit,
        event: &Event,
    ) -> Result<Traces, DiagnoseError> {
        if self.is_pq_phasor() {
            return fitness(unit, event, false)
                .map(|(_, tr)| tr)
                .map_err(|err| DiagnoseError::simulation(&event.name, &err));
        }
        simulate_mode_traces(unit, event, self.mode, &accurate_integrator())
            .map_err(|error| DiagnoseError::engine(&event.name, error))
    }

    /// `"phasor: P, Q"`, `"closed_loop: |V|, Q, E_fd"`: for reports.
    pub fn describe(&self) -> String {
        format!(
            "{}: {}",
            self.mode,
            self.channels
                .iter()
                .map(|c| signal_name(*c))
                .collect::<Vec<_>>()
                .join(", ")
        )
    }
}

/// What every χ² of a diagnosis is computed with: the playback, the phasor playback's
/// `(w_P, w_Q)` and a mode's [`Compare`] (`None` in the phasor playback).
pub(super) type Scoring<'a> = (&'a Playback, (f64, f64), Option<&'a Compare>);

/// The name of a channel's residual in the evidence (`P`, `Q`, `|V|`, `Efd`, `Ifd`): the names
/// the catalog's signatures read.
pub fn signal_name(c: Channel) -> &'static str {
    match c {
        Channel::P => "P",
        Channel::Q => "Q",
        Channel::V => "|V|",
        Channel::Efd => "Efd",
        Channel::Ifd => "Ifd",
        Channel::Angle => "angle",
        Channel::Freq => "frequency",
    }
}

/// The channel a residual is named after ([`signal_name`]'s inverse).
pub fn signal_channel(name: &str) -> Option<Channel> {
    Channel::ALL.into_iter().find(|c| signal_name(*c) == name)
}

#[cfg(test)]
mod tests {
    use super::*;
    use itaipu_dynamics::event::Record;

    /// A flat 5 s record at 60 samples/s, with the field channels asked for.
    fn record(efd: bool, ifd: bool) -> Event {
        let n = 300;
        let rec = Record {
            time_s: (0..n).map(|i| i as f64 / 60.0).collect(),
            v_mag_pu: vec![1.0; n],
            v_ang_rad: vec![0.1; n],
            p_pu: vec![0.6; n],
            q_pu: vec![0.1; n],
            freq_hz: None,
            efd_pu: efd.then(|| vec![1.8; n]),
            ifd_pu: ifd.then(|| vec![1.6; n]),
        };
        Event::from_record("flat", rec, 1000.0, 60.0, None, None).unwrap()
    }

    /// The phasor playback compares the field channels every event records, and only those;
    /// a mode keeps its own channels; P and Q alone is the legacy phasor playback.
    #[test]
    fn the_phasor_playback_compares_the_field_channels_every_event_records() {
        let (both, efd_only, none) = (
            record(true, true),
            record(true, false),
            record(false, false),
        );
        let pb = |events: &[&Event]| Playback::for_events(None, events).unwrap();
        let full = pb(&[&both]);
        assert_eq!(
            full.channels,
            [Channel::P, Channel::Q, Channel::Efd, Channel::Ifd]
        );
        assert!(!full.is_pq_phasor());
        assert_eq!(full.describe(), "phasor: P, Q, Efd, Ifd");
        assert_eq!(
            pb(&[&both, &efd_only]).channels,
            [Channel::P, Channel::Q, Channel::Efd]
        );
        let legacy = pb(&[&both, &none]);
        assert!(legacy.is_pq_phasor(), "{legacy:?}");
        // The compared channels are weighted by their noise (a Compare), except in the legacy
        // playback, which keeps its (w_P, w_Q).
        let cmp = full.compare(&[0.002, 0.002, 0.01, 0.005]).unwrap();
        assert_eq!(cmp.weights.len(), 4);
        assert!((cmp.weights[2].1 - 1e4).abs() < 1e-6, "{:?}", cmp.weights);
        assert!(legacy.compare(&[0.002, 0.002]).is_none());
        // A mode's channels are its own (a staged test's recorder: E_fd in exciter_alone).
        let mode = Playback::for_events(Some(PlaybackMode::ExciterAlone), &[&both]).unwrap();
        assert_eq!(mode.channels, PlaybackMode::ExciterAlone.default_channels());
    }

    /// Every channel's residual name leads back to the channel, and the compared channels have
    /// the trace columns the reports read them from.
    #[test]
    fn signal_names_and_trace_columns_are_one_map() {
        for c in Channel::ALL {
            assert_eq!(signal_channel(signal_name(c)), Some(c), "{c:?}");
        }
        assert_eq!(signal_channel("Vt"), None);
        for mode in [
            PlaybackMode::Phasor,
            PlaybackMode::ExciterAlone,
            PlaybackMode::MachineFromEfd,
            PlaybackMode::ClosedLoop,
        ] {
            for c in mode.default_channels() {
                assert!(
                    itaipu_dynamics::simulate::trace_columns(*c).is_some(),
                    "{mode}: {c:?}"
                );
            }
        }
    }
}

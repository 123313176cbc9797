//! What an event declares besides its samples: the channels that were recorded, the time base of
//! the recorder, and the known inputs of a staged test (set-point steps).
//!
//! ```toml
//! channels = ["v", "p", "q", "efd"]   # what was recorded; no "angle": |V| only (CSV column v_pu)
//! time_base = "non_uniform"           # "uniform" (default) | "non_uniform"
//! [[step]]                            # a known input: a set-point step
//! time_s = 1.7                        # when (s, on the record's time axis)
//! size_pu = 0.05                      # how much (pu)
//! reference = "v_ref"                 # which reference: the AVR's voltage set point
//! [[step]]
//! time_s = 10.25
//! size_pu = -0.05
//! reference = "v_ref"
//! ```
//!
//! **Channels.** Without `channels` an event is a phasor record as before: a voltage phasor
//! (`v_re_pu` + `v_im_pu`, or `v_pu` + `angle_deg`), `p_pu`, `q_pu`, and whichever of `freq_hz`,
//! `efd_pu`, `ifd_pu` the CSV has. With `channels` the list must name exactly the recorded
//! channels, `v`, `p` and `q` among them (every playback initialises from the pre-event |V|, P,
//! Q); a record without `angle` gives |V| as `v_pu` alone, and [`crate::event::Record::v_ang_rad`]
//! then holds zeros that nothing may play back ([`crate::simulate`] refuses a phasor playback
//! of it; the playback modes of [`crate::mode`] need no angle). A declared channel the CSV lacks,
//! or a CSV column the declaration does not list, is an error naming the event file and the key.
//!
//! **E_fd and I_fd** are per unit of the machine model's field base: E_fd in pu of the field
//! voltage that gives 1 pu open-circuit voltage on the air-gap line, I_fd as X_ad·I_fd (1 pu
//! gives 1 pu air-gap voltage on the air-gap line), the non-reciprocal base PSS/E's exciters use
//! for their K_C term. Their no-load values are about 1 pu; a record whose median |E_fd| or
//! |I_fd| exceeds [`FIELD_LIMIT_PU`] holds volts or amperes and is refused.
//!
//! **Time base.** `"non_uniform"` declares a recorder whose stamps are not evenly spaced (a
//! digital excitation system's trending recorder). The stamps are **kept**, not resampled: every
//! playback stops at every recorded stamp (the integrators' knots), plays the measured inputs
//! linearly interpolated between stamps, and compares the simulated outputs at the recorded
//! stamps, exactly where the measurements are, as RaPId does (it interpolates its simulation onto
//! the reference's stamps). Resampling would interpolate the measurements themselves, low-passing
//! them and moving every compared value off a measured one, for nothing: nothing in a playback
//! needs a uniform grid. (A stage's `lowpass_hz` does: its zero-phase filter refuses
//! non-uniform stamps, naming the interval.) A record whose intervals vary by more than
//! [`NON_UNIFORM_SPREAD`] of the median without the declaration is a plausibility warning.
//!
//! **Steps.** A set-point step adds `size_pu` to the named reference from `time_s` on (right-
//! continuous: a sample stamped exactly `time_s` sees the new set point). The only reference
//! so far is `v_ref`, the AVR's voltage set point: the step enters the exciter where the
//! stabiliser signal V_S does (at the voltage summing point, after the transducer, see
//! [`crate::mode`]). Steps must lie inside the playback window, after its first sample (the unit
//! initialises before them) and at most at its last, in increasing time; the default init
//! window ends [`super::ONSET_GUARD_SAMPLES`] samples before the first step, and an init window
//! given in the file must end before it. Two steps, up then back, are the usual on-line AVR
//! test (the bundled Mostar record: +0.05 at 1.7 s, −0.05 at 10.25 s).

use std::fmt;

use serde::{Deserialize, Serialize};

/// Median |E_fd| or |I_fd| [pu] above which the channel holds volts or amperes, not per unit:
/// the no-load field voltage and current are about 1 pu on the air-gap-line base, and a
/// static exciter's ceiling rarely exceeds 10 pu.
pub const FIELD_LIMIT_PU: f64 = 20.0;

/// Spread of the sample intervals (max − min, relative to the median) above which a record not
/// declared `time_base = "non_uniform"` gets a plausibility warning.
pub const NON_UNIFORM_SPREAD: f64 = 0.1;

/// A recorded channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Channel {
    /// Terminal-voltage magnitude |V|.
    V,
    /// Terminal-voltage angle (a phasor record).
    Angle,
    /// Active power.
    P,
    /// Reactive power.
    Q,
    /// Frequency.
    Freq,
    /// Field voltage E_fd.
    Efd,
    /// Field current X_ad·I_fd.
    Ifd,
}

impl Channel {
    /// Every channel, in the order of [`Channel::name`]'s list.
    pub const ALL: [Channel; 7] = [
        Channel::V,
        Channel::Angle,
        Channel::P,
        Channel::Q,
        Channel::Freq,
        Channel::Efd,
        Channel::Ifd,
    ];

    /// The name in event files and calibration specs.
    pub fn name(self) -> &'static str {
        match self {
            Channel::V => "v",
            Channel::Angle => "angle",
            Channel::P => "p",
            Channel::Q => "q",
            Channel::Freq => "freq",
            Channel::Efd => "efd",
            Channel::Ifd => "ifd",
        }
    }

    /// The CSV column(s) holding it.
    pub fn columns(self) -> &'static str {
        match self {
            Channel::V => "v_pu (or v_re_pu + v_im_pu)",
            Channel::Angle => "angle_deg (or v_re_pu + v_im_pu)",
            Channel::P => "p_pu",
            Channel::Q => "q_pu",
            Channel::Freq => "freq_hz",
            Channel::Efd => "efd_pu",
            Channel::Ifd => "ifd_pu",
        }
    }

    /// The channel named `s` (exact name).
    pub fn parse(s: &str) -> Option<Channel> {
        Channel::ALL.into_iter().find(|c| c.name() == s)
    }

    /// The names of all channels, for messages.
    pub fn names() -> String {
        Channel::ALL.map(|c| c.name()).join(", ")
    }
}

impl fmt::Display for Channel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// How the recorder's time stamps are spaced.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TimeBase {
    /// Evenly spaced (a PMU's reporting rate).
    #[default]
    Uniform,
    /// Declared unevenly spaced: kept as recorded (see the module documentation).
    NonUniform,
}

impl TimeBase {
    pub fn name(self) -> &'static str {
        match self {
            TimeBase::Uniform => "uniform",
            TimeBase::NonUniform => "non_uniform",
        }
    }
}

/// Which reference a set-point step moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum StepReference {
    /// The AVR's voltage set point V_ref.
    VRef,
}

impl StepReference {
    /// Accepted names.
    pub const NAMES: [&'static str; 1] = ["v_ref"];

    pub fn name(self) -> &'static str {
        match self {
            StepReference::VRef => "v_ref",
        }
    }

    pub fn parse(s: &str) -> Option<StepReference> {
        match s {
            "v_ref" => Some(StepReference::VRef),
            _ => None,
        }
    }
}

/// A known set-point step of a staged test: `size_pu` added to `reference` from `time_s` on.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SetpointStep {
    pub time_s: f64,
    pub size_pu: f64,
    pub reference: StepReference,
}

/// What an event declares besides its samples (the event TOML's `channels`, `time_base` and
/// `[[step]]`; in memory, [`crate::event::Event::from_record_declared`]).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Declaration {
    /// The recorded channels; `None`: a phasor record with whatever optional columns it has.
    pub channels: Option<Vec<Channel>>,
    pub time_base: TimeBase,
    /// Set-point steps, in increasing time.
    pub steps: Vec<SetpointStep>,
}

impl Declaration {
    /// Whether the declared channels include the angle (true without a declaration).
    pub fn has_angle(&self) -> bool {
        match &self.channels {
            None => true,
            Some(c) => c.contains(&Channel::Angle),
        }
    }
}

/// The sum of the steps in effect at `t` (right-continuous: a step at `t` is in effect).
pub fn step_level(steps: &[SetpointStep], t: f64) -> f64 {
    steps
        .iter()
        .filter(|s| s.time_s <= t)
        .map(|s| s.size_pu)
        .sum()
}

//! The field channels a record may hold besides the terminal quantities, and which of them a
//! set of events records in common.

use super::{Channel, Event};

/// The field channels a phasor playback compares besides P and Q when every event records them
/// (E_fd and X_ad I_fd from the excitation system's recorder). A calibration on P and Q alone
/// may bend X_d and the exciter's gain so that the simulated field runs off the recorded one by
/// many noise widths; the recorded field is what shows a ceiling or a saturation that bending
/// absorbed.
pub const FIELD_CHANNELS: [Channel; 2] = [Channel::Efd, Channel::Ifd];

/// The field channels ([`FIELD_CHANNELS`]) that every one of `events` records (none for no
/// event): what the phasor playback, `channels = "recorded"` and the fit's warning compare.
pub fn field_recorded_by_all<'a>(events: impl Iterator<Item = &'a Event> + Clone) -> Vec<Channel> {
    let mut any = events.clone().peekable();
    if any.peek().is_none() {
        return vec![];
    }
    FIELD_CHANNELS
        .into_iter()
        .filter(|c| events.clone().all(|e| e.has(*c)))
        .collect()
}

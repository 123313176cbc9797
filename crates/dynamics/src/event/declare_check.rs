//! The checks of an event's declaration ([`super::Declaration`]) against its record: the
//! declared channels against the columns found, the set-point steps against the playback and
//! init windows. Every message names the file and the key.

use std::path::Path;

use super::{Channel, Declaration, EventError, SetpointStep};

fn err(src: &Path, field: impl Into<String>, message: impl Into<String>) -> EventError {
    EventError::Declaration {
        path: src.to_path_buf(),
        field: field.into(),
        message: message.into(),
    }
}

/// The channels of the event: the declared ones, checked against those `found` in the data
/// (`data`: "the CSV file x.csv", "the record"), or the found ones without a declaration.
pub(super) fn resolve_channels(
    src: &Path,
    declaration: &Declaration,
    found: &[Channel],
    data: &str,
) -> Result<Vec<Channel>, EventError> {
    let Some(declared) = &declaration.channels else {
        return Ok(found.to_vec());
    };
    for (k, c) in declared.iter().enumerate() {
        if declared[..k].contains(c) {
            return Err(err(src, "channels", format!("\"{c}\" is listed twice")));
        }
    }
    for need in [Channel::V, Channel::P, Channel::Q] {
        if !declared.contains(&need) {
            return Err(err(
                src,
                "channels",
                format!(
                    "must list \"{need}\": every playback initialises from the pre-event |V|, P \
                     and Q (channels: {})",
                    Channel::names()
                ),
            ));
        }
    }
    for c in declared {
        if !found.contains(c) {
            return Err(err(
                src,
                "channels",
                format!(
                    "\"{c}\" is declared but {data} does not hold it (column {})",
                    c.columns()
                ),
            ));
        }
    }
    for c in found {
        if !declared.contains(c) {
            return Err(err(
                src,
                "channels",
                format!(
                    "{data} holds \"{c}\" (column {}), which channels does not list: list it, or \
                     leave the column out",
                    c.columns()
                ),
            ));
        }
    }
    // Canonical order.
    Ok(Channel::ALL
        .into_iter()
        .filter(|c| declared.contains(c))
        .collect())
}

/// Checks the steps against the playback window `[t_first, t_last]` (the first and last
/// playback samples): finite, non-zero sizes, times after the first sample and at most at the
/// last, strictly increasing.
pub(super) fn check_steps(
    src: &Path,
    steps: &[SetpointStep],
    t_first: f64,
    t_last: f64,
    window_desc: &str,
) -> Result<(), EventError> {
    for (k, s) in steps.iter().enumerate() {
        if !(s.size_pu.is_finite() && s.size_pu != 0.0) {
            return Err(err(
                src,
                format!("step[{k}].size_pu"),
                format!("{} must be a finite, non-zero size in pu", s.size_pu),
            ));
        }
        if !s.time_s.is_finite() {
            return Err(err(
                src,
                format!("step[{k}].time_s"),
                format!("{} is not a finite time", s.time_s),
            ));
        }
        if !(s.time_s > t_first && s.time_s <= t_last) {
            return Err(err(
                src,
                format!("step[{k}].time_s"),
                format!(
                    "{} s lies outside {window_desc}: a step must come after its first sample \
                     ({t_first} s; the unit starts in steady state before it) and at most at its \
                     last ({t_last} s)",
                    s.time_s
                ),
            ));
        }
        if k > 0 && !(s.time_s > steps[k - 1].time_s) {
            return Err(err(
                src,
                format!("step[{k}].time_s"),
                format!(
                    "{} s is not after step[{}].time_s = {} s: list the steps in increasing time",
                    s.time_s,
                    k - 1,
                    steps[k - 1].time_s
                ),
            ));
        }
    }
    Ok(())
}

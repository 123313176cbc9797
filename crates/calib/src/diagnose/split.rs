//! Step 3, the split: fitted and held-out samples (held-out events, or alternating blocks of
//! each event aligned on its disturbance).

use crate::problem::EventData;
use itaipu_dynamics::event::Event;

use super::error::DiagnoseError;

/// Which alternate blocks are fitted. The block that opens on the disturbance (or on the
/// record's first sample, ambient data) is fitted in both folds: its few samples of a fault dip
/// are what the fast dynamics are identified from, and a fold holding them out would test
/// whether a re-fit extrapolates the trigger, not whether it predicts the response.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Fold {
    /// Even blocks fitted, odd blocks held out.
    #[default]
    Even,
    /// Odd blocks (and the disturbance's) fitted, even blocks held out: the swapped fold.
    Odd,
}

impl Fold {
    /// Whether block `k` (counted from the disturbance's, which is block 0) is fitted.
    fn fits(self, k: i64) -> bool {
        match self {
            Fold::Even => k % 2 == 0,
            Fold::Odd => k % 2 != 0 || k == 0,
        }
    }

    fn describe(self) -> &'static str {
        match self {
            Fold::Even => "even blocks fitted, odd blocks held out",
            Fold::Odd => {
                "odd blocks and the disturbance's fitted, the other even blocks held out (the swapped fold)"
            }
        }
    }
}

/// Fit and held-out problem data.
pub(super) struct Split {
    pub(super) fit: Vec<EventData>,
    pub(super) held: Vec<EventData>,
    /// The held-out samples are windows on the fitted events (alternate blocks), not events of
    /// their own: one simulation gives both.
    pub(super) blocks: bool,
    pub(super) description: String,
}

pub(super) fn split(
    events: &[Event],
    held_out: &[Event],
    block_s: f64,
    fold: Fold,
) -> Result<Split, DiagnoseError> {
    let data =
        |e: &Event| EventData::new(e, None, None).map_err(|e| DiagnoseError::Setup(e.to_string()));
    if !held_out.is_empty() {
        return Ok(Split {
            fit: events.iter().map(data).collect::<Result<_, _>>()?,
            held: held_out.iter().map(data).collect::<Result<_, _>>()?,
            blocks: false,
            description: format!(
                "fitted on {} event(s), judged on {} held-out event(s)",
                events.len(),
                held_out.len()
            ),
        });
    }
    let (mut fit, mut held) = (vec![], vec![]);
    for e in events {
        let d = data(e)?;
        // Aligned on the event's onset (none, ambient data: from the record's start).
        let t0 = e
            .onset_s()
            .map_or(e.record.time_s[0], |a| a - DISTURBANCE_LEAD_S);
        let even: Vec<bool> = e
            .record
            .time_s
            .iter()
            .map(|t| fold.fits(((t - t0) / block_s).floor() as i64))
            .collect();
        let mut f = d.clone();
        let mut h = d;
        for ((fw, hw), e) in f
            .in_window
            .iter_mut()
            .zip(h.in_window.iter_mut())
            .zip(&even)
        {
            *fw &= *e;
            *hw &= !*e;
        }
        fit.push(f);
        held.push(h);
    }
    Ok(Split {
        fit,
        held,
        blocks: true,
        description: format!(
            "alternate {block_s} s blocks of each event, one fitted block starting \
             {DISTURBANCE_LEAD_S} s before the disturbance: {}",
            fold.describe()
        ),
    })
}

/// Length of the contiguous segments of the second held-out test [s]: a fitted segment holds
/// the disturbance and the first seconds after it, the held-out ones the later phases of the
/// response (the same alignment as the blocks).
pub(super) const SEGMENT_S: f64 = 3.0;

/// Largest ratio, per held-out sample, of the baseline's χ² on the held-out segments to its χ²
/// on the held-out blocks for the second held-out test to count. A baseline that predicts
/// unseen samples as it predicts the interleaved ones has a ratio near 1 (both at the noise, or
/// the same misfit per sample); at twice the per-sample χ² the baseline re-fitted on the
/// segments has followed the phases of the response it saw and predicts the others much worse,
/// and then which of two such predictions fails less says nothing of structure.
pub(super) const SEGMENT_OVERFIT: f64 = 2.0;

/// How far before the disturbance (the event's onset, [`Event::onset`]) the fitted block that
/// holds it starts [s].
///
/// The fit/held-out split aligns its blocks on the onset, so that the few samples of a fault
/// dip (the ones that say most about the fast dynamics, and about what limits and saturation
/// do) are fitted rather than left to be predicted by a re-fit that never saw them: with blocks
/// counted from the start of the record, a 0.1 s dip falls in a held-out block as often as not.
/// An event without an onset (ambient data) has its blocks counted from its first sample.
pub(super) const DISTURBANCE_LEAD_S: f64 = 0.1;

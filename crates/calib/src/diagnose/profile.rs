//! Where a diagnosis's time goes: each re-fit's kind and name, and the profile of wall time,
//! simulations and re-fits per kind and phase ([`super::Diagnosis::profile`]).

use super::report::ProfileRow;

/// Where a diagnosis' time goes ([`super::Diagnosis::profile`]): wall time, simulations and
/// re-fits per kind of re-fit ([`RefitKind`]) and phase, summed over the run (re-fits of one cause run one
/// after another; the swarm's and the local method's simulations run on every thread).
#[derive(Default)]
pub(super) struct Profile(std::sync::Mutex<Vec<ProfileRow>>);

impl Profile {
    /// Adds `wall_s` seconds, `simulations` and `refits` to the row (`kind`, `phase`).
    pub(super) fn add(
        &self,
        kind: &str,
        phase: &str,
        wall_s: f64,
        simulations: usize,
        refits: usize,
    ) {
        let mut rows = self.0.lock().unwrap_or_else(|e| e.into_inner());
        match rows.iter_mut().find(|r| r.kind == kind && r.phase == phase) {
            Some(r) => {
                r.wall_s += wall_s;
                r.simulations += simulations;
                r.refits += refits;
            }
            None => rows.push(ProfileRow {
                kind: kind.to_string(),
                phase: phase.to_string(),
                wall_s,
                simulations,
                refits,
            }),
        }
    }

    /// The rows in an order that does not depend on the threads: the diagnosis's own phases
    /// as they ran (one after another), then each kind of re-fit in [`RefitKind`]'s order with
    /// its phases by name (re-fits of one kind run side by side, so which phase first appeared
    /// is the scheduler's choice).
    pub(super) fn rows(&self) -> Vec<ProfileRow> {
        let mut rows = self.0.lock().unwrap_or_else(|e| e.into_inner()).clone();
        let rank = |kind: &str| RefitKind::ALL.iter().position(|k| k.name() == kind);
        rows.sort_by(|a, b| match (rank(&a.kind), rank(&b.kind)) {
            (None, None) => std::cmp::Ordering::Equal,
            (None, Some(_)) => std::cmp::Ordering::Less,
            (Some(_), None) => std::cmp::Ordering::Greater,
            (Some(x), Some(y)) => x.cmp(&y).then_with(|| a.phase.cmp(&b.phase)),
        });
        rows
    }
}

/// The kind of a re-fit, what the profile counts it as: the reference's nuisance re-fit, a
/// cause's baseline, its extension (every start and structure), the baseline again from the
/// extension's values, the second held-out test's segments, or the surrogate (noise-only)
/// re-fits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum RefitKind {
    Reference,
    Baseline,
    Extension,
    BaselineAgain,
    Segments,
    Surrogate,
}

impl RefitKind {
    /// Every kind, in the profile's order.
    const ALL: [RefitKind; 6] = [
        Self::Reference,
        Self::Baseline,
        Self::Extension,
        Self::BaselineAgain,
        Self::Segments,
        Self::Surrogate,
    ];

    /// The profile's name of the kind.
    pub(super) fn name(self) -> &'static str {
        match self {
            Self::Reference => "reference",
            Self::Baseline => "baselines",
            Self::Extension => "extensions",
            Self::BaselineAgain => "baseline again",
            Self::Segments => "segments test",
            Self::Surrogate => "surrogate (noise-only) re-fits",
        }
    }
}

/// A re-fit's kind and its name in progress messages (`"saturation baseline"`).
#[derive(Debug, Clone)]
pub(super) struct Label {
    pub(super) kind: RefitKind,
    pub(super) text: String,
}

impl Label {
    pub(super) fn new(kind: RefitKind, text: impl Into<String>) -> Self {
        Self {
            kind,
            text: text.into(),
        }
    }

    /// The same kind of re-fit, its name followed by `more` (another start of the same re-fit).
    pub(super) fn then(&self, more: &str) -> Self {
        Self::new(self.kind, format!("{} {more}", self.text))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Another start of a re-fit is counted as the same kind, whatever its name says: an
    /// extension polished "from the baseline" is an extension, not a baseline.
    #[test]
    fn a_further_start_keeps_its_refits_kind() {
        let ext = Label::new(RefitKind::Extension, "saturation");
        let polish = ext.then("from the baseline");
        assert_eq!(polish.kind, RefitKind::Extension);
        assert_eq!(polish.text, "saturation from the baseline");
        let seg = Label::new(RefitKind::Segments, "oel on segments").then("from the baseline");
        assert_eq!(seg.kind.name(), "segments test");
        let kinds = [
            RefitKind::Reference,
            RefitKind::Baseline,
            RefitKind::Extension,
            RefitKind::BaselineAgain,
            RefitKind::Segments,
            RefitKind::Surrogate,
        ];
        let mut names: Vec<&str> = kinds.iter().map(|k| k.name()).collect();
        names.sort();
        names.dedup();
        assert_eq!(names.len(), kinds.len(), "two kinds share a profile name");
    }
}

//! The baselines re-fitted during a diagnosis, kept by what makes one re-fit differ from
//! another ([`BaselineKey`]): the playback of the record, the samples fitted and every field of
//! every bound freed. A re-fit depends only on these and the diagnosis's seed, so a baseline
//! re-fitted once serves every cause that frees the same parameters alike.

use std::collections::BTreeMap;

use crate::bounds::FreeBound;

use super::refit::Refit;

/// How a cause's re-fits play the record back.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub(super) enum Input {
    /// As the events say (their input low-passed where they declare a cut-off).
    AsEvents,
    /// As recorded (the cut-off cleared): for a cause whose mode lies above it.
    AsRecorded,
}

/// The samples a baseline is re-fitted on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub(super) enum Samples {
    /// The record's split (fitted blocks or events, held-out ones).
    Record,
    /// A surrogate record's split, by draw ([`super::DiagnoseOptions::null_draws`]).
    Surrogate(usize),
    /// The contiguous segments of the second held-out test.
    Segments,
}

/// One bound as a re-fit reads it: its parameter, range, start, prior spread, scan, polish role
/// and prior, the numbers by their bits (two bounds are the same re-fit only when every number
/// is the same).
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
struct BoundKey {
    param: String,
    min: u64,
    max: u64,
    start: Option<u64>,
    spread: Option<u64>,
    scan: usize,
    polish_only: bool,
    prior: Option<(u64, u64)>,
}

impl From<&FreeBound> for BoundKey {
    fn from(b: &FreeBound) -> Self {
        BoundKey {
            param: b.param.clone(),
            min: b.min.to_bits(),
            max: b.max.to_bits(),
            start: b.start.map(f64::to_bits),
            spread: b.spread.map(f64::to_bits),
            scan: b.scan,
            polish_only: b.polish_only,
            prior: b
                .prior
                .as_ref()
                .map(|p| (p.center.to_bits(), p.spread.to_bits())),
        }
    }
}

/// Which baseline a re-fit is: two causes share a cached baseline only when they would have
/// searched it alike (the same playback, samples and bounds), so that a cause's numbers do not
/// depend on which cause was tried first.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub(super) struct BaselineKey {
    input: Input,
    samples: Samples,
    bounds: Vec<BoundKey>,
}

impl BaselineKey {
    /// The re-fit over `bounds` on the record played back as `input`.
    pub(super) fn new(input: Input, bounds: &[FreeBound]) -> Self {
        Self {
            input,
            samples: Samples::Record,
            bounds: bounds.iter().map(BoundKey::from).collect(),
        }
    }

    /// The same re-fit on the surrogate record of draw `draw`.
    pub(super) fn on_surrogate(&self, draw: usize) -> Self {
        Self {
            samples: Samples::Surrogate(draw),
            ..self.clone()
        }
    }

    /// The same re-fit on the contiguous segments of the second held-out test.
    pub(super) fn on_segments(&self) -> Self {
        Self {
            samples: Samples::Segments,
            ..self.clone()
        }
    }
}

/// The baselines one candidate reads: those re-fitted before its batch (`shared`, read-only
/// while the batch's candidates are scored side by side: every main baseline the batch needs)
/// and those it re-fits itself (`own`, merged into the shared map after the batch: its
/// surrogates' and segments' baselines, and a main one whose re-fit before the batch failed).
/// Every re-fit of a given set of bounds on a given split is the same (the search's seed is the
/// diagnosis's, not the candidate's), so which candidate re-fitted a baseline first changes no
/// number.
pub(super) struct BaselineCache<'m> {
    shared: &'m BTreeMap<BaselineKey, Refit>,
    own: BTreeMap<BaselineKey, Refit>,
}

impl<'m> BaselineCache<'m> {
    pub(super) fn new(shared: &'m BTreeMap<BaselineKey, Refit>) -> Self {
        Self {
            shared,
            own: BTreeMap::new(),
        }
    }

    pub(super) fn get(&self, key: &BaselineKey) -> Option<&Refit> {
        self.own.get(key).or_else(|| self.shared.get(key))
    }

    pub(super) fn contains_key(&self, key: &BaselineKey) -> bool {
        self.get(key).is_some()
    }

    pub(super) fn insert(&mut self, key: BaselineKey, r: Refit) {
        self.own.insert(key, r);
    }

    /// The baseline under `key`, which the caller has inserted or found.
    pub(super) fn at(&self, key: &BaselineKey) -> &Refit {
        self.get(key)
            .expect("a baseline re-fitted before it is read")
    }

    /// The baselines this candidate re-fitted itself.
    pub(super) fn into_own(self) -> BTreeMap<BaselineKey, Refit> {
        self.own
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::problem::Prior;

    /// Two baselines are the same re-fit only when every field of every bound is the same and
    /// they play the same record on the same samples: a cause that frees the same parameters
    /// alike shares one, any difference (a start, a scan, a prior, the polish role, the
    /// playback, the samples) makes another.
    #[test]
    fn a_baseline_is_shared_only_by_the_same_re_fit() {
        let b = FreeBound::new("exciter.k", 30.0, 300.0).starting_at(120.0);
        let key = |bounds: &[FreeBound]| BaselineKey::new(Input::AsEvents, bounds);
        let same = key(std::slice::from_ref(&b));
        assert_eq!(same, key(std::slice::from_ref(&b)));
        let others = [
            FreeBound {
                scan: 8,
                ..b.clone()
            },
            FreeBound {
                polish_only: true,
                ..b.clone()
            },
            b.clone().starting_at(121.0),
            FreeBound {
                prior: Some(Prior {
                    center: 100.0,
                    spread: 0.5,
                }),
                ..b.clone()
            },
            FreeBound {
                max: 301.0,
                ..b.clone()
            },
        ];
        for o in &others {
            assert_ne!(same, key(std::slice::from_ref(o)), "{o:?}");
        }
        assert_ne!(same, key(&[b.clone(), b.clone()]));
        assert_ne!(
            same,
            BaselineKey::new(Input::AsRecorded, std::slice::from_ref(&b))
        );
        assert_ne!(same, same.on_segments());
        assert_ne!(same.on_surrogate(0), same.on_surrogate(1));
        assert_eq!(same.on_surrogate(1), key(&[b]).on_surrogate(1));
    }
}

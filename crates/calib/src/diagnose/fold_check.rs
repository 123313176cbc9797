//! Step 7, the named cause on the other fold: the cause alone diagnosed again with the fitted
//! and held-out blocks swapped ([`Fold::Odd`]) and the next seed. A verdict that holds on one
//! split and one seed only is `inconclusive`, with both folds' numbers.

use itaipu_dynamics::event::Event;

use crate::fit::Progress;

use super::error::DiagnoseError;
use super::options::DiagnoseOptions;
use super::report::{CandidateReport, DiagnoseResult, Grade, Verdict, VerdictCause};
use super::split::Fold;

/// Whether the other fold is tried for the verdict of `r`: a named cause, blocks of the events
/// split by the diagnosis itself (held-out events are the user's split), the check asked for,
/// and this run on the first fold.
fn applies(r: &DiagnoseResult, held_out: &[Event], opts: &DiagnoseOptions) -> bool {
    opts.other_fold
        && opts.fold == Fold::Even
        && held_out.is_empty()
        && r.report.verdict.names_a_cause()
}

/// The options of the other fold's run: the named cause `id` alone (no look-alikes: the rivals
/// were judged on the first fold), the swapped blocks, the next seed.
fn other_options(id: &str, opts: &DiagnoseOptions) -> DiagnoseOptions {
    DiagnoseOptions {
        causes: vec![id.to_string()],
        fold: Fold::Odd,
        seed: opts.seed.wrapping_add(1),
        look_alikes: false,
        other_fold: false,
        ..opts.clone()
    }
}

/// The numbers a fold's verdict quotes for cause `id`: its record evidence and its stated
/// probability, or why its candidate was not named.
fn numbers(v: &Verdict, candidates: &[CandidateReport], id: &str) -> String {
    let cand = candidates.iter().find(|c| c.cause == id);
    let evidence = cand
        .and_then(|c| c.gains.as_ref())
        .map_or("no gain".to_string(), |g| {
            format!("2 ln B = {:.1}", g.record_evidence)
        });
    match (v.probability, v.grade) {
        (Some(p), Some(g)) if v.cause == *id => {
            format!("{evidence}, posterior probability {p:.3}, {}", g.as_str())
        }
        _ => format!(
            "{evidence}, {}",
            cand.map_or("not scored", |c| c.note.as_str())
                .trim_start_matches("not named: ")
        ),
    }
}

/// Runs the named cause of `r` on the other fold (by `run`, the diagnosis itself) and keeps the
/// verdict when it holds there (its statement quoting the other fold, a `strong` grade only
/// when it is strong there too) or when the other fold does not contradict it (a positive
/// evidence that is not enough to name it alone: `moderate`); makes it `inconclusive` with both
/// folds' numbers when the other fold contradicts it (no gain over the baseline there, or a
/// check refusing it).
pub(super) fn check(
    mut r: DiagnoseResult,
    held_out: &[Event],
    opts: &DiagnoseOptions,
    progress: &dyn Progress,
    run: impl Fn(&DiagnoseOptions) -> Result<DiagnoseResult, DiagnoseError>,
) -> Result<DiagnoseResult, DiagnoseError> {
    if !applies(&r, held_out, opts) {
        return Ok(r);
    }
    let id = r.report.verdict.cause.as_str().to_string();
    let other = other_options(&id, opts);
    progress.message(&format!(
        "diagnose: {id} on the other fold (blocks swapped, seed {})",
        other.seed
    ));
    let b = match run(&other) {
        Ok(b) => b,
        Err(e @ DiagnoseError::Interrupted { .. }) => return Err(e),
        // A fold whose run fails does not decide either way: the verdict stands, not strong.
        Err(e) => {
            let v = &mut r.report.verdict;
            v.statement += &format!(" The check on the other fold could not run ({e}).");
            if v.grade == Some(Grade::Strong) {
                v.grade = Some(Grade::Moderate);
                if let Some(c) = v.confidence.as_mut() {
                    c.not_strong.push("not checked on the other fold".into());
                }
            }
            return Ok(r);
        }
    };
    r.report.wall_s += b.report.wall_s;
    let first = numbers(&r.report.verdict, &r.report.candidates, &id);
    let second = numbers(&b.report.verdict, &b.report.candidates, &id);
    let v = &mut r.report.verdict;
    if b.report.verdict.cause == v.cause {
        v.statement = format!(
            "{} On the other fold (blocks swapped, seed {}) it holds: {second}.",
            v.statement, other.seed
        );
        if v.grade == Some(Grade::Strong) && b.report.verdict.grade != Some(Grade::Strong) {
            v.grade = Some(Grade::Moderate);
            if let Some(c) = v.confidence.as_mut() {
                c.not_strong
                    .push("on the other fold it is named, not strong".into());
            }
            v.statement += " Graded moderate: on the other fold it is not strong.";
        }
        return Ok(r);
    }
    // Not named there, yet not against it: its gain still favours it over its baseline on the
    // swapped blocks (2 ln B > 0) and no check refused it. The two folds share most of the
    // record, so the threshold's stringency is the first fold's; the second is asked not to
    // contradict it. The name stands, not strong.
    let favours = b
        .report
        .candidates
        .iter()
        .find(|c| c.cause == id)
        .is_some_and(|c| {
            !c.note.starts_with("not named")
                && c.gains.as_ref().is_some_and(|g| g.record_evidence > 0.0)
        });
    if favours {
        v.statement = format!(
            "{} On the other fold (blocks swapped, seed {}) its gain is smaller and not named on its own, \
             but it does not contradict it: {second}.",
            v.statement, other.seed
        );
        if v.grade == Some(Grade::Strong) {
            v.grade = Some(Grade::Moderate);
            v.statement += " Graded moderate for it.";
        }
        if let Some(c) = v.confidence.as_mut() {
            c.not_strong
                .push("on the other fold not named on its own".into());
        }
        return Ok(r);
    }
    let title = format!("inconclusive: {id} holds on one fold only");
    *v = Verdict {
        cause: VerdictCause::Inconclusive,
        title,
        statement: format!(
            "Inconclusive. {id} is named on the fitted even blocks (seed {}: {first}) but not with the blocks \
             swapped (seed {}: {second}): the verdict follows the split or the seed, so it is no verdict. \
             A longer record, or another event, would decide.",
            opts.seed, other.seed
        ),
        key_parameters: vec![],
        gains: None,
        where_: v.where_.clone(),
        grade: None,
        probability: None,
        confidence: v.confidence.take(),
        competing: vec![(id, 0.0)],
    };
    r.extended_unit = None;
    r.after.clear();
    r.report.evidence_after.clear();
    Ok(r)
}

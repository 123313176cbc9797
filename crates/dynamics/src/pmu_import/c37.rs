//! C37.118-style CSV exports: one row per data frame, a header naming the columns.
//!
//! Time is one of: a `timestamp` (also `time`, `utc`, `datetime`) column holding ISO 8601
//! stamps (`2021-03-04T05:06:07.016667Z`, `T` or blank, an optional `Z` or `±hh:mm`) or epoch
//! seconds (`1614834367.016667`); a `soc` column (second of century, i.e. epoch seconds) with
//! `fracsec` as a fraction of a second (FRACSEC / TIME_BASE); or `time_s`, seconds from any
//! origin. An optional `stat` column (decimal or `0x` hex) flags samples: data-error bits 15-14
//! set make a dropout; bit 13 (PMU not synchronised) and bit 9 (data modified) are counted in a
//! warning. Phasor and frequency columns as in [`super`]; other columns are ignored, with a
//! warning naming them. An empty field or `NaN` is a dropout; any other text that is not a
//! number is an error naming the line and the column.

use std::path::Path;

use super::{assign, finish, parse_iso, ImportError, ImportOptions, ImportReport, RawSample};
use crate::event::Event;

enum TimeCols {
    Stamp(usize),
    SocFrac(usize, usize),
    Relative(usize),
}

fn norm(h: &str) -> String {
    h.trim()
        .to_ascii_lowercase()
        .split(|c: char| c == '_' || c == '.' || c == '-' || c.is_whitespace())
        .filter(|s| !s.is_empty())
        .collect::<Vec<_>>()
        .join("_")
}

/// Splits a decimal number into whole seconds and fraction without losing the µs of an epoch.
fn split_seconds(s: &str) -> Option<(i64, f64)> {
    let s = s.trim();
    let (w, f) = s.split_once('.').unwrap_or((s, ""));
    if f.is_empty() || f.chars().all(|c| c.is_ascii_digit()) {
        let whole: i64 = w.parse().ok()?;
        let frac: f64 = if f.is_empty() {
            0.0
        } else {
            format!("0.{f}").parse().ok()?
        };
        return Some(if whole < 0 || w.starts_with('-') {
            (whole, -frac)
        } else {
            (whole, frac)
        });
    }
    None
}

/// Reads a C37.118-style CSV into an event (see the module documentation).
pub fn import(path: &Path, opts: &ImportOptions) -> Result<(Event, ImportReport), ImportError> {
    let text = std::fs::read(path).map_err(|source| ImportError::Io {
        path: path.into(),
        source,
    })?;
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(true)
        .flexible(true)
        .trim(csv::Trim::All)
        .from_reader(text.as_slice());
    let headers = rdr
        .headers()
        .map_err(|e| {
            ImportError::data(
                path,
                Some("line 1".into()),
                format!("cannot read the header: {e}"),
            )
        })?
        .clone();
    if headers.is_empty() || headers.iter().all(|h| h.is_empty()) {
        return Err(ImportError::data(
            path,
            Some("line 1".into()),
            "empty header",
        ));
    }
    let names: Vec<String> = headers.iter().map(|h| h.to_string()).collect();
    let find = |keys: &[&str]| names.iter().position(|h| keys.contains(&norm(h).as_str()));
    let time = if let Some(k) = find(&["timestamp", "time", "utc", "datetime", "date_time"]) {
        TimeCols::Stamp(k)
    } else if let (Some(a), Some(b)) = (find(&["soc"]), find(&["fracsec"])) {
        TimeCols::SocFrac(a, b)
    } else if let Some(k) = find(&["time_s"]) {
        TimeCols::Relative(k)
    } else {
        return Err(ImportError::data(
            path,
            Some("line 1".into()),
            "no time column: timestamp (ISO 8601 or epoch seconds), soc + fracsec, or time_s",
        ));
    };
    let stat = find(&["stat", "status", "stat_word"]);
    let dfreq = find(&["dfreq", "rocof"]);
    let skip: Vec<usize> = match time {
        TimeCols::Stamp(k) | TimeCols::Relative(k) => vec![k],
        TimeCols::SocFrac(a, b) => vec![a, b],
    }
    .into_iter()
    .chain(stat)
    .chain(dfreq)
    .collect();
    let chans: Vec<(usize, String, Option<String>)> = names
        .iter()
        .enumerate()
        .filter(|(k, _)| !skip.contains(k))
        .map(|(k, n)| (k, n.clone(), None))
        .collect();
    let mut ignored = vec![];
    let a = assign(&chans, &opts.map, &mut ignored)
        .map_err(|m| ImportError::data(path, Some("line 1".into()), m))?;
    let mut warnings = vec![];
    if !ignored.is_empty() {
        warnings.push(format!("columns not used: {}", ignored.join(", ")));
    }
    let mut samples = vec![];
    let (mut unsynced, mut modified) = (0usize, 0usize);
    let mut start = None;
    for rec in rdr.records() {
        let rec = rec.map_err(|e| {
            let line = e.position().map(|p| p.line() as usize);
            ImportError::data(path, line.map(|l| format!("line {l}")), format!("CSV: {e}"))
        })?;
        let line = rec.position().map(|p| p.line() as usize).unwrap_or(0);
        if rec.iter().all(|f| f.is_empty()) {
            continue;
        }
        let at = |col: usize| Some(format!("line {line}, column {}", names[col]));
        if rec.len() != names.len() {
            return Err(ImportError::data(
                path,
                Some(format!("line {line}")),
                format!("{} fields, the header has {}", rec.len(), names.len()),
            ));
        }
        let (sec, frac) = match time {
            TimeCols::Stamp(k) => parse_iso(&rec[k])
                .or_else(|| split_seconds(&rec[k]))
                .ok_or_else(|| {
                    ImportError::data(
                        path,
                        at(k),
                        format!(
                            "'{}' is not an ISO 8601 time stamp or epoch seconds",
                            &rec[k]
                        ),
                    )
                })?,
            TimeCols::Relative(k) => split_seconds(&rec[k])
                .or_else(|| {
                    rec[k]
                        .parse::<f64>()
                        .ok()
                        .filter(|x| x.is_finite())
                        .map(|x| (x.floor() as i64, x - x.floor()))
                })
                .ok_or_else(|| {
                    ImportError::data(
                        path,
                        at(k),
                        format!("'{}' is not a number of seconds", &rec[k]),
                    )
                })?,
            TimeCols::SocFrac(a, b) => {
                let soc: i64 = rec[a].parse().map_err(|_| {
                    ImportError::data(
                        path,
                        at(a),
                        format!("'{}' is not a whole number of seconds", &rec[a]),
                    )
                })?;
                let fr: f64 = rec[b]
                    .parse()
                    .ok()
                    .filter(|x: &f64| (0.0..1.0).contains(x))
                    .ok_or_else(|| ImportError::data(path, at(b), format!("'{}' is not a fraction of a second in [0, 1) (FRACSEC / TIME_BASE)", &rec[b])))?;
                (soc, fr)
            }
        };
        if start.is_none() && !matches!(time, TimeCols::Relative(_)) {
            start = Some(super::format_iso(sec, frac));
        }
        let mut bad = None;
        if let Some(k) = stat {
            let s = rec[k].trim();
            let v = if let Some(h) = s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
                u32::from_str_radix(h, 16).ok()
            } else {
                s.parse::<u32>().ok()
            }
            .ok_or_else(|| {
                ImportError::data(
                    path,
                    at(k),
                    format!("STAT '{s}' is not a number (decimal or 0x hex)"),
                )
            })?;
            bad = match (v >> 14) & 3 {
                0 => None,
                1 => Some(format!("STAT {v:#06x}: PMU error")),
                2 => Some(format!("STAT {v:#06x}: PMU in test mode")),
                _ => Some(format!("STAT {v:#06x}: PMU error, data not to be used")),
            };
            unsynced += usize::from(v & 0x2000 != 0);
            modified += usize::from(v & 0x0200 != 0);
        }
        let mut vals = [f64::NAN; 9];
        for (s, slot) in a.slots.iter().enumerate() {
            if let Some((k, _, _)) = slot {
                let f = rec[*k].trim();
                vals[s] = if f.is_empty() || f.eq_ignore_ascii_case("nan") {
                    f64::NAN
                } else {
                    f.parse::<f64>().map_err(|_| {
                        ImportError::data(path, at(*k), format!("'{f}' is not a number"))
                    })?
                };
            }
        }
        samples.push(RawSample {
            sec,
            frac,
            vals,
            at: format!("line {line}"),
            bad,
        });
    }
    if unsynced > 0 {
        warnings.push(format!(
            "{unsynced} sample(s) with STAT bit 13 set: PMU not synchronised to UTC (kept)"
        ));
    }
    if modified > 0 {
        warnings.push(format!("{modified} sample(s) with STAT bit 9 set: data modified by a post-processing device (kept)"));
    }
    finish(
        path,
        "C37.118 CSV".into(),
        start,
        &a,
        samples,
        opts,
        warnings,
    )
}

//! COMTRADE (IEEE C37.111-1991/1999/2013): a `.cfg` describing the channels and a `.dat` of
//! samples, ASCII, BINARY (16-bit), BINARY32 or FLOAT32.
//!
//! The recording must hold phasor channels (magnitude and angle, or real and imaginary parts,
//! as a PMU or a recorder's phasor output writes them), named as in [`super`]; the unit comes
//! from the channel's unit field `uu` unless the name says it. Each value is `a·x + b`, taken to
//! the primary side when the channel's PS flag is `S` (× primary/secondary). Time comes from the
//! sampling-rate table (sample number over rate; a skipped sample number is a gap) or, when the
//! file has no rates (`nrates = 0` or rate 0), from each sample's time stamp × `timemult` µs.
//! Missing-data codes (an empty ASCII field or 99999, 0x8000 in BINARY, 0x80000000 in BINARY32,
//! NaN in FLOAT32) make dropouts. `.cff` (2013 single file) is not read.
//!
//! Errors name the `.cfg` and its line, or the `.dat` and its line (ASCII) or record (binary).

use std::path::{Path, PathBuf};

use super::{
    assign, days_from_civil, finish, parse_hms, ImportError, ImportOptions, ImportReport, RawSample,
};
use crate::event::Event;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Fmt {
    Ascii,
    Binary,
    Binary32,
    Float32,
}

#[derive(Debug, Clone)]
struct Analog {
    id: String,
    unit: String,
    a: f64,
    b: f64,
    /// Factor to the primary side.
    to_primary: f64,
}

struct Cfg {
    rev: u32,
    analog: Vec<Analog>,
    n_digital: usize,
    rates: Vec<(f64, u64)>,
    start: (i64, f64),
    fmt: Fmt,
    timemult: f64,
}

fn parse_cfg(text: &str, path: &Path) -> Result<Cfg, ImportError> {
    let lines: Vec<&str> = text.lines().map(|l| l.trim_end_matches('\r')).collect();
    let mut k = 0usize;
    let mut next = |what: &str| -> Result<(usize, Vec<String>), ImportError> {
        let line = lines.get(k).ok_or_else(|| {
            ImportError::data(
                path,
                Some(format!("line {}", k + 1)),
                format!("the file ends where {what} is expected"),
            )
        })?;
        k += 1;
        Ok((k, line.split(',').map(|f| f.trim().to_string()).collect()))
    };
    let err = |l: usize, m: String| ImportError::data(path, Some(format!("line {l}")), m);
    let num = |l: usize, f: &str, what: &str| -> Result<f64, ImportError> {
        f.parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| err(l, format!("{what} '{f}' is not a number")))
    };
    let (_, first) = next("station_name,rec_dev_id,rev_year")?;
    let rev = match first.get(2).map(|s| s.as_str()) {
        None | Some("") => 1991,
        Some(y) => y
            .parse()
            .map_err(|_| err(1, format!("revision year '{y}' is not 1991, 1999 or 2013")))?,
    };
    if ![1991, 1999, 2013].contains(&rev) {
        return Err(err(
            1,
            format!("revision year {rev} is not 1991, 1999 or 2013"),
        ));
    }
    let (l, counts) = next("TT,##A,##D")?;
    let count = |f: Option<&String>, suffix: char| -> Option<usize> {
        f?.trim()
            .strip_suffix(suffix)
            .or_else(|| f?.trim().strip_suffix(suffix.to_ascii_lowercase()))?
            .parse()
            .ok()
    };
    let (na, nd) = match (count(counts.get(1), 'A'), count(counts.get(2), 'D')) {
        (Some(a), Some(d)) => (a, d),
        _ => return Err(err(l, format!("'{}' is not TT,##A,##D", counts.join(",")))),
    };
    let total: usize = counts[0]
        .parse()
        .map_err(|_| err(l, format!("channel total '{}' is not a number", counts[0])))?;
    if total != na + nd {
        return Err(err(
            l,
            format!("{total} channels, but {na} analog + {nd} digital"),
        ));
    }
    let mut analog = vec![];
    for _ in 0..na {
        let (l, f) = next("an analog channel line")?;
        let need = if rev == 1991 { 10 } else { 13 };
        if f.len() < need {
            return Err(err(l, format!("an analog channel line has {need} fields (An,ch_id,ph,ccbm,uu,a,b,skew,min,max{}), found {}", if rev == 1991 { "" } else { ",primary,secondary,PS" }, f.len())));
        }
        let a = num(l, &f[5], "multiplier a")?;
        let b = num(l, &f[6], "offset b")?;
        let to_primary = if rev != 1991 && f[12].eq_ignore_ascii_case("s") {
            let (p, s) = (num(l, &f[10], "primary")?, num(l, &f[11], "secondary")?);
            if s == 0.0 {
                return Err(err(l, "secondary ratio 0".into()));
            }
            p / s
        } else {
            1.0
        };
        analog.push(Analog {
            id: f[1].clone(),
            unit: f[4].clone(),
            a,
            b,
            to_primary,
        });
    }
    for _ in 0..nd {
        next("a digital channel line")?;
    }
    next("the line frequency")?;
    let (l, nr) = next("nrates")?;
    let nrates: usize = nr[0]
        .parse()
        .map_err(|_| err(l, format!("nrates '{}' is not a number", nr[0])))?;
    let mut rates = vec![];
    for _ in 0..nrates.max(1) {
        let (l, f) = next("samp,endsamp")?;
        if f.len() < 2 {
            return Err(err(l, "expected samp,endsamp".into()));
        }
        let samp = num(l, &f[0], "sampling rate")?;
        let end: u64 = f[1].parse().map_err(|_| {
            err(
                l,
                format!("last sample number '{}' is not a whole number", f[1]),
            )
        })?;
        rates.push((samp, end));
    }
    let (l, st) = next("the start date and time")?;
    let start = parse_stamp(&st, rev).ok_or_else(|| {
        err(
            l,
            format!(
                "'{}' is not {},hh:mm:ss.ssssss",
                st.join(","),
                if rev == 1991 {
                    "mm/dd/yy"
                } else {
                    "dd/mm/yyyy"
                }
            ),
        )
    })?;
    next("the trigger date and time")?;
    let (l, ft) = next("the file type")?;
    let fmt = match ft[0].to_ascii_uppercase().as_str() {
        "ASCII" => Fmt::Ascii,
        "BINARY" => Fmt::Binary,
        "BINARY32" => Fmt::Binary32,
        "FLOAT32" => Fmt::Float32,
        o => {
            return Err(err(
                l,
                format!("file type '{o}' is not ASCII, BINARY, BINARY32 or FLOAT32"),
            ))
        }
    };
    let timemult = match lines.get(k) {
        Some(t) if rev != 1991 && !t.trim().is_empty() => {
            num(k + 1, t.split(',').next().unwrap_or("").trim(), "timemult")?
        }
        _ => 1.0,
    };
    Ok(Cfg {
        rev,
        analog,
        n_digital: nd,
        rates,
        start,
        fmt,
        timemult,
    })
}

fn parse_stamp(f: &[String], rev: u32) -> Option<(i64, f64)> {
    let d: Vec<i64> = f
        .first()?
        .split('/')
        .map(|x| x.trim().parse().ok())
        .collect::<Option<_>>()?;
    if d.len() != 3 {
        return None;
    }
    let (day, month, mut year) = if rev == 1991 {
        (d[1], d[0], d[2])
    } else {
        (d[0], d[1], d[2])
    };
    if year < 100 {
        year += if year >= 70 { 1900 } else { 2000 };
    }
    if !(1..=12).contains(&month) || !(1..=31).contains(&day) {
        return None;
    }
    let (sod, frac) = parse_hms(f.get(1)?)?;
    Some((days_from_civil(year, month, day) * 86400 + sod, frac))
}

/// Reads a COMTRADE recording (`.cfg` path; the `.dat` beside it) into an event.
pub fn import(cfg_path: &Path, opts: &ImportOptions) -> Result<(Event, ImportReport), ImportError> {
    let bytes = std::fs::read(cfg_path).map_err(|source| ImportError::Io {
        path: cfg_path.into(),
        source,
    })?;
    let cfg = parse_cfg(&String::from_utf8_lossy(&bytes), cfg_path)?;
    let dat_path: PathBuf = {
        let lower = cfg_path.with_extension("dat");
        let upper = cfg_path.with_extension("DAT");
        if !lower.is_file() && upper.is_file() {
            upper
        } else {
            lower
        }
    };
    let chans: Vec<(usize, String, Option<String>)> = cfg
        .analog
        .iter()
        .enumerate()
        .map(|(k, a)| (k, a.id.clone(), Some(a.unit.clone())))
        .collect();
    let mut ignored = vec![];
    let asg = assign(&chans, &opts.map, &mut ignored)
        .map_err(|m| ImportError::data(cfg_path, None, m))?;
    let mut warnings = vec![];
    if !ignored.is_empty() {
        warnings.push(format!("analog channels not used: {}", ignored.join(", ")));
    }
    let data = std::fs::read(&dat_path).map_err(|source| ImportError::Io {
        path: dat_path.clone(),
        source,
    })?;
    let rows = match cfg.fmt {
        Fmt::Ascii => read_ascii(&data, &dat_path, &cfg)?,
        _ => read_binary(&data, &dat_path, &cfg)?,
    };
    // The rate table's last sample number is the number of samples the .cfg declares (also
    // with no rates: `0,endsamp`). A .dat cut short (a copy that stopped, a recorder that lost
    // its end) holds fewer: said, never read in silence.
    let declared = cfg.rates.last().map(|r| r.1 as usize).filter(|n| *n > 0);
    let use_rates =
        cfg.rates.iter().all(|r| r.0 > 0.0) && !(cfg.rates.len() == 1 && cfg.rates[0].0 == 0.0);
    let mut samples = vec![];
    for (n, ts, vals, at, missing) in rows {
        let t = if use_rates {
            time_of(n, &cfg.rates).ok_or_else(|| {
                ImportError::data(
                    &dat_path,
                    Some(at.clone()),
                    format!("sample number {n} is beyond the last in the .cfg's rate table"),
                )
            })?
        } else {
            let ts = ts.ok_or_else(|| {
                ImportError::data(
                    &dat_path,
                    Some(at.clone()),
                    "no time stamp, and the .cfg gives no sampling rate",
                )
            })?;
            ts * cfg.timemult * 1e-6
        };
        let mut v = [f64::NAN; 9];
        let mut bad = None;
        for (s, slot) in asg.slots.iter().enumerate() {
            if let Some((k, _, name)) = slot {
                if missing[*k] {
                    bad = Some(format!("missing-data code in channel {name}"));
                }
                let an = &cfg.analog[*k];
                v[s] = (an.a * vals[*k] + an.b) * an.to_primary;
            }
        }
        samples.push(RawSample {
            sec: cfg.start.0,
            frac: cfg.start.1 + t,
            vals: v,
            at,
            bad,
        });
    }
    let fmt = match cfg.fmt {
        Fmt::Ascii => "ASCII",
        Fmt::Binary => "BINARY",
        Fmt::Binary32 => "BINARY32",
        Fmt::Float32 => "FLOAT32",
    };
    let start = Some(super::format_iso(cfg.start.0, cfg.start.1));
    let read = samples.len();
    let last_s = samples.last().map_or(0.0, |s| s.frac - cfg.start.1);
    let note = declared.and_then(|d| super::truncation_note(&dat_path, cfg_path, read, d, last_s));
    if let Some(n) = &note {
        if opts.refuse_truncated {
            let prefix = format!("{} ", dat_path.display());
            return Err(ImportError::data(
                &dat_path,
                None,
                format!(
                    "{}; refused (refuse_truncated, --refuse-truncated)",
                    n.strip_prefix(&prefix).unwrap_or(n)
                ),
            ));
        }
        warnings.push(n.clone());
    }
    let (mut event, mut report) = finish(
        cfg_path,
        format!("COMTRADE {} {fmt}", cfg.rev),
        start,
        &asg,
        samples,
        opts,
        warnings,
    )?;
    report.samples_declared = declared;
    event.import_notes.extend(note);
    Ok((event, report))
}

/// Time of sample number `n` (1-based) from the rate table, s after the first sample.
fn time_of(n: u64, rates: &[(f64, u64)]) -> Option<f64> {
    let (mut t, mut prev_end) = (0.0, 1u64);
    for &(rate, end) in rates {
        if n <= end {
            return Some(t + (n.saturating_sub(prev_end)) as f64 / rate);
        }
        t += (end - prev_end) as f64 / rate;
        prev_end = end;
    }
    None
}

/// (sample number, time stamp, analog raw values, location, missing flags).
type Row = (u64, Option<f64>, Vec<f64>, String, Vec<bool>);

fn read_ascii(data: &[u8], path: &Path, cfg: &Cfg) -> Result<Vec<Row>, ImportError> {
    let text = String::from_utf8_lossy(data);
    let na = cfg.analog.len();
    let mut rows = vec![];
    for (k, line) in text.lines().enumerate() {
        let l = k + 1;
        let line = line.trim_end_matches('\r');
        if line.trim().is_empty() || line.trim() == "\u{1a}" {
            continue;
        }
        let at = format!("line {l}");
        let err = |m: String| ImportError::data(path, Some(at.clone()), m);
        let f: Vec<&str> = line.split(',').map(|s| s.trim()).collect();
        if f.len() != 2 + na + cfg.n_digital {
            return Err(err(format!(
                "{} fields; the .cfg's channels make {} (n, timestamp, {na} analog, {} digital)",
                f.len(),
                2 + na + cfg.n_digital,
                cfg.n_digital
            )));
        }
        let n: u64 = f[0]
            .parse()
            .map_err(|_| err(format!("sample number '{}' is not a whole number", f[0])))?;
        let ts = if f[1].is_empty() {
            None
        } else {
            Some(
                f[1].parse::<f64>()
                    .map_err(|_| err(format!("time stamp '{}' is not a number", f[1])))?,
            )
        };
        let mut vals = vec![0.0; na];
        let mut missing = vec![false; na];
        for j in 0..na {
            let s = f[2 + j];
            if s.is_empty() || (cfg.rev == 1999 && s == "99999") {
                missing[j] = true;
                vals[j] = f64::NAN;
            } else {
                vals[j] = s
                    .parse::<f64>()
                    .ok()
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| {
                        err(format!(
                            "channel {} ({}): '{s}' is not a number",
                            j + 1,
                            cfg.analog[j].id
                        ))
                    })?;
            }
        }
        rows.push((n, ts, vals, at, missing));
    }
    Ok(rows)
}

fn read_binary(data: &[u8], path: &Path, cfg: &Cfg) -> Result<Vec<Row>, ImportError> {
    let na = cfg.analog.len();
    let width = if cfg.fmt == Fmt::Binary { 2 } else { 4 };
    let size = 8 + na * width + 2 * cfg.n_digital.div_ceil(16);
    if !data.len().is_multiple_of(size) {
        return Err(ImportError::data(
            path,
            Some(format!("record {}", data.len() / size + 1)),
            format!("{} bytes is not a whole number of {size}-byte records: the last record is truncated", data.len()),
        ));
    }
    let u32_at = |b: &[u8], o: usize| u32::from_le_bytes([b[o], b[o + 1], b[o + 2], b[o + 3]]);
    let mut rows = vec![];
    for (k, r) in data.chunks_exact(size).enumerate() {
        let n = u32_at(r, 0) as u64;
        let ts_raw = u32_at(r, 4);
        let ts = if ts_raw == u32::MAX {
            None
        } else {
            Some(ts_raw as f64)
        };
        let mut vals = vec![0.0; na];
        let mut missing = vec![false; na];
        for j in 0..na {
            let o = 8 + j * width;
            let (v, miss) = match cfg.fmt {
                Fmt::Binary => {
                    let x = i16::from_le_bytes([r[o], r[o + 1]]);
                    (x as f64, x == i16::MIN)
                }
                Fmt::Binary32 => {
                    let x = u32_at(r, o) as i32;
                    (x as f64, x == i32::MIN)
                }
                _ => {
                    let x = f32::from_le_bytes([r[o], r[o + 1], r[o + 2], r[o + 3]]);
                    (x as f64, !x.is_finite())
                }
            };
            vals[j] = if miss { f64::NAN } else { v };
            missing[j] = miss;
        }
        rows.push((
            n,
            ts,
            vals,
            format!("record {} (byte {})", k + 1, k * size),
            missing,
        ));
    }
    Ok(rows)
}

//! Time stamps: ISO 8601 parsing and formatting (UTC epoch seconds and a fraction), civil
//! dates and `hh:mm:ss.f` times of day.

/// The start stamp moved on by `dt` seconds when the first samples were dropped (only noted).
pub(super) fn shift_iso(s: &str, dt: f64) -> String {
    if dt == 0.0 {
        s.to_string()
    } else {
        format!("{s} + {dt:.6} s")
    }
}

/// Days since 1970-01-01 of a civil date (proleptic Gregorian).
pub(crate) fn days_from_civil(y: i64, m: i64, d: i64) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = if y >= 0 { y } else { y - 399 } / 400;
    let yoe = y - era * 400;
    let mp = (m + 9) % 12;
    let doy = (153 * mp + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146097 + doe - 719468
}

/// Parses `hh:mm:ss[.frac]` into (seconds of day, fraction).
pub(crate) fn parse_hms(s: &str) -> Option<(i64, f64)> {
    let mut it = s.split(':');
    let h: i64 = it.next()?.trim().parse().ok()?;
    let m: i64 = it.next()?.trim().parse().ok()?;
    let sec = it.next()?.trim();
    if it.next().is_some() || !(0..24).contains(&h) || !(0..60).contains(&m) {
        return None;
    }
    let (whole, frac) = match sec.split_once('.') {
        Some((w, f)) => (w, f),
        None => (sec, ""),
    };
    let w: i64 = whole.parse().ok()?;
    if !(0..=60).contains(&w) || !frac.chars().all(|c| c.is_ascii_digit()) {
        return None;
    }
    let f = if frac.is_empty() {
        0.0
    } else {
        format!("0.{frac}").parse().ok()?
    };
    Some((h * 3600 + m * 60 + w, f))
}

/// Parses an ISO 8601 time stamp `YYYY-MM-DD[T ]hh:mm:ss[.frac][Z|±hh:mm]` (a `/` date
/// separator is accepted) into (seconds since the Unix epoch, UTC; fraction).
pub fn parse_iso(s: &str) -> Option<(i64, f64)> {
    let s = s.trim();
    let (date, rest) = s.split_once(['T', ' '])?;
    let mut d = date.split(['-', '/']);
    let y: i64 = d.next()?.parse().ok()?;
    let mo: i64 = d.next()?.parse().ok()?;
    let da: i64 = d.next()?.parse().ok()?;
    if d.next().is_some() || !(1..=12).contains(&mo) || !(1..=31).contains(&da) {
        return None;
    }
    let rest = rest.trim();
    let (time, offset) = if let Some(t) = rest.strip_suffix(['Z', 'z']) {
        (t, 0)
    } else if let Some(k) = rest.rfind(['+', '-']) {
        let (t, o) = rest.split_at(k);
        let sign = if o.starts_with('-') { -1 } else { 1 };
        let (oh, om) = o[1..].split_once(':').unwrap_or((&o[1..], "0"));
        (
            t,
            sign * (oh.parse::<i64>().ok()? * 3600 + om.parse::<i64>().ok()? * 60),
        )
    } else {
        (rest, 0)
    };
    let (sod, frac) = parse_hms(time)?;
    Some((days_from_civil(y, mo, da) * 86400 + sod - offset, frac))
}

/// Formats epoch seconds as ISO 8601 UTC with microseconds.
pub fn format_iso(sec: i64, frac: f64) -> String {
    let days = sec.div_euclid(86400);
    let sod = sec.rem_euclid(86400);
    // civil_from_days
    let z = days + 719468;
    let era = if z >= 0 { z } else { z - 146096 } / 146097;
    let doe = z - era * 146097;
    let yoe = (doe - doe / 1460 + doe / 36524 - doe / 146096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + if m <= 2 { 1 } else { 0 };
    let us = (frac * 1e6).round() as i64;
    let (sod, us) = if us >= 1_000_000 {
        (sod + 1, us - 1_000_000)
    } else {
        (sod, us)
    };
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}.{us:06}Z",
        sod / 3600,
        sod % 3600 / 60,
        sod % 60
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iso_time_stamps_round_trip_and_match_epoch_seconds() {
        assert_eq!(parse_iso("1970-01-01T00:00:00Z"), Some((0, 0.0)));
        let (s, f) = parse_iso("2021-03-04 05:06:07.25+01:00").unwrap();
        assert_eq!(s, 1614834367 - 3600); // 04:06:07 UTC
        assert_eq!(f, 0.25);
        assert_eq!(format_iso(s, f), "2021-03-04T04:06:07.250000Z");
        assert_eq!(parse_iso("2021-13-04T00:00:00"), None);
    }
}

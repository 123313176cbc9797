//! The measurement CSV: reading it ([`read_csv`]) and writing it ([`Event::write_csv`],
//! [`format_g17`]), and the record validation shared by CSV and in-memory records (sample
//! count, finite values, strictly increasing time, unit sanity checks).

use std::fs;
use std::io::{BufWriter, Write};
use std::path::Path;

use super::spec::check_nominal_hz;
use super::{
    unwrap_angles, Channel, Event, EventError, Location, Record, ACCEPTED_COLUMNS, FIELD_LIMIT_PU,
    FREQ_TOLERANCE, MIN_SAMPLES, PQ_LIMIT_PU, V_MEDIAN_RANGE_PU,
};

impl Event {
    /// Writes the playback record as a canonical CSV: header
    /// `time_s,v_mag_pu,v_ang_rad,p_pu,q_pu` (`time_s,v_pu,p_pu,q_pu` for a record without an
    /// angle) followed by `freq_hz`, `efd_pu`, `ifd_pu` for the optional channels present.
    /// Numbers are written with 17 significant digits (like C's `%.17g`), which reproduces every
    /// `f64` exactly when read back; the voltage is written as the record holds it (|V| and the
    /// unwrapped angle in radians), so reading the file back gives the record bit for bit: an
    /// event written and read plays back exactly as the event in memory (an import, a synthetic
    /// event).
    pub fn write_csv(&self, path: &Path) -> Result<(), EventError> {
        let io_err = |source| EventError::Io {
            path: path.to_path_buf(),
            action: "cannot write the CSV file".into(),
            source,
        };
        let file = fs::File::create(path).map_err(io_err)?;
        let mut w = BufWriter::new(file);
        let rec = &self.record;
        let mut cols: Vec<(&str, &[f64])> = if self.has_angle() {
            vec![
                ("time_s", &rec.time_s),
                ("v_mag_pu", &rec.v_mag_pu),
                ("v_ang_rad", &rec.v_ang_rad),
            ]
        } else {
            // A record without an angle keeps |V| alone (its event declares the channels).
            vec![("time_s", &rec.time_s), ("v_pu", &rec.v_mag_pu)]
        };
        cols.extend([("p_pu", rec.p_pu.as_slice()), ("q_pu", rec.q_pu.as_slice())]);
        if let Some(f) = &rec.freq_hz {
            cols.push(("freq_hz", f));
        }
        if let Some(e) = &rec.efd_pu {
            cols.push(("efd_pu", e));
        }
        if let Some(i) = &rec.ifd_pu {
            cols.push(("ifd_pu", i));
        }
        let header: Vec<&str> = cols.iter().map(|c| c.0).collect();
        writeln!(w, "{}", header.join(",")).map_err(io_err)?;
        let mut line = String::new();
        for i in 0..rec.len() {
            line.clear();
            for (j, (_, v)) in cols.iter().enumerate() {
                if j > 0 {
                    line.push(',');
                }
                line.push_str(&format_g17(v[i]));
            }
            writeln!(w, "{line}").map_err(io_err)?;
        }
        w.flush().map_err(io_err)?;
        Ok(())
    }
}

/// Formats `x` with 17 significant digits in the style of C's `%.17g` (trailing zeros removed,
/// exponent form for exponents < -4 or >= 17). Parsing the result gives back `x` exactly.
pub fn format_g17(x: f64) -> String {
    if !x.is_finite() {
        return format!("{x}");
    }
    if x == 0.0 {
        return if x.is_sign_negative() {
            "-0".into()
        } else {
            "0".into()
        };
    }
    let sci = format!("{x:.16e}"); // d.dddddddddddddddde±x
    let (mant, exp) = sci.split_once('e').expect("exponent");
    let exp: i32 = exp.parse().expect("integer exponent");
    let trim = |s: &str| -> String {
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s.to_string()
        }
    };
    if !(-4..17).contains(&exp) {
        let sign = if exp < 0 { '-' } else { '+' };
        format!("{}e{}{:02}", trim(mant), sign, exp.abs())
    } else {
        let decimals = (16 - exp) as usize;
        trim(&format!("{x:.decimals$}"))
    }
}

// ---------------------------------------------------------------------------------------------
// Record validation (shared by CSV and in-memory records)
// ---------------------------------------------------------------------------------------------

/// Names of the data columns as the user knows them (CSV header names or `Record` fields).
pub(super) struct ColumnLabels {
    voltage: &'static str,
    magnitude: &'static str,
}

impl ColumnLabels {
    pub(super) fn in_memory() -> Self {
        ColumnLabels {
            voltage: "v_mag_pu",
            magnitude: "v_mag_pu",
        }
    }
}

pub(super) fn check_record_shape(src: &Path, rec: &Record) -> Result<(), EventError> {
    let n = rec.time_s.len();
    let mut fields: Vec<(&str, usize)> = vec![
        ("v_mag_pu", rec.v_mag_pu.len()),
        ("v_ang_rad", rec.v_ang_rad.len()),
        ("p_pu", rec.p_pu.len()),
        ("q_pu", rec.q_pu.len()),
    ];
    if let Some(v) = &rec.freq_hz {
        fields.push(("freq_hz", v.len()));
    }
    if let Some(v) = &rec.efd_pu {
        fields.push(("efd_pu", v.len()));
    }
    if let Some(v) = &rec.ifd_pu {
        fields.push(("ifd_pu", v.len()));
    }
    for (name, len) in fields {
        if len != n {
            return Err(EventError::RecordShape {
                path: src.to_path_buf(),
                message: format!("{name} has {len} samples but time_s has {n}"),
            });
        }
    }
    Ok(())
}

/// Validates a record whose vectors have equal lengths: sample count, finite values,
/// |V| >= 0, strictly increasing time and unit sanity.
pub(super) fn validate_record(
    src: &Path,
    rec: &Record,
    nominal_hz: f64,
    labels: &ColumnLabels,
    loc: &dyn Fn(usize) -> Location,
) -> Result<(), EventError> {
    if rec.len() < MIN_SAMPLES {
        return Err(EventError::TooFewSamples {
            path: src.to_path_buf(),
            what: "the record".into(),
            count: rec.len(),
            min: MIN_SAMPLES,
        });
    }
    let mut channels: Vec<(&str, &[f64])> = vec![
        ("time_s", &rec.time_s),
        (labels.magnitude, &rec.v_mag_pu),
        ("v_ang_rad", &rec.v_ang_rad),
        ("p_pu", &rec.p_pu),
        ("q_pu", &rec.q_pu),
    ];
    if let Some(v) = &rec.freq_hz {
        channels.push(("freq_hz", v));
    }
    if let Some(v) = &rec.efd_pu {
        channels.push(("efd_pu", v));
    }
    if let Some(v) = &rec.ifd_pu {
        channels.push(("ifd_pu", v));
    }
    for (name, v) in &channels {
        if let Some(i) = v.iter().position(|x| !x.is_finite()) {
            return Err(EventError::BadNumber {
                path: src.to_path_buf(),
                at: loc(i),
                column: name.to_string(),
                text: v[i].to_string(),
                reason: "is not a finite number",
            });
        }
    }
    if let Some(i) = rec.v_mag_pu.iter().position(|&m| m < 0.0) {
        return Err(EventError::BadNumber {
            path: src.to_path_buf(),
            at: loc(i),
            column: labels.magnitude.to_string(),
            text: rec.v_mag_pu[i].to_string(),
            reason: "is negative; a voltage magnitude must be >= 0",
        });
    }
    for i in 1..rec.len() {
        if rec.time_s[i] <= rec.time_s[i - 1] {
            return Err(EventError::NonMonotonicTime {
                path: src.to_path_buf(),
                at: loc(i),
                prev_at: loc(i - 1),
                prev_time_s: rec.time_s[i - 1],
                time_s: rec.time_s[i],
            });
        }
    }

    // Units.
    let mut mags = rec.v_mag_pu.clone();
    mags.sort_by(f64::total_cmp);
    let n = mags.len();
    let median = if n % 2 == 1 {
        mags[n / 2]
    } else {
        0.5 * (mags[n / 2 - 1] + mags[n / 2])
    };
    let (vlo, vhi) = V_MEDIAN_RANGE_PU;
    if median > vhi {
        return Err(EventError::Units {
            path: src.to_path_buf(),
            column: labels.voltage.to_string(),
            at: None,
            message: format!(
                "median |V| = {median} is above {vhi}: the voltage looks like it is in kV or volts, \
                 not per unit; give it per unit of the rated terminal voltage"
            ),
        });
    }
    if median < vlo {
        return Err(EventError::Units {
            path: src.to_path_buf(),
            column: labels.voltage.to_string(),
            at: None,
            message: format!(
                "median |V| = {median} is below {vlo}: the voltage does not look like per unit \
                 of the rated terminal voltage (wrong base or units?); it must be per unit"
            ),
        });
    }
    for (name, v, what) in [("p_pu", &rec.p_pu, "MW"), ("q_pu", &rec.q_pu, "Mvar")] {
        if let Some((i, x)) = v
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
        {
            if x.abs() >= PQ_LIMIT_PU {
                return Err(EventError::Units {
                    path: src.to_path_buf(),
                    column: name.to_string(),
                    at: Some(loc(i)),
                    message: format!(
                        "|{name}| = {} is not below {PQ_LIMIT_PU} pu: this looks like {what}, not \
                         per unit; give it per unit on the system base ({what} / system_mva)",
                        x.abs()
                    ),
                });
            }
        }
    }
    for (name, col, what) in [
        ("efd_pu", &rec.efd_pu, "volts"),
        ("ifd_pu", &rec.ifd_pu, "amperes"),
    ] {
        let Some(v) = col else { continue };
        let mut a: Vec<f64> = v.iter().map(|x| x.abs()).collect();
        a.sort_by(f64::total_cmp);
        let med = a[a.len() / 2];
        if med > FIELD_LIMIT_PU {
            return Err(EventError::Units {
                path: src.to_path_buf(),
                column: name.to_string(),
                at: None,
                message: format!(
                    "median |{name}| = {med} is above {FIELD_LIMIT_PU} pu, hundreds of times a field's \
                     no-load value (about 1 pu): this looks like {what}, not per unit; give it per \
                     unit of the machine's field base (the air-gap-line base: E_fd that gives 1 pu \
                     open-circuit voltage, X_ad·I_fd)"
                ),
            });
        }
    }
    if let Some(f) = &rec.freq_hz {
        // Rounded to µHz for the message (60 * 1.1 is 66.00000000000001 in f64).
        let lo = (nominal_hz * (1.0 - FREQ_TOLERANCE) * 1e6).round() / 1e6;
        let hi = (nominal_hz * (1.0 + FREQ_TOLERANCE) * 1e6).round() / 1e6;
        if let Some(i) = f.iter().position(|&x| x < lo || x > hi) {
            return Err(EventError::Units {
                path: src.to_path_buf(),
                column: "freq_hz".into(),
                at: Some(loc(i)),
                message: format!(
                    "{} Hz lies outside {lo}..{hi} Hz (nominal_hz = {nominal_hz} ± {} %): freq_hz \
                     must be the absolute frequency in Hz (maybe it was given as a deviation or \
                     in per unit?)",
                    f[i],
                    FREQ_TOLERANCE * 100.0
                ),
            });
        }
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// CSV
// ---------------------------------------------------------------------------------------------

/// Reads an event CSV (format in the `event` module documentation) into a [`Record`] holding every
/// sample of the file, with |V| and the unwrapped angle computed from whichever voltage form is
/// present. `nominal_hz` (> 0) is needed for the `freq_hz` sanity check. The file must hold at
/// least [`MIN_SAMPLES`] samples.
pub fn read_csv(path: &Path, nominal_hz: f64) -> Result<Record, EventError> {
    read_csv_channels(path, nominal_hz, false).map(|(r, _)| r)
}

/// The channels a record holds (`has_angle`: whether its angle was recorded).
pub(super) fn record_channels(rec: &Record, has_angle: bool) -> Vec<Channel> {
    let mut c = vec![Channel::V];
    if has_angle {
        c.push(Channel::Angle);
    }
    c.extend([Channel::P, Channel::Q]);
    if rec.freq_hz.is_some() {
        c.push(Channel::Freq);
    }
    if rec.efd_pu.is_some() {
        c.push(Channel::Efd);
    }
    if rec.ifd_pu.is_some() {
        c.push(Channel::Ifd);
    }
    c
}

/// [`read_csv`]; with `magnitude_only_ok` a `v_pu` column without `angle_deg` is a record
/// without an angle (zeros in `v_ang_rad`; the event must declare it). Returns the record and
/// whether it holds an angle.
pub(crate) fn read_csv_channels(
    path: &Path,
    nominal_hz: f64,
    magnitude_only_ok: bool,
) -> Result<(Record, bool), EventError> {
    check_nominal_hz(path, nominal_hz)?;
    let file = fs::File::open(path).map_err(|source| EventError::Io {
        path: path.to_path_buf(),
        action: "cannot open the CSV file".into(),
        source,
    })?;
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(true)
        .flexible(true)
        .trim(csv::Trim::All)
        .from_reader(std::io::BufReader::new(file));

    let csv_err = |e: csv::Error| -> EventError {
        let line = e.position().map(|p| p.line() as usize);
        match e.into_kind() {
            csv::ErrorKind::Io(source) => EventError::Io {
                path: path.to_path_buf(),
                action: "cannot read the CSV file".into(),
                source,
            },
            other => EventError::CsvStructure {
                path: path.to_path_buf(),
                line,
                message: csv_kind_message(&other),
            },
        }
    };

    let headers = rdr.headers().map_err(csv_err)?.clone();
    if headers.is_empty() || (headers.len() == 1 && headers[0].is_empty()) {
        return Err(EventError::CsvStructure {
            path: path.to_path_buf(),
            line: Some(1),
            message: format!(
                "the file is empty; expected a header line with the columns {}",
                ACCEPTED_COLUMNS.join(", ")
            ),
        });
    }

    // Map columns (index into ACCEPTED_COLUMNS -> index in the record).
    let mut col: [Option<usize>; ACCEPTED_COLUMNS.len()] = [None; ACCEPTED_COLUMNS.len()];
    for (j, h) in headers.iter().enumerate() {
        match ACCEPTED_COLUMNS.iter().position(|c| *c == h) {
            None => {
                return Err(EventError::UnknownColumn {
                    path: path.to_path_buf(),
                    column: h.to_string(),
                })
            }
            Some(k) => {
                if col[k].is_some() {
                    return Err(EventError::DuplicateColumn {
                        path: path.to_path_buf(),
                        column: h.to_string(),
                    });
                }
                col[k] = Some(j);
            }
        }
    }
    let idx = |name: &str| col[ACCEPTED_COLUMNS.iter().position(|c| *c == name).unwrap()];
    let missing = |column: &str, detail: &str| EventError::MissingColumn {
        path: path.to_path_buf(),
        column: column.to_string(),
        detail: detail.to_string(),
    };
    for req in ["time_s", "p_pu", "q_pu"] {
        if idx(req).is_none() {
            return Err(missing(req, "(required)"));
        }
    }
    let (re, im, mag_deg, ang_deg, mag_rad, ang_rad) = (
        idx("v_re_pu"),
        idx("v_im_pu"),
        idx("v_pu"),
        idx("angle_deg"),
        idx("v_mag_pu"),
        idx("v_ang_rad"),
    );
    let rectangular = re.is_some() || im.is_some();
    let polar_deg = mag_deg.is_some() || ang_deg.is_some();
    let polar_rad = mag_rad.is_some() || ang_rad.is_some();
    if [rectangular, polar_deg, polar_rad]
        .iter()
        .filter(|f| **f)
        .count()
        > 1
    {
        return Err(EventError::ConflictingColumns {
            path: path.to_path_buf(),
            message: "more than one voltage form is present (v_re_pu/v_im_pu, v_pu/angle_deg, \
                      v_mag_pu/v_ang_rad); give exactly one of them"
                .into(),
        });
    }
    const VOLTAGE_HINT: &str = "(the voltage is given as v_re_pu and v_im_pu, as v_pu and \
                                angle_deg, or as v_mag_pu and v_ang_rad; a record without an \
                                angle gives v_pu alone and declares its channels in the event \
                                file, e.g. channels = [\"v\", \"p\", \"q\", \"efd\"])";
    let polar = polar_deg || polar_rad;
    let (mag, ang) = if polar_rad {
        (mag_rad, ang_rad)
    } else {
        (mag_deg, ang_deg)
    };
    let (va, vb, labels) = if polar_rad {
        match (mag, ang) {
            (Some(a), Some(b)) => (
                a,
                Some(b),
                ColumnLabels {
                    voltage: "v_mag_pu",
                    magnitude: "v_mag_pu",
                },
            ),
            (None, _) => return Err(missing("v_mag_pu", VOLTAGE_HINT)),
            (_, None) => return Err(missing("v_ang_rad", VOLTAGE_HINT)),
        }
    } else if polar {
        match (mag, ang) {
            (Some(a), Some(b)) => (
                a,
                Some(b),
                ColumnLabels {
                    voltage: "v_pu",
                    magnitude: "v_pu",
                },
            ),
            (Some(a), None) if magnitude_only_ok => (
                a,
                None,
                ColumnLabels {
                    voltage: "v_pu",
                    magnitude: "v_pu",
                },
            ),
            (None, _) => return Err(missing("v_pu", VOLTAGE_HINT)),
            (_, None) => return Err(missing("angle_deg", VOLTAGE_HINT)),
        }
    } else {
        match (re, im) {
            (Some(a), Some(b)) => (
                a,
                Some(b),
                ColumnLabels {
                    voltage: "v_re_pu/v_im_pu",
                    magnitude: "|V| from v_re_pu/v_im_pu",
                },
            ),
            (None, _) => return Err(missing("v_re_pu", VOLTAGE_HINT)),
            (_, None) => return Err(missing("v_im_pu", VOLTAGE_HINT)),
        }
    };
    let (t_i, p_i, q_i) = (
        idx("time_s").unwrap(),
        idx("p_pu").unwrap(),
        idx("q_pu").unwrap(),
    );
    let (f_i, e_i, i_i) = (idx("freq_hz"), idx("efd_pu"), idx("ifd_pu"));

    let mut lines: Vec<usize> = Vec::new();
    let mut time_s = Vec::new();
    let mut va_v = Vec::new();
    let mut vb_v = Vec::new();
    let mut p = Vec::new();
    let mut q = Vec::new();
    let mut fr = f_i.map(|_| Vec::new());
    let mut efd = e_i.map(|_| Vec::new());
    let mut ifd = i_i.map(|_| Vec::new());

    let mut row = csv::StringRecord::new();
    loop {
        match rdr.read_record(&mut row) {
            Ok(false) => break,
            Ok(true) => {}
            Err(e) => return Err(csv_err(e)),
        }
        let line = row.position().map(|p| p.line() as usize).unwrap_or(0);
        if row.len() != headers.len() {
            return Err(EventError::CsvStructure {
                path: path.to_path_buf(),
                line: Some(line),
                message: format!(
                    "expected {} fields (as in the header), found {}",
                    headers.len(),
                    row.len()
                ),
            });
        }
        let num = |j: usize| -> Result<f64, EventError> {
            let text = &row[j];
            match text.parse::<f64>() {
                Ok(x) if x.is_finite() => Ok(x),
                _ => Err(EventError::BadNumber {
                    path: path.to_path_buf(),
                    at: Location::Line(line),
                    column: headers[j].to_string(),
                    text: text.to_string(),
                    reason: if text.is_empty() {
                        "(empty field) is not a finite number"
                    } else {
                        "is not a finite number"
                    },
                }),
            }
        };
        time_s.push(num(t_i)?);
        va_v.push(num(va)?);
        if let Some(vb) = vb {
            vb_v.push(num(vb)?);
        }
        p.push(num(p_i)?);
        q.push(num(q_i)?);
        if let (Some(j), Some(v)) = (f_i, fr.as_mut()) {
            v.push(num(j)?);
        }
        if let (Some(j), Some(v)) = (e_i, efd.as_mut()) {
            v.push(num(j)?);
        }
        if let (Some(j), Some(v)) = (i_i, ifd.as_mut()) {
            v.push(num(j)?);
        }
        lines.push(line);
    }

    let has_angle = vb.is_some();
    let (v_mag_pu, raw_ang): (Vec<f64>, Vec<f64>) = if !has_angle {
        let n = va_v.len();
        (va_v, vec![0.0; n])
    } else if polar_rad {
        (va_v, vb_v)
    } else if polar {
        (va_v, vb_v.iter().map(|d| d.to_radians()).collect())
    } else {
        (
            va_v.iter().zip(&vb_v).map(|(r, i)| r.hypot(*i)).collect(),
            va_v.iter().zip(&vb_v).map(|(r, i)| i.atan2(*r)).collect(),
        )
    };
    let mut rec = Record {
        time_s,
        v_mag_pu,
        v_ang_rad: unwrap_angles(&raw_ang),
        p_pu: p,
        q_pu: q,
        freq_hz: fr,
        efd_pu: efd,
        ifd_pu: ifd,
    };
    rec.normalize_angle_start();
    validate_record(path, &rec, nominal_hz, &labels, &|i| {
        Location::Line(lines[i])
    })?;
    Ok((rec, has_angle))
}

fn csv_kind_message(kind: &csv::ErrorKind) -> String {
    match kind {
        csv::ErrorKind::Utf8 { err, .. } => format!("invalid UTF-8 text: {err}"),
        csv::ErrorKind::UnequalLengths {
            expected_len, len, ..
        } => format!("expected {expected_len} fields, found {len}"),
        other => format!("malformed CSV: {other:?}"),
    }
}

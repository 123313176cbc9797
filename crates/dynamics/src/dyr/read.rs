//! Reading a `.dyr`: the record syntax ([`parse_records`]) and the unit built from the
//! selected machine's records ([`read_dyr`], [`parse_dyr`]).

use std::path::Path;

use super::layout::{Icon, ZsorceX};
use super::{DyrBases, DyrError, DyrWarning};
use crate::block::Block;
use crate::registry::{self, ModelInfo, Role};
use crate::unit::Unit;

/// One record as written: its first line and its fields.
#[derive(Debug, Clone, PartialEq)]
pub struct RawRecord {
    pub line: usize,
    pub bus: i64,
    pub model: String,
    pub id: String,
    /// Fields after the identifier, as text, each with its line.
    pub data: Vec<(String, usize)>,
}

/// Splits `.dyr` text into records (syntax only: terminators, bus numbers, model names).
pub fn parse_records(text: &str, path: &Path) -> Result<Vec<RawRecord>, DyrError> {
    let syntax = |line: usize, msg: String| DyrError::Syntax {
        path: path.into(),
        line,
        msg,
    };
    let mut records = vec![];
    let mut fields: Vec<(String, usize)> = vec![];
    for (k, raw_line) in text.lines().enumerate() {
        let line = k + 1;
        let mut chars = raw_line.char_indices().peekable();
        let mut cur = String::new();
        let flush = |cur: &mut String, fields: &mut Vec<(String, usize)>| {
            if !cur.is_empty() {
                fields.push((std::mem::take(cur), line));
            }
        };
        while let Some((_, c)) = chars.next() {
            match c {
                '\'' | '"' => {
                    flush(&mut cur, &mut fields);
                    let mut s = String::new();
                    let mut closed = false;
                    for (_, d) in chars.by_ref() {
                        if d == c {
                            closed = true;
                            break;
                        }
                        s.push(d);
                    }
                    if !closed {
                        return Err(syntax(
                            line,
                            format!("string {c}{s} is not closed on its line"),
                        ));
                    }
                    // A quoted empty string still counts as a field.
                    fields.push((format!("\u{1}{}", s.trim()), line));
                }
                '/' => {
                    flush(&mut cur, &mut fields);
                    if !fields.is_empty() {
                        records.push(make_record(std::mem::take(&mut fields), path)?);
                    }
                    break; // the rest of the line is a comment
                }
                c if c.is_whitespace() || c == ',' => flush(&mut cur, &mut fields),
                c => cur.push(c),
            }
        }
        flush(&mut cur, &mut fields);
    }
    if let Some((_, line)) = fields.first() {
        return Err(syntax(
            *line,
            "record not terminated: every record ends with '/'".into(),
        ));
    }
    Ok(records)
}

fn unquote(s: &str) -> &str {
    s.strip_prefix('\u{1}').unwrap_or(s)
}

fn make_record(fields: Vec<(String, usize)>, path: &Path) -> Result<RawRecord, DyrError> {
    let line = fields[0].1;
    let syntax = |msg: String| DyrError::Syntax {
        path: path.into(),
        line,
        msg,
    };
    if fields.len() < 3 {
        return Err(syntax(format!(
            "record '{}' is too short: a record is IBUS 'MODEL' ID data… /",
            fields
                .iter()
                .map(|f| unquote(&f.0))
                .collect::<Vec<_>>()
                .join(" ")
        )));
    }
    let bus_text = unquote(&fields[0].0);
    let bus: i64 = bus_text
        .parse()
        .map_err(|_| syntax(format!("bus number '{bus_text}' is not an integer")))?;
    let model = unquote(&fields[1].0).to_ascii_uppercase();
    if model.is_empty() || model.parse::<f64>().is_ok() {
        return Err(syntax(format!(
            "'{model}' is not a model name (record: IBUS 'MODEL' ID data… /)"
        )));
    }
    let id = unquote(&fields[2].0).to_string();
    Ok(RawRecord {
        line,
        bus,
        model,
        id,
        data: fields[3..]
            .iter()
            .map(|(s, l)| (unquote(s).to_string(), *l))
            .collect(),
    })
}

fn parse_number(s: &str) -> Option<f64> {
    let t = s.replace(['D', 'd'], "E");
    t.parse::<f64>().ok().filter(|x| x.is_finite())
}

/// The unit read from a `.dyr`, with what could not be carried over.
pub struct DyrUnit {
    pub unit: Unit,
    pub bus: i64,
    pub id: String,
    /// (line, model) of every record used.
    pub used: Vec<(usize, String)>,
    pub warnings: Vec<DyrWarning>,
}

/// How to read a `.dyr`: which unit, and whether records of models the engine lacks may be
/// left out.
#[derive(Debug, Clone, Copy, Default)]
pub struct DyrReadOptions<'a> {
    /// The unit `(bus, machine id)`; `None`: the file's only unit.
    pub select: Option<(i64, &'a str)>,
    /// Build the unit without the records of models the engine lacks (each a warning and an
    /// entry of [`Unit::lacks`], which every report repeats). Default: such a record is an
    /// error ([`DyrError::Unsupported`]).
    pub skip_unsupported: bool,
}

/// One unit of a `.dyr` as listed by [`list_units`]: its bus, machine id and records.
#[derive(Debug, Clone, PartialEq)]
pub struct UnitListing {
    pub bus: i64,
    pub id: String,
    /// `(line, model, supported)` of each record, in file order.
    pub records: Vec<(usize, String, bool)>,
}

impl std::fmt::Display for UnitListing {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "bus {} id '{}':", self.bus, self.id)?;
        for (line, model, ok) in &self.records {
            write!(
                f,
                " {model} (line {line}{})",
                if *ok { "" } else { ", not supported" }
            )?;
        }
        Ok(())
    }
}

/// The units of a `.dyr` (every distinct bus and machine id, in file order) with their records.
pub fn list_units(text: &str, path: &Path) -> Result<Vec<UnitListing>, DyrError> {
    let mut out: Vec<UnitListing> = vec![];
    for r in parse_records(text, path)? {
        let supported = dyr_model(&r.model).is_some();
        match out.iter_mut().find(|u| u.bus == r.bus && u.id == r.id) {
            Some(u) => u.records.push((r.line, r.model.clone(), supported)),
            None => out.push(UnitListing {
                bus: r.bus,
                id: r.id.clone(),
                records: vec![(r.line, r.model.clone(), supported)],
            }),
        }
    }
    Ok(out)
}

/// Reads the unit `select` = (bus, id) from a `.dyr` file (any unit if the file holds one); a
/// record of a model the engine lacks is an error ([`read_dyr_with`] to leave it out).
pub fn read_dyr(
    path: &Path,
    select: Option<(i64, &str)>,
    bases: &DyrBases,
) -> Result<DyrUnit, DyrError> {
    read_dyr_with(
        path,
        bases,
        &DyrReadOptions {
            select,
            skip_unsupported: false,
        },
    )
}

/// [`read_dyr`] with the options spelled out.
pub fn read_dyr_with(
    path: &Path,
    bases: &DyrBases,
    opts: &DyrReadOptions,
) -> Result<DyrUnit, DyrError> {
    let text = std::fs::read_to_string(path).map_err(|source| DyrError::Io {
        path: path.into(),
        source,
    })?;
    parse_dyr_with(&text, path, bases, opts)
}

/// Parses `.dyr` text; `path` is used in messages and for the default unit name. A record of a
/// model the engine lacks is an error.
pub fn parse_dyr(
    text: &str,
    path: &Path,
    select: Option<(i64, &str)>,
    bases: &DyrBases,
) -> Result<DyrUnit, DyrError> {
    parse_dyr_with(
        text,
        path,
        bases,
        &DyrReadOptions {
            select,
            skip_unsupported: false,
        },
    )
}

/// [`parse_dyr`] with the options spelled out.
pub fn parse_dyr_with(
    text: &str,
    path: &Path,
    bases: &DyrBases,
    opts: &DyrReadOptions,
) -> Result<DyrUnit, DyrError> {
    let records = parse_records(text, path)?;
    // Every field of a record the engine reads is a number (PSS/E quotes only the model name and
    // the machine id): a field that is not is named at its line before any unit is chosen, so
    // that the file's own error is what the user reads, not a consequence of it.
    for r in &records {
        let Some(m) = dyr_model(&r.model) else {
            continue;
        };
        let Some(k) = r.data.iter().position(|(t, _)| parse_number(t).is_none()) else {
            continue;
        };
        let layout = m.dyr.as_ref().expect("a model with a record");
        let names = layout.field_names(m.create().as_ref());
        let field = match (k.checked_sub(layout.icons.len()), names.get(k)) {
            (None, Some(name)) => format!("ICON {} ({name})", k + 1),
            (Some(c), Some(name)) => format!("CON {} ({name})", c + 1),
            (_, None) => format!("field {}", k + 1),
        };
        let (text, line) = &r.data[k];
        return Err(DyrError::Record {
            path: path.into(),
            line: *line,
            model: m.name.into(),
            msg: format!("{field} = '{text}' is not a number"),
        });
    }
    let warn = |line: Option<usize>, msg: String| DyrWarning {
        path: Some(path.into()),
        line,
        msg,
    };
    let (bus, id) = match opts.select {
        Some((b, i)) => (b, i.trim().to_string()),
        None => {
            let mut units: Vec<(i64, String)> = vec![];
            for r in &records {
                if dyr_model(&r.model).map(|m| m.role) == Some(Role::Machine)
                    || guess_role(&r.model).0 == Role::Machine
                {
                    let u = (r.bus, r.id.clone());
                    if !units.contains(&u) {
                        units.push(u);
                    }
                }
            }
            match units.len() {
                1 => units.pop().expect("one"),
                0 => {
                    return Err(DyrError::Selection {
                        path: path.into(),
                        msg: format!(
                            "no machine record ({}) in the file",
                            machine_names().join(", ")
                        ),
                    })
                }
                _ => {
                    return Err(DyrError::Selection {
                        path: path.into(),
                        msg: format!(
                        "the file holds {} machines ({}); choose one by bus number and machine id",
                        units.len(),
                        list_units_short(&units)
                    ),
                    })
                }
            }
        }
    };
    let mut warnings = vec![];
    let mut chosen: Vec<(&RawRecord, &'static ModelInfo)> = vec![];
    let mut unsupported: Vec<&RawRecord> = vec![];
    let mut others: Vec<(i64, String)> = vec![];
    let mut n_other = 0usize;
    for r in &records {
        if r.bus != bus || r.id != id {
            n_other += 1;
            let u = (r.bus, r.id.clone());
            if !others.contains(&u) {
                others.push(u);
            }
            continue;
        }
        let Some(m) = dyr_model(&r.model) else {
            unsupported.push(r);
            continue;
        };
        if let Some((first, _)) = chosen.iter().find(|(_, c)| c.role == m.role) {
            return Err(DyrError::Record {
                path: path.into(),
                line: r.line,
                model: m.name.into(),
                msg: format!(
                    "a second {} model for bus {bus} id '{id}' (the first, {}, is on line {})",
                    m.role.section(),
                    first.model,
                    first.line
                ),
            });
        }
        chosen.push((r, m));
    }
    if chosen.is_empty() && unsupported.is_empty() {
        return Err(DyrError::Selection {
            path: path.into(),
            msg: format!(
                "no record for bus {bus} id '{id}'{}",
                if others.is_empty() {
                    String::new()
                } else {
                    format!(" (units in the file: {})", list_units_short(&others))
                }
            ),
        });
    }
    // What the unit would lack without each unsupported record.
    let lacking: Vec<(usize, String, String)> = unsupported
        .iter()
        .map(|r| {
            let name = record_name(r);
            let model = match r.model.as_str() {
                "USRMDL" => r.data.first().map_or("USRMDL", |d| d.0.as_str()),
                m => m,
            };
            let (role, kind) = guess_role(model);
            let lacks = match chosen
                .iter()
                .find(|(_, m)| m.role == role && role != Role::Other)
            {
                Some((c, m)) => format!(
                    "nothing (it is a second {} record beside {} on line {})",
                    role.section(),
                    m.name,
                    c.line
                ),
                None if role == Role::Other => kind.to_string(),
                None => format!("{kind} ({})", role.absence()),
            };
            (r.line, name, lacks)
        })
        .collect();
    if !lacking.is_empty() && !opts.skip_unsupported {
        return Err(DyrError::Unsupported {
            path: path.into(),
            bus,
            id: id.clone(),
            records: lacking,
        });
    }
    let mut lacks = vec![];
    for (line, name, what) in &lacking {
        let msg = format!(
            "{name} (bus {bus}, id '{id}') is not supported; the unit is built without it, as asked: {what}"
        );
        warnings.push(warn(Some(*line), msg));
        lacks.push(format!(
            "{name} ({} line {line}) not supported, left out: {what}",
            path.display()
        ));
    }
    if n_other > 0 {
        warnings.push(warn(
            None,
            format!(
                "{n_other} record(s) of other units ignored ({})",
                list_units_short(&others)
            ),
        ));
    }
    let Some(&(mrec, mmodel)) = chosen.iter().find(|(_, m)| m.role == Role::Machine) else {
        return Err(DyrError::Selection {
            path: path.into(),
            msg: format!(
                "bus {bus} id '{id}' has no machine record ({}); found {}",
                machine_names().join(", "),
                chosen
                    .iter()
                    .map(|(r, _)| format!("{} (line {})", r.model, r.line))
                    .chain(
                        unsupported
                            .iter()
                            .map(|r| format!("{} (line {}, not supported)", r.model, r.line))
                    )
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        });
    };
    let name = bases.name.clone().unwrap_or_else(|| {
        let stem = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        format!("{stem} bus {bus} id {id}")
    });
    let mut unit = Unit::new(&name, bases.mbase, bases.nominal_hz);
    unit.description = format!("read from {} (bus {bus}, id '{id}')", path.display());
    unit.lacks = lacks;
    let mut used = vec![];
    // Machine first, then exciter, PSS, governor (the state order of unit files).
    let order = [Role::Machine, Role::Exciter, Role::Pss, Role::Governor];
    for role in order {
        let Some(&(r, m)) = chosen.iter().find(|(_, m)| m.role == role) else {
            continue;
        };
        if role == Role::Exciter && mmodel.name == "GENCLS" {
            return Err(DyrError::Record {
                path: path.into(),
                line: r.line,
                model: m.name.into(),
                msg: format!(
                    "GENCLS (line {}) has no field winding: an exciter cannot be attached",
                    mrec.line
                ),
            });
        }
        let (block, rewire) = build(r, m, bases, path, &mut warnings)?;
        unit.add(role.section(), block, &rewire)
            .map_err(|source| DyrError::Unit {
                path: path.into(),
                source,
            })?;
        used.push((r.line, m.name.to_string()));
    }
    unit.finish().map_err(|source| DyrError::Unit {
        path: path.into(),
        source,
    })?;
    Ok(DyrUnit {
        unit,
        bus,
        id,
        used,
        warnings,
    })
}

/// The registry's machine models with a record, for messages.
fn machine_names() -> Vec<&'static str> {
    registry::all()
        .filter(|m| m.role == Role::Machine && m.dyr.is_some())
        .map(|m| m.name)
        .collect()
}

/// `model X` or `user model X` (a USRMDL record names its model in its first field).
fn record_name(r: &RawRecord) -> String {
    if r.model == "USRMDL" {
        format!(
            "user model {}",
            r.data.first().map(|d| d.0.as_str()).unwrap_or("?")
        )
    } else {
        format!("model {}", r.model)
    }
}

/// What a model the engine lacks most likely is, by PSS/E's naming of its library (the role,
/// and a name for it). A record whose role cannot be told is `Role::Other`.
pub fn guess_role(model: &str) -> (Role, &'static str) {
    let m = model.to_ascii_uppercase();
    let starts = |prefixes: &[&str]| prefixes.iter().any(|p| m.starts_with(p));
    if starts(&[
        "PSS", "STAB", "IEEEST", "IEE2ST", "ST2CUT", "PTIST", "STBSVC",
    ]) {
        (Role::Pss, "the stabiliser")
    } else if starts(&["GEN", "CIMTR", "FRECHG", "CGEN"]) {
        (Role::Machine, "the machine")
    } else if starts(&[
        "ES", "EX", "IEEET", "IEEEX", "SCRX", "SEXS", "REXS", "URST", "AC7B", "AC8B", "ST5B",
        "ST6B", "ST7B", "BBSEX", "BUDCZT", "CELIN", "EMAC", "ESURRY", "IVOEX", "OEX",
    ]) {
        (Role::Exciter, "the exciter")
    } else if m.contains("GOV")
        || m.contains("HYG")
        || starts(&[
            "TGOV", "IEEEG", "IEESGO", "GAST", "TG", "GGOV", "DEGOV", "PIDGOV", "CRCMGV", "URGS",
            "SHAF", "WPIDHY", "WEHGOV", "WESGOV", "H6E", "IVOGO",
        ])
    {
        (Role::Governor, "the governor")
    } else if starts(&["MAXEX", "OEL", "UEL", "MNLEX", "SCL"]) {
        (
            Role::Other,
            "an excitation limiter (its limiting action missing)",
        )
    } else if starts(&["COMP", "IEEEVC", "REMCMP"]) {
        (
            Role::Other,
            "a voltage compensator (the regulated voltage is then |V_t|)",
        )
    } else {
        (
            Role::Other,
            "a model whose role cannot be told from its name (its action missing)",
        )
    }
}

fn list_units_short(u: &[(i64, String)]) -> String {
    let mut s: Vec<String> = u
        .iter()
        .take(12)
        .map(|(b, i)| format!("bus {b} id '{i}'"))
        .collect();
    if u.len() > 12 {
        s.push(format!("and {} more", u.len() - 12));
    }
    s.join(", ")
}

type Rewire = Vec<(String, String)>;

/// The registry entry of a model with a `.dyr` record.
fn dyr_model(name: &str) -> Option<&'static ModelInfo> {
    registry::find(name).filter(|m| m.dyr.is_some())
}

/// A block from its record: the ICONs (options, input wiring, zeros), the CONs, the machine's
/// fields from the bases, then the block's own parameter checks.
fn build(
    r: &RawRecord,
    m: &ModelInfo,
    bases: &DyrBases,
    path: &Path,
    warnings: &mut Vec<DyrWarning>,
) -> Result<(Box<dyn Block>, Rewire), DyrError> {
    let err = |line: usize, msg: String| DyrError::Record {
        path: path.into(),
        line,
        model: m.name.into(),
        msg,
    };
    let layout = m.dyr.as_ref().expect("a model with a record");
    let mut block = m.create();
    let n = layout.len();
    if r.data.len() != n {
        return Err(err(
            r.line,
            format!(
                "{n} values expected after the machine id ({}), found {}",
                layout.field_names(block.as_ref()).join(" "),
                r.data.len()
            ),
        ));
    }
    let mut icons = vec![];
    for (k, icon) in layout.icons.iter().enumerate() {
        let (text, line) = &r.data[k];
        let v: i64 = text.parse().map_err(|_| {
            err(
                *line,
                format!("ICON {} = '{text}' is not an integer", icon.name()),
            )
        })?;
        icons.push(v);
    }
    for (k, con) in layout.cons.iter().enumerate() {
        let (text, line) = &r.data[layout.icons.len() + k];
        let alias = || {
            block
                .params()
                .specs()
                .iter()
                .find(|s| s.name == *con)
                .map_or(con.to_string(), |s| s.alias.to_string())
        };
        let v = parse_number(text).ok_or_else(|| {
            err(
                *line,
                format!("CON {} ({}) = '{text}' is not a number", k + 1, alias()),
            )
        })?;
        let idx = block
            .params()
            .index_of(con)
            .expect("CON names are canonical parameter names");
        block.params_mut().set(idx, v);
    }
    let mut rewire = vec![];
    for (k, icon) in layout.icons.iter().enumerate() {
        let (v, line) = (icons[k], r.data[k].1);
        match icon {
            Icon::Option { name, key, .. } => block
                .set_option(key, &v.to_string())
                .map_err(|e| err(line, format!("ICON {name}: {e}")))?,
            Icon::Input { name, port, codes } => {
                let supported = || {
                    codes
                        .iter()
                        .filter(|c| c.signal.is_some())
                        .map(|c| format!("{} {}", c.code, c.meaning))
                        .collect::<Vec<_>>()
                        .join(", ")
                };
                let sig = match codes.iter().find(|c| c.code == v) {
                    Some(c) => c.signal.ok_or_else(|| {
                        err(
                            line,
                            format!(
                                "input code {name} = {v} ({}) has no signal in the engine (supported: {})",
                                c.meaning,
                                supported()
                            ),
                        )
                    })?,
                    None => {
                        return Err(err(
                            line,
                            format!(
                                "input code {name} = {v} has no signal in the engine (supported: {})",
                                supported()
                            ),
                        ))
                    }
                };
                let default = block
                    .ports()
                    .iter()
                    .find(|p| p.name == *port)
                    .map(|p| p.signal)
                    .expect("checked by the registry test");
                if sig != default {
                    rewire.push((port.to_string(), sig.to_string()));
                }
            }
            Icon::Zero { name, meaning } => {
                if v != 0 {
                    return Err(err(
                        line,
                        format!("{meaning} {name} = {v}: only 0 (the unit's own bus and machine) is supported"),
                    ));
                }
            }
            Icon::Ignored { .. } => {}
        }
    }
    let set = |block: &mut Box<dyn Block>, name: &str, v: f64| {
        let idx = block.params().index_of(name).expect("canonical parameter");
        block.params_mut().set(idx, v);
    };
    let wline = |msg: String| DyrWarning {
        path: Some(path.into()),
        line: Some(r.line),
        msg,
    };
    if let Some(mf) = &layout.machine {
        set(&mut block, "r_a", bases.zr.unwrap_or(0.0));
        if bases.zr.is_none() {
            warnings.push(wline(format!(
                "{}: R_a = 0 (ZSORCE R not given: zr in the bases)",
                m.name
            )));
        }
        match mf.zsorce_x {
            ZsorceX::Sets(p) => {
                let zx = bases.zx.ok_or_else(|| DyrError::Bases {
                    path: path.into(),
                    field: "zx".into(),
                    msg: format!(
                        "missing: {} (line {}) takes {p} from ZSORCE X of the power-flow record",
                        m.name, r.line
                    ),
                })?;
                set(&mut block, p, zx);
            }
            ZsorceX::Equals(p) => {
                let pos = layout.cons.iter().position(|c| *c == p).expect("a CON");
                let xpp = parse_number(&r.data[layout.icons.len() + pos].0).expect("parsed above");
                if let Some(zx) = bases.zx {
                    if (zx - xpp).abs() > 1e-6 * xpp.abs().max(1.0) {
                        warnings.push(wline(format!(
                            "{}: ZSORCE X = {zx} differs from X'' = {xpp} (PSS/E expects them equal); X'' of the record is used",
                            m.name
                        )));
                    }
                }
            }
        }
        for t in mf.ties {
            let v = block
                .params()
                .get(block.params().index_of(t.from.0).expect("tied parameter"));
            set(&mut block, t.to.0, v);
        }
    }
    block.validate().map_err(|e| err(r.line, e.to_string()))?;
    Ok((block, rewire))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_span_lines_and_comments_follow_the_slash() {
        let text = "1 'GENCLS' 1 4.5\n  0.0 / the classical machine\n\n2,'SEXS','G1',\n0.1,10,100,0.05,0,4 / exciter\n";
        let r = parse_records(text, Path::new("x.dyr")).unwrap();
        assert_eq!(r.len(), 2);
        assert_eq!(
            (r[0].line, r[0].bus, r[0].model.as_str(), r[0].id.as_str()),
            (1, 1, "GENCLS", "1")
        );
        assert_eq!(
            r[0].data.iter().map(|d| d.1).collect::<Vec<_>>(),
            vec![1, 2]
        );
        assert_eq!((r[1].line, r[1].id.as_str(), r[1].data.len()), (4, "G1", 6));
        assert_eq!(parse_number("1.5D-3"), Some(1.5e-3));
    }
}

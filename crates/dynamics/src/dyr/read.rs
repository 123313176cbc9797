//! Reading a `.dyr`: the record syntax ([`parse_records`]) and the unit built from the
//! selected machine's records ([`read_dyr`], [`parse_dyr`]).

use std::path::Path;

use super::records::{alias_of, dyr_model, icon_option, supported_models, DyrModel, IEEEST_INPUTS};
use super::{DyrBases, DyrError, DyrWarning};
use crate::block::Block;
use crate::registry::{self, Role};
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

/// Reads the unit `select` = (bus, id) from a `.dyr` file (any unit if the file holds one).
pub fn read_dyr(
    path: &Path,
    select: Option<(i64, &str)>,
    bases: &DyrBases,
) -> Result<DyrUnit, DyrError> {
    let text = std::fs::read_to_string(path).map_err(|source| DyrError::Io {
        path: path.into(),
        source,
    })?;
    parse_dyr(&text, path, select, bases)
}

/// Parses `.dyr` text; `path` is used in messages and for the default unit name.
pub fn parse_dyr(
    text: &str,
    path: &Path,
    select: Option<(i64, &str)>,
    bases: &DyrBases,
) -> Result<DyrUnit, DyrError> {
    let records = parse_records(text, path)?;
    let warn = |line: Option<usize>, msg: String| DyrWarning {
        path: Some(path.into()),
        line,
        msg,
    };
    let (bus, id) = match select {
        Some((b, i)) => (b, i.trim().to_string()),
        None => {
            let mut units: Vec<(i64, String)> = vec![];
            for r in &records {
                if dyr_model(&r.model).map(|m| m.role) == Some(Role::Machine)
                    || r.model.starts_with("GEN")
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
                        msg: "no machine record (GENSAE, GENSAL, GENROU, GENCLS) in the file"
                            .into(),
                    })
                }
                _ => {
                    return Err(DyrError::Selection {
                        path: path.into(),
                        msg: format!(
                        "the file holds {} machines ({}); choose one by bus number and machine id",
                        units.len(),
                        list_units(&units)
                    ),
                    })
                }
            }
        }
    };
    let mut warnings = vec![];
    let mut chosen: Vec<(&RawRecord, &'static DyrModel)> = vec![];
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
            let name = if r.model == "USRMDL" {
                format!(
                    "user model {}",
                    r.data.first().map(|d| d.0.as_str()).unwrap_or("?")
                )
            } else {
                format!("model {}", r.model)
            };
            warnings.push(warn(
                Some(r.line),
                format!(
                    "{name} (bus {bus}, id '{id}') is not supported (supported: {}); the unit is built without it",
                    supported_models().join(", ")
                ),
            ));
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
    if chosen.is_empty() {
        return Err(DyrError::Selection {
            path: path.into(),
            msg: format!(
                "no record for bus {bus} id '{id}'{}",
                if others.is_empty() {
                    String::new()
                } else {
                    format!(" (units in the file: {})", list_units(&others))
                }
            ),
        });
    }
    if n_other > 0 {
        warnings.push(warn(
            None,
            format!(
                "{n_other} record(s) of other units ignored ({})",
                list_units(&others)
            ),
        ));
    }
    let Some(&(mrec, mmodel)) = chosen.iter().find(|(_, m)| m.role == Role::Machine) else {
        return Err(DyrError::Selection {
            path: path.into(),
            msg: format!(
                "bus {bus} id '{id}' has no machine record (GENSAE, GENSAL, GENROU, GENCLS); found {}",
                chosen.iter().map(|(r, _)| format!("{} (line {})", r.model, r.line)).collect::<Vec<_>>().join(", ")
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

fn list_units(u: &[(i64, String)]) -> String {
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

fn build(
    r: &RawRecord,
    m: &DyrModel,
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
    let n = m.icons.len() + m.cons.len();
    if r.data.len() != n {
        let names: Vec<String> = m
            .icons
            .iter()
            .map(|s| s.to_string())
            .chain(m.cons.iter().map(|c| alias_of(m, c)))
            .collect();
        return Err(err(
            r.line,
            format!(
                "{n} values expected after the machine id ({}), found {}",
                names.join(" "),
                r.data.len()
            ),
        ));
    }
    let info = registry::find(m.name).expect("every .dyr model is in the registry");
    let mut block = info.create();
    let mut rewire = vec![];
    let mut icons = vec![];
    for (k, icon) in m.icons.iter().enumerate() {
        let (text, line) = &r.data[k];
        let v: i64 = text
            .parse()
            .map_err(|_| err(*line, format!("ICON {icon} = '{text}' is not an integer")))?;
        icons.push(v);
    }
    for (k, con) in m.cons.iter().enumerate() {
        let (text, line) = &r.data[m.icons.len() + k];
        let v = parse_number(text).ok_or_else(|| {
            err(
                *line,
                format!(
                    "CON {} ({}) = '{text}' is not a number",
                    k + 1,
                    alias_of(m, con)
                ),
            )
        })?;
        let idx = block
            .params()
            .index_of(con)
            .expect("CON names are canonical parameter names");
        block.params_mut().set(idx, v);
    }
    for (k, icon) in m.icons.iter().enumerate() {
        if let Some((opt, _)) = icon_option(m.name, icon) {
            block
                .set_option(opt, &icons[k].to_string())
                .map_err(|e| err(r.data[k].1, format!("ICON {icon}: {e}")))?;
        }
    }
    let mut set = |name: &str, v: f64| {
        let idx = block.params().index_of(name).expect("canonical parameter");
        block.params_mut().set(idx, v);
    };
    let wline = |msg: String| DyrWarning {
        path: Some(path.into()),
        line: Some(r.line),
        msg,
    };
    match m.role {
        Role::Machine => {
            set("r_a", bases.zr.unwrap_or(0.0));
            if bases.zr.is_none() {
                warnings.push(wline(format!(
                    "{}: R_a = 0 (ZSORCE R not given: zr in the bases)",
                    m.name
                )));
            }
            if m.name == "GENCLS" {
                let zx = bases.zx.ok_or_else(|| DyrError::Bases {
                    path: path.into(),
                    field: "zx".into(),
                    msg: format!("missing: GENCLS (line {}) takes X'd from ZSORCE X of the power-flow record", r.line),
                })?;
                set("x_d_prime", zx);
            } else {
                let pos = m.cons.iter().position(|c| *c == "x_d_pp").expect("X''d");
                let xpp = parse_number(&r.data[pos].0).expect("parsed above");
                if matches!(m.name, "GENSAE" | "GENSAL") {
                    set("x_q_pp", xpp);
                }
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
        Role::Pss if m.name == "IEEEST" => {
            let (ic, ib) = (icons[0], icons[1]);
            let Some((_, sig, _)) = IEEEST_INPUTS.iter().find(|(c, _, _)| *c == ic) else {
                return Err(err(
                    r.data[0].1,
                    format!(
                        "input code IC = {ic} has no signal in the engine (supported: {})",
                        IEEEST_INPUTS
                            .iter()
                            .map(|(c, _, d)| format!("{c} {d}"))
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                ));
            };
            if ib != 0 {
                return Err(err(
                    r.data[1].1,
                    format!("remote bus IB = {ib}: only the unit's own bus (IB = 0) is supported"),
                ));
            }
            if *sig != "speed" {
                rewire.push(("u".to_string(), sig.to_string()));
            }
        }
        _ => {}
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

//! PSS/E dynamic data files (`.dyr`): read one unit's records into a [`Unit`], write a unit back.
//!
//! A record is `IBUS 'MODEL' ID data… /`: the bus number, the model name, the machine
//! identifier, then the model's ICONs and CONs in the order PSS/E documents them. A record may
//! span lines and ends with `/`; whatever follows the `/` on its line is a comment. Fields are
//! separated by blanks or commas; strings may be quoted with `'` or `"`; Fortran exponents
//! (`1.5D-3`) are accepted.
//!
//! | model  | ICONs     | CONs (PSS/E order)                                                     |
//! |--------|-----------|------------------------------------------------------------------------|
//! | GENSAE | —         | T'd0 T''d0 T''q0 H D Xd Xq X'd X''d Xl S(1.0) S(1.2)                    |
//! | GENSAL | —         | T'd0 T''d0 T''q0 H D Xd Xq X'd X''d Xl S(1.0) S(1.2)                    |
//! | GENROU | —         | T'd0 T''d0 T'q0 T''q0 H D Xd Xq X'd X'q X''d Xl S(1.0) S(1.2)           |
//! | GENCLS | —         | H D                                                                    |
//! | SEXS   | —         | TA/TB TB K TE EMIN EMAX                                                |
//! | STAB3  | —         | Tt TX1 TX2 KX VLIM                                                     |
//! | IEEEST | IC IB     | A1 A2 A3 A4 A5 A6 T1 T2 T3 T4 T5 T6 KS LSMAX LSMIN VCU VCL              |
//! | HYGOV  | —         | R r Tr Tf Tg VELM GMAX GMIN TW At Dturb qNL                             |
//!
//! What the `.dyr` does not hold comes from the power-flow machine record, given on the command
//! line or in a small side file ([`DyrBases`], TOML): `mbase` (MVA), `nominal_hz`, `zr` (ZSORCE
//! R: the armature resistance R_a on MBASE, 0 if not given, with a warning) and `zx` (ZSORCE X:
//! GENCLS's X'd; for the other machines PSS/E's X'', checked against the record's X''d).
//! PSS/E has a single X'': GENSAE and GENSAL read it into both X''d and X''q.
//!
//! IEEEST's input code IC selects the signal its input port is wired to: 1 rotor speed
//! deviation (`speed`), 3 electrical power (`pe`), 5 terminal voltage (`v_term`); the other codes
//! (bus frequency, accelerating power, dV/dt) and a remote bus IB ≠ 0 have no signal in the
//! engine and are refused.
//!
//! Records of the selected unit whose model the engine lacks are reported by line as warnings
//! and left out; records of other units are counted in one warning. Malformed records (no `/`,
//! a bus number that is not an integer, a CON that is not a number, the wrong number of CONs, a
//! second model in the same role, parameters the model refuses) are [`DyrError`]s naming the
//! file and the line.

use std::fmt;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::block::Block;
use crate::registry::{self, Role};
use crate::unit::{Unit, UnitError};

/// One model the reader and writer know: its role, ICON names and CONs as canonical parameter
/// names of the model's `param_set!` (the one definition of each parameter).
struct DyrModel {
    name: &'static str,
    role: Role,
    icons: &'static [&'static str],
    cons: &'static [&'static str],
}

const SALIENT: &[&str] = &[
    "t_d0_prime",
    "t_d0_pp",
    "t_q0_pp",
    "h",
    "d",
    "x_d",
    "x_q",
    "x_d_prime",
    "x_d_pp",
    "x_l",
    "s10",
    "s12",
];

static DYR_MODELS: &[DyrModel] = &[
    DyrModel {
        name: "GENSAE",
        role: Role::Machine,
        icons: &[],
        cons: SALIENT,
    },
    DyrModel {
        name: "GENSAL",
        role: Role::Machine,
        icons: &[],
        cons: SALIENT,
    },
    DyrModel {
        name: "GENROU",
        role: Role::Machine,
        icons: &[],
        cons: &[
            "t_d0_prime",
            "t_d0_pp",
            "t_q0_prime",
            "t_q0_pp",
            "h",
            "d",
            "x_d",
            "x_q",
            "x_d_prime",
            "x_q_prime",
            "x_d_pp",
            "x_l",
            "s10",
            "s12",
        ],
    },
    DyrModel {
        name: "GENCLS",
        role: Role::Machine,
        icons: &[],
        cons: &["h", "d"],
    },
    DyrModel {
        name: "SEXS",
        role: Role::Exciter,
        icons: &[],
        cons: &["ta_tb", "tb", "k", "te", "e_min", "e_max"],
    },
    DyrModel {
        name: "STAB3",
        role: Role::Pss,
        icons: &[],
        cons: &["t_t", "t_x1", "t_x2", "k_x", "v_lim"],
    },
    DyrModel {
        name: "IEEEST",
        role: Role::Pss,
        icons: &["IC", "IB"],
        cons: &[
            "a1", "a2", "a3", "a4", "a5", "a6", "t1", "t2", "t3", "t4", "t5", "t6", "ks", "ls_max",
            "ls_min", "vcu", "vcl",
        ],
    },
    DyrModel {
        name: "HYGOV",
        role: Role::Governor,
        icons: &[],
        cons: &[
            "r_perm", "r_temp", "t_r", "t_f", "t_g", "velm", "g_max", "g_min", "t_w", "a_t",
            "d_turb", "q_nl",
        ],
    },
];

/// IEEEST input codes the engine can wire: (IC, signal, meaning).
const IEEEST_INPUTS: &[(i64, &str, &str)] = &[
    (1, "speed", "rotor speed deviation"),
    (3, "pe", "generator electrical power on MBASE"),
    (5, "v_term", "bus voltage"),
];

fn dyr_model(name: &str) -> Option<&'static DyrModel> {
    DYR_MODELS
        .iter()
        .find(|m| m.name.eq_ignore_ascii_case(name))
}

/// The models this module reads and writes.
pub fn supported_models() -> Vec<&'static str> {
    DYR_MODELS.iter().map(|m| m.name).collect()
}

/// Values from the power-flow machine record that a `.dyr` does not hold.
#[derive(Debug, Clone, PartialEq)]
pub struct DyrBases {
    /// MBASE, MVA (the machine base of every per-unit CON).
    pub mbase: f64,
    /// Nominal frequency, Hz.
    pub nominal_hz: f64,
    /// ZSORCE R: armature resistance R_a, pu on MBASE (`None`: 0, with a warning).
    pub zr: Option<f64>,
    /// ZSORCE X, pu on MBASE: X'd of GENCLS; for the other machines checked against X''d.
    pub zx: Option<f64>,
    /// Unit name (default: `<file stem> bus N id ID`).
    pub name: Option<String>,
}

/// Keys of the side file.
const BASES_KEYS: [&str; 5] = ["mbase", "nominal_hz", "zr", "zx", "name"];

impl DyrBases {
    /// Reads a side file (TOML: `mbase`, `nominal_hz`, optional `zr`, `zx`, `name`).
    pub fn from_file(path: &Path) -> Result<DyrBases, DyrError> {
        let text = std::fs::read_to_string(path).map_err(|source| DyrError::Io {
            path: path.into(),
            source,
        })?;
        Self::parse(&text, path, None)
    }

    /// Parses side-file text; values in `over` (e.g. from the command line) replace the file's
    /// and may stand in for missing keys.
    pub fn parse(
        text: &str,
        path: &Path,
        over: Option<&PartialBases>,
    ) -> Result<DyrBases, DyrError> {
        let field = |f: &str, msg: String| DyrError::Bases {
            path: path.into(),
            field: f.into(),
            msg,
        };
        let table: toml::Table = text.parse().map_err(|e: toml::de::Error| DyrError::Bases {
            path: path.into(),
            field: "(syntax)".into(),
            msg: e.to_string().trim().replace('\n', " "),
        })?;
        for k in table.keys() {
            if !BASES_KEYS.contains(&k.as_str()) {
                return Err(field(
                    k,
                    format!("unknown key (accepted: {})", BASES_KEYS.join(", ")),
                ));
            }
        }
        let num = |k: &str| -> Result<Option<f64>, DyrError> {
            match table.get(k) {
                None => Ok(None),
                Some(toml::Value::Float(x)) => Ok(Some(*x)),
                Some(toml::Value::Integer(i)) => Ok(Some(*i as f64)),
                Some(_) => Err(field(k, "must be a number".into())),
            }
        };
        let mut p = PartialBases {
            mbase: num("mbase")?,
            nominal_hz: num("nominal_hz")?,
            zr: num("zr")?,
            zx: num("zx")?,
            name: match table.get("name") {
                None => None,
                Some(toml::Value::String(s)) => Some(s.clone()),
                Some(_) => return Err(field("name", "must be a string".into())),
            },
        };
        if let Some(o) = over {
            p.overlay(o);
        }
        p.finish(path)
    }
}

/// Bases as far as they are known (command-line options, or a side file being read).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PartialBases {
    pub mbase: Option<f64>,
    pub nominal_hz: Option<f64>,
    pub zr: Option<f64>,
    pub zx: Option<f64>,
    pub name: Option<String>,
}

impl PartialBases {
    /// Takes every value `o` has.
    pub fn overlay(&mut self, o: &PartialBases) {
        self.mbase = o.mbase.or(self.mbase);
        self.nominal_hz = o.nominal_hz.or(self.nominal_hz);
        self.zr = o.zr.or(self.zr);
        self.zx = o.zx.or(self.zx);
        self.name = o.name.clone().or(self.name.take());
    }

    /// Checks and completes; `src` names where the values came from in messages.
    pub fn finish(self, src: &Path) -> Result<DyrBases, DyrError> {
        let field = |f: &str, msg: String| DyrError::Bases {
            path: src.into(),
            field: f.into(),
            msg,
        };
        let mbase = self.mbase.ok_or_else(|| {
            field(
                "mbase",
                "missing: the machine base MBASE [MVA] from the power-flow machine record".into(),
            )
        })?;
        if !(mbase.is_finite() && mbase > 0.0) {
            return Err(field(
                "mbase",
                format!("must be a finite number > 0 MVA (got {mbase})"),
            ));
        }
        let nominal_hz = self
            .nominal_hz
            .ok_or_else(|| field("nominal_hz", "missing: the nominal frequency [Hz]".into()))?;
        if !(nominal_hz.is_finite() && nominal_hz > 0.0) {
            return Err(field(
                "nominal_hz",
                format!("must be a finite number > 0 Hz (got {nominal_hz})"),
            ));
        }
        for (k, v) in [("zr", self.zr), ("zx", self.zx)] {
            if let Some(x) = v {
                if !(x.is_finite() && x >= 0.0) {
                    return Err(field(
                        k,
                        format!("must be a finite number >= 0 pu (got {x})"),
                    ));
                }
            }
        }
        Ok(DyrBases {
            mbase,
            nominal_hz,
            zr: self.zr,
            zx: self.zx,
            name: self.name,
        })
    }
}

/// `<stem>.bases.toml` beside a `.dyr`: the side file read by default.
pub fn side_file(dyr: &Path) -> PathBuf {
    let stem = dyr
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    dyr.with_file_name(format!("{stem}.bases.toml"))
}

/// The bases of `dyr`: the side file `side` (else [`side_file`] if it exists) with the values
/// of `over` on top; without a side file, `over` alone (a missing value names the `.dyr`).
pub fn resolve_bases(
    dyr: &Path,
    side: Option<&Path>,
    over: &PartialBases,
) -> Result<DyrBases, DyrError> {
    let default = side_file(dyr);
    let side = side
        .map(Path::to_path_buf)
        .or_else(|| default.is_file().then_some(default));
    match side {
        Some(s) => {
            let text = std::fs::read_to_string(&s).map_err(|source| DyrError::Io {
                path: s.clone(),
                source,
            })?;
            DyrBases::parse(&text, &s, Some(over))
        }
        None => over.clone().finish(dyr),
    }
}

/// A bad `.dyr`, side file or unit. Messages name the file and the line or field.
#[derive(Debug, thiserror::Error)]
pub enum DyrError {
    #[error("{}: cannot read: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// A malformed record.
    #[error("{} line {line}: {msg}", path.display())]
    Syntax {
        path: PathBuf,
        line: usize,
        msg: String,
    },
    /// A record of the selected unit that cannot be used (CON count, refused values).
    #[error("{} line {line}: {model}: {msg}", path.display())]
    Record {
        path: PathBuf,
        line: usize,
        model: String,
        msg: String,
    },
    /// The unit asked for is not in the file, or none was asked for and the file holds several.
    #[error("{}: {msg}", path.display())]
    Selection { path: PathBuf, msg: String },
    /// A base value missing or wrong (side file or command line).
    #[error("{}: {field}: {msg}", path.display())]
    Bases {
        path: PathBuf,
        field: String,
        msg: String,
    },
    /// The blocks do not make a unit.
    #[error("{}: {source}", path.display())]
    Unit { path: PathBuf, source: UnitError },
}

impl DyrError {
    /// Short identifier of the error kind.
    pub fn kind(&self) -> &'static str {
        match self {
            DyrError::Io { .. } => "io",
            DyrError::Syntax { .. } => "syntax",
            DyrError::Record { .. } => "record",
            DyrError::Selection { .. } => "selection",
            DyrError::Bases { .. } => "bases",
            DyrError::Unit { .. } => "unit",
        }
    }
}

/// Something the reader or writer could not carry over, or found implausible.
#[derive(Debug, Clone, PartialEq)]
pub struct DyrWarning {
    /// The file and line it is about (`None` for the whole file or a unit being written).
    pub path: Option<PathBuf>,
    pub line: Option<usize>,
    pub msg: String,
}

impl fmt::Display for DyrWarning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match (&self.path, self.line) {
            (Some(p), Some(l)) => write!(f, "{} line {l}: {}", p.display(), self.msg),
            (Some(p), None) => write!(f, "{}: {}", p.display(), self.msg),
            _ => write!(f, "{}", self.msg),
        }
    }
}

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

/// The PSS/E alias of a canonical parameter of model `m` (for messages).
fn alias_of(m: &DyrModel, name: &str) -> String {
    registry::find(m.name)
        .and_then(|i| {
            let b = i.create();
            b.params()
                .specs()
                .iter()
                .find(|s| s.name == name)
                .map(|s| s.alias.to_string())
        })
        .unwrap_or_else(|| name.to_string())
}

/// A unit written as `.dyr` text and its side file, with what could not be written.
#[derive(Debug, Clone)]
pub struct DyrText {
    pub dyr: String,
    /// The side file (TOML) with MBASE, nominal frequency, ZSORCE R and X.
    pub bases: String,
    pub warnings: Vec<String>,
}

/// Writes `unit` as `.dyr` records for bus `bus`, machine `id`, and the side file of bases.
/// Blocks without a PSS/E record (extensions, `constant_pm`, which is the absence of a governor
/// record) are left out, each named in `warnings` (except `constant_pm`).
pub fn write_dyr(unit: &Unit, bus: i64, id: &str) -> DyrText {
    let mut dyr = String::new();
    let mut warnings = vec![];
    let mut zr = None;
    let mut zx = None;
    for inst in unit.instances() {
        let b = &inst.block;
        let m = dyr_model(b.model()).filter(|m| m.role.section() == inst.name);
        let Some(m) = m else {
            if b.model() != "constant_pm" {
                warnings.push(format!(
                    "block '{}' ({}) has no PSS/E record here: not written",
                    inst.name,
                    b.model()
                ));
            }
            continue;
        };
        let ps = b.params();
        let get = |n: &str| ps.get(ps.index_of(n).expect("canonical parameter"));
        let mut vals: Vec<String> = vec![];
        let rew = inst.rewiring();
        if m.name == "IEEEST" {
            let sig = rew
                .iter()
                .find(|(p, _)| p == "u")
                .map(|(_, s)| s.as_str())
                .unwrap_or("speed");
            let ic = IEEEST_INPUTS
                .iter()
                .find(|(_, s, _)| *s == sig)
                .map(|(c, _, _)| *c);
            match ic {
                Some(c) => vals.push(c.to_string()),
                None => {
                    warnings.push(format!(
                        "IEEEST input wired to '{sig}', which has no PSS/E input code: written as IC = 1 (speed)"
                    ));
                    vals.push("1".into());
                }
            }
            vals.push("0".into());
        }
        for (p, s) in &rew {
            if !(m.name == "IEEEST" && p == "u") {
                warnings.push(format!(
                    "{} port '{p}' rewired to '{s}': PSS/E has no such connection, not written",
                    inst.name
                ));
            }
        }
        for c in m.cons {
            vals.push(fmt_num(get(c)));
        }
        if m.role == Role::Machine {
            zr = Some(get("r_a"));
            if m.name == "GENCLS" {
                zx = Some(get("x_d_prime"));
            } else {
                zx = Some(get("x_d_pp"));
                if matches!(m.name, "GENSAE" | "GENSAL") {
                    let (xd, xq) = (get("x_d_pp"), get("x_q_pp"));
                    if xd != xq {
                        warnings.push(format!(
                            "{}: X''q = {xq} differs from X''d = {xd}; PSS/E has one X'': X''d written, X''q lost",
                            m.name
                        ));
                    }
                }
            }
        }
        for (o, v) in b.options() {
            if !(o == "swing" && v == "pm_over_speed") {
                warnings.push(format!(
                    "{} option {o} = {v} has no PSS/E form: not written",
                    inst.name
                ));
            }
        }
        let _ = write!(dyr, "{bus} '{}' '{id}'", m.name);
        for (k, v) in vals.iter().enumerate() {
            if k % 6 == 0 {
                dyr.push_str("\n   ");
            }
            let _ = write!(dyr, " {v}");
        }
        dyr.push_str(" /\n");
    }
    let mut bases = String::new();
    let _ = writeln!(
        bases,
        "# bases of {} for the .dyr beside (from the power-flow machine record); written by itaipu-calib",
        unit.name
    );
    let _ = writeln!(bases, "name = {}", toml::Value::String(unit.name.clone()));
    let _ = writeln!(bases, "mbase = {}  # MVA", fmt_num(unit.machine_mva));
    let _ = writeln!(bases, "nominal_hz = {}", fmt_num(unit.nominal_hz));
    if let Some(r) = zr {
        let _ = writeln!(
            bases,
            "zr = {}  # ZSORCE R: armature resistance, pu on MBASE",
            fmt_num(r)
        );
    }
    if let Some(x) = zx {
        let _ = writeln!(bases, "zx = {}  # ZSORCE X, pu on MBASE", fmt_num(x));
    }
    DyrText {
        dyr,
        bases,
        warnings,
    }
}

/// Shortest text that reads back to the same `f64`, always with a decimal point or exponent.
fn fmt_num(x: f64) -> String {
    format!("{x:?}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_con_name_is_a_parameter_of_its_model() {
        for m in DYR_MODELS {
            let info = registry::find(m.name).expect(m.name);
            assert_eq!(info.role, m.role, "{}", m.name);
            let b = info.create();
            for c in m.cons {
                assert!(
                    b.params().specs().iter().any(|s| s.name == *c),
                    "{}: {c} is not a parameter",
                    m.name
                );
            }
            let mut cons = m.cons.to_vec();
            cons.sort();
            cons.dedup();
            assert_eq!(cons.len(), m.cons.len(), "{}: a CON twice", m.name);
        }
    }

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

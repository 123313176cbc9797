//! Unit model files (TOML): read and write.
//!
//! ```toml
//! name = "Itaipu 60 Hz unit"
//! description = "free text"
//! lacks = ["…"]        # optional: what the unit lacks of the model it was read from
//!                      # (a .dyr record left out); every report repeats it
//! machine_mva = 737.0
//! nominal_hz = 60.0
//!
//! [machine]            # required
//! model = "GENSAE"
//! swing = "pm_over_speed"   # option (machines): or "pm_is_torque" (ANDES)
//! h = 4.5                   # every parameter by name or PSS/E alias (H, Tpd0, …)
//! # …
//!
//! [exciter]            # optional: without it E_fd stays at E_fd0
//! model = "SEXS"
//! # …
//! [pss]                # optional
//! [governor]           # optional: without it P_m stays at P_m0 (same as model = "constant_pm")
//!
//! # any section may hold a user-defined diagram (see [`crate::diagram`]):
//! # model = "diagram", diagram = "file.toml" or an inline [<section>.diagram] table, then the
//! # diagram's parameter values as keys
//!
//! [[block]]            # any further block, wired by signal names
//! name = "my_filter"
//! model = "…"
//! wiring = { u = "pe" }     # port = signal (any section may rewire its ports)
//! ```
//!
//! Every parameter of a model must be given, except nuisance offsets (`*_offset`), which
//! default to 0. Unknown keys, unknown models and unknown parameters are errors naming the file
//! and the field. A `[calibration]` table is left for the calibrator.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::diagram;
use crate::registry::{self, Role};
use crate::unit::{Unit, UnitError};

/// Sections holding one block each, in state order.
const ROLE_SECTIONS: [&str; 4] = ["machine", "exciter", "pss", "governor"];
/// Top-level tables that belong to other tools.
const FOREIGN_SECTIONS: [&str; 1] = ["calibration"];

/// Error reading a unit file. Messages name the file and the field.
#[derive(Debug, thiserror::Error)]
pub enum UnitFileError {
    #[error("{}: cannot read: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: TOML syntax: {msg}", path.display())]
    Syntax { path: PathBuf, msg: String },
    #[error("{}: {field}: {msg}", path.display())]
    Field {
        path: PathBuf,
        field: String,
        msg: String,
    },
    #[error("{}: {source}", path.display())]
    Unit { path: PathBuf, source: UnitError },
}

impl UnitFileError {
    /// Short identifier of the error kind.
    pub fn kind(&self) -> &'static str {
        match self {
            UnitFileError::Io { .. } => "io",
            UnitFileError::Syntax { .. } => "syntax",
            UnitFileError::Field { .. } => "field",
            UnitFileError::Unit {
                source: UnitError::Model { .. },
                ..
            } => "model",
            UnitFileError::Unit { .. } => "wiring",
        }
    }
}

/// Reads a unit file.
pub fn read_unit(path: &Path) -> Result<Unit, UnitFileError> {
    let text = std::fs::read_to_string(path).map_err(|e| UnitFileError::Io {
        path: path.into(),
        source: e,
    })?;
    parse_unit(&text, path)
}

/// Parses unit-file text; `path` is used in messages.
pub fn parse_unit(text: &str, path: &Path) -> Result<Unit, UnitFileError> {
    let field = |f: &str, msg: String| UnitFileError::Field {
        path: path.into(),
        field: f.to_string(),
        msg,
    };
    let table: toml::Table = text
        .parse()
        .map_err(|e: toml::de::Error| UnitFileError::Syntax {
            path: path.into(),
            msg: e.to_string().trim().replace('\n', " "),
        })?;
    for key in table.keys() {
        let known = [
            "name",
            "description",
            "lacks",
            "machine_mva",
            "nominal_hz",
            "block",
        ];
        if !known.contains(&key.as_str())
            && !ROLE_SECTIONS.contains(&key.as_str())
            && !FOREIGN_SECTIONS.contains(&key.as_str())
        {
            return Err(field(key, "unknown key (expected name, description, lacks, machine_mva, nominal_hz, [machine], [exciter], [pss], [governor], [[block]], [calibration])".into()));
        }
    }
    let name = match table.get("name") {
        Some(toml::Value::String(s)) => s.clone(),
        Some(_) => return Err(field("name", "must be a string".into())),
        None => path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default(),
    };
    let number = |key: &str| -> Result<f64, UnitFileError> {
        match table.get(key) {
            Some(v) => as_f64(v).ok_or_else(|| field(key, "must be a number".into())),
            None => Err(field(key, "missing".into())),
        }
    };
    let machine_mva = number("machine_mva")?;
    if !(machine_mva > 0.0 && machine_mva.is_finite()) {
        return Err(field(
            "machine_mva",
            format!("must be > 0 (got {machine_mva})"),
        ));
    }
    let nominal_hz = number("nominal_hz")?;
    if !(nominal_hz > 0.0 && nominal_hz.is_finite()) {
        return Err(field(
            "nominal_hz",
            format!("must be > 0 (got {nominal_hz})"),
        ));
    }
    let mut unit = Unit::new(&name, machine_mva, nominal_hz);
    if let Some(d) = table.get("description") {
        unit.description = d
            .as_str()
            .ok_or_else(|| field("description", "must be a string".into()))?
            .to_string();
    }
    if let Some(v) = table.get("lacks") {
        let bad = || field("lacks", "must be an array of strings".into());
        for x in v.as_array().ok_or_else(bad)? {
            unit.lacks.push(x.as_str().ok_or_else(bad)?.to_string());
        }
    }
    if !table.contains_key("machine") {
        return Err(field(
            "machine",
            "missing: a unit needs a [machine] section".into(),
        ));
    }
    for section in ROLE_SECTIONS {
        if let Some(v) = table.get(section) {
            let t = v
                .as_table()
                .ok_or_else(|| field(section, "must be a table".into()))?;
            add_block(&mut unit, section, section, t, path)?;
        }
    }
    if let Some(v) = table.get("block") {
        let arr = v
            .as_array()
            .ok_or_else(|| field("block", "must be an array of tables ([[block]])".into()))?;
        for (k, item) in arr.iter().enumerate() {
            let ctx = format!("block[{k}]");
            let t = item
                .as_table()
                .ok_or_else(|| field(&ctx, "must be a table".into()))?;
            let bname = t
                .get("name")
                .and_then(|v| v.as_str())
                .ok_or_else(|| field(&ctx, "needs name = \"...\"".into()))?;
            if ROLE_SECTIONS.contains(&bname) {
                return Err(field(
                    &ctx,
                    format!("name '{bname}' is reserved for the [{bname}] section"),
                ));
            }
            add_block(&mut unit, bname, &ctx, t, path)?;
        }
    }
    // GENCLS has no field winding.
    if let (Some(m), Some(_)) = (unit.block("machine"), unit.block("exciter")) {
        if m.model() == "GENCLS" {
            return Err(field(
                "exciter",
                "GENCLS has no field winding: an exciter cannot be attached".into(),
            ));
        }
    }
    unit.finish().map_err(|e| UnitFileError::Unit {
        path: path.into(),
        source: e,
    })?;
    Ok(unit)
}

fn as_f64(v: &toml::Value) -> Option<f64> {
    match v {
        toml::Value::Float(f) => Some(*f),
        toml::Value::Integer(i) => Some(*i as f64),
        _ => None,
    }
}

fn add_block(
    unit: &mut Unit,
    name: &str,
    ctx: &str,
    t: &toml::Table,
    path: &Path,
) -> Result<(), UnitFileError> {
    let field = |f: String, msg: String| UnitFileError::Field {
        path: path.into(),
        field: f,
        msg,
    };
    let model = t.get("model").and_then(|v| v.as_str()).ok_or_else(|| {
        field(
            format!("{ctx}.model"),
            format!("missing (one of: {}, diagram)", registry::names()),
        )
    })?;
    if model.eq_ignore_ascii_case(diagram::MODEL) {
        if name == "machine" {
            return Err(field(
                format!("{ctx}.model"),
                format!(
                    "the machine is a built-in model (one of the machine models of: {})",
                    registry::names()
                ),
            ));
        }
        let base = path.parent().unwrap_or(Path::new("."));
        let (block, rewire) = build_diagram_block(ctx, t, base, path)?;
        return unit
            .add(name, block, &rewire)
            .map_err(|e| UnitFileError::Unit {
                path: path.into(),
                source: e,
            });
    }
    let info = registry::find(model).ok_or_else(|| {
        field(
            format!("{ctx}.model"),
            format!("unknown model '{model}' (known: {})", registry::names()),
        )
    })?;
    let expected_role = match name {
        "machine" => Some(Role::Machine),
        "exciter" => Some(Role::Exciter),
        "pss" => Some(Role::Pss),
        "governor" => Some(Role::Governor),
        _ => None,
    };
    if let Some(r) = expected_role {
        if info.role != r {
            return Err(field(
                format!("{ctx}.model"),
                format!(
                    "{} is a {} model, not a {} model",
                    info.name,
                    info.role.section(),
                    r.section()
                ),
            ));
        }
    }
    if expected_role.is_none() && info.role == Role::Machine {
        return Err(field(
            format!("{ctx}.model"),
            "a machine goes in the [machine] section".into(),
        ));
    }
    let (block, rewire) = build_block(info, ctx, t).map_err(|(f, msg)| field(f, msg))?;
    unit.add(name, block, &rewire)
        .map_err(|e| UnitFileError::Unit {
            path: path.into(),
            source: e,
        })
}

/// A block built from a table, with its `(port, signal)` rewiring.
pub type BuiltBlock = (Box<dyn crate::block::Block>, Vec<(String, String)>);

/// Builds a user-defined diagram block (`model = "diagram"`) from a unit-file section: the
/// definition from `diagram = "file.toml"` (relative to `base`) or an inline `[….diagram]`
/// table, then the parameter values and `wiring` as for any model. `path` is the unit file,
/// for messages; an error in a definition file names that file.
pub fn build_diagram_block(
    ctx: &str,
    t: &toml::Table,
    base: &Path,
    path: &Path,
) -> Result<BuiltBlock, UnitFileError> {
    let field = |p: &Path, f: String, msg: String| UnitFileError::Field {
        path: p.into(),
        field: f,
        msg,
    };
    let (def_table, def_path, def_ctx) =
        match t.get("diagram") {
            Some(toml::Value::String(file)) => {
                let p = base.join(file);
                let text = std::fs::read_to_string(&p).map_err(|e| UnitFileError::Io {
                    path: p.clone(),
                    source: e,
                })?;
                let tab: toml::Table =
                    text.parse()
                        .map_err(|e: toml::de::Error| UnitFileError::Syntax {
                            path: p.clone(),
                            msg: e.to_string().trim().replace('\n', " "),
                        })?;
                (tab, p, String::new())
            }
            Some(toml::Value::Table(tab)) => {
                (tab.clone(), path.to_path_buf(), format!("{ctx}.diagram."))
            }
            Some(_) => {
                return Err(field(
                    path,
                    format!("{ctx}.diagram"),
                    "must be a file name or a table (the diagram definition)".into(),
                ))
            }
            None => return Err(field(
                path,
                format!("{ctx}.diagram"),
                "missing: a diagram needs diagram = \"file.toml\" or a [<section>.diagram] table"
                    .into(),
            )),
        };
    let d = diagram::from_table(&def_table)
        .map_err(|e| field(&def_path, format!("{def_ctx}{}", e.field), e.msg))?;
    let declared: Vec<bool> = d.def().defaults.iter().map(|x| x.is_some()).collect();
    fill_block(Box::new(d), diagram::MODEL, ctx, t, &|i| declared[i])
        .map_err(|(f, m)| field(path, f, m))
}

/// What [`read_diagram_or_unit`] found in a file.
pub enum DiagramFile {
    /// A diagram definition (a file with `[[block]]` entries and no `[machine]`).
    Definition(Box<diagram::Diagram>),
    /// A unit file.
    Unit(Box<Unit>),
}

/// Reads a diagram definition file, or a unit file (told apart by a `[machine]` table).
pub fn read_diagram_or_unit(path: &Path) -> Result<DiagramFile, UnitFileError> {
    let text = std::fs::read_to_string(path).map_err(|e| UnitFileError::Io {
        path: path.into(),
        source: e,
    })?;
    let table: toml::Table = text
        .parse()
        .map_err(|e: toml::de::Error| UnitFileError::Syntax {
            path: path.into(),
            msg: e.to_string().trim().replace('\n', " "),
        })?;
    if table.contains_key("machine") {
        return parse_unit(&text, path).map(|u| DiagramFile::Unit(Box::new(u)));
    }
    diagram::from_table(&table)
        .map(|d| DiagramFile::Definition(Box::new(d)))
        .map_err(|e| UnitFileError::Field {
            path: path.into(),
            field: e.field,
            msg: e.msg,
        })
}

/// Builds a block from a unit-file table, a registry model or a diagram (the calibrator's
/// replacement blocks). `base` resolves a diagram's definition file.
pub fn build_any_block(ctx: &str, t: &toml::Table, base: &Path) -> Result<BuiltBlock, String> {
    let model = t
        .get("model")
        .and_then(|v| v.as_str())
        .ok_or_else(|| format!("{ctx}: needs model = \"...\""))?;
    if model.eq_ignore_ascii_case(diagram::MODEL) {
        return build_diagram_block(ctx, t, base, &base.join("(spec)")).map_err(|e| e.to_string());
    }
    let info = registry::find(model).ok_or_else(|| {
        format!(
            "{ctx}: unknown model '{model}' (known: {}, diagram)",
            registry::names()
        )
    })?;
    build_block(info, ctx, t).map_err(|(f, m)| format!("{f}: {m}"))
}

/// Builds a block of model `info` from a unit-file table: every parameter (nuisance offsets
/// default to 0), word options, and `wiring`. Errors are `(field, message)`, the field prefixed
/// with `ctx`. Used for unit files and for the calibrator's replacement blocks alike.
pub fn build_block(
    info: &registry::ModelInfo,
    ctx: &str,
    t: &toml::Table,
) -> Result<BuiltBlock, (String, String)> {
    let block = info.create();
    let specs = block.params().specs();
    fill_block(block, info.name, ctx, t, &|i| {
        specs[i].name.ends_with("_offset")
    })
}

/// Sets a block's parameters, options and wiring from a table; `optional(i)` says whether
/// parameter `i` may be omitted (it keeps its current value).
fn fill_block(
    mut block: Box<dyn crate::block::Block>,
    model: &str,
    ctx: &str,
    t: &toml::Table,
    optional: &dyn Fn(usize) -> bool,
) -> Result<BuiltBlock, (String, String)> {
    let mut given = vec![false; block.params().specs().len()];
    let mut rewire = vec![];
    for (key, value) in t {
        let f = format!("{ctx}.{key}");
        match key.as_str() {
            "model" | "name" => {}
            "diagram" if model == diagram::MODEL => {}
            "wiring" => {
                let w = value.as_table().ok_or_else(|| {
                    (
                        f.clone(),
                        "must be a table { port = \"signal\" }".to_string(),
                    )
                })?;
                for (port, sig) in w {
                    let s = sig.as_str().ok_or_else(|| {
                        (format!("{f}.{port}"), "must be a signal name".to_string())
                    })?;
                    rewire.push((port.clone(), s.to_string()));
                }
            }
            _ => match value {
                toml::Value::String(s) => block
                    .set_option(key, s)
                    .map_err(|e| (f.clone(), e.to_string()))?,
                v => {
                    let x = as_f64(v).ok_or_else(|| (f.clone(), "must be a number".to_string()))?;
                    let idx = block.params().index_of(key).ok_or_else(|| {
                        let names: Vec<_> = block.params().specs().iter().map(|s| s.name).collect();
                        (
                            f.clone(),
                            format!(
                                "unknown parameter of {} (parameters: {})",
                                model,
                                names.join(", ")
                            ),
                        )
                    })?;
                    if given[idx] {
                        return Err((f.clone(), "given twice (by name and by alias?)".to_string()));
                    }
                    if !x.is_finite() {
                        return Err((f.clone(), format!("must be finite (got {x})")));
                    }
                    block.params_mut().set(idx, x);
                    given[idx] = true;
                }
            },
        }
    }
    let specs = block.params().specs();
    let missing: Vec<String> = specs
        .iter()
        .zip(&given)
        .enumerate()
        .filter(|(i, (_, g))| !**g && !optional(*i))
        .map(|(_, (s, _))| format!("{} ({}, {} [{}])", s.name, s.alias, s.doc, s.unit))
        .collect();
    if !missing.is_empty() {
        return Err((
            ctx.to_string(),
            format!("{} needs these parameters: {}", model, missing.join("; ")),
        ));
    }
    block.validate().map_err(|e| {
        // A parameter of the block's own table names its field.
        let f = match &e {
            crate::block::ModelError::BadParam { param, .. }
                if block.params().index_of(param).is_some() =>
            {
                format!("{ctx}.{param}")
            }
            _ => ctx.to_string(),
        };
        (f, format!("{model}: {e}"))
    })?;
    Ok((block, rewire))
}

/// Writes a unit as a unit file (every parameter, with its unit and meaning as a comment).
pub fn unit_to_toml(unit: &Unit) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "name = {}", toml_str(&unit.name));
    if !unit.description.is_empty() {
        let _ = writeln!(s, "description = {}", toml_str(&unit.description));
    }
    if !unit.lacks.is_empty() {
        let items: Vec<String> = unit.lacks.iter().map(|l| toml_str(l)).collect();
        let _ = writeln!(s, "lacks = [\n  {},\n]", items.join(",\n  "));
    }
    let _ = writeln!(s, "machine_mva = {:?}", unit.machine_mva);
    let _ = writeln!(s, "nominal_hz = {:?}", unit.nominal_hz);
    for inst in unit.instances() {
        let b = &inst.block;
        s.push('\n');
        if ROLE_SECTIONS.contains(&inst.name.as_str()) {
            let _ = writeln!(s, "[{}]", inst.name);
        } else {
            let _ = writeln!(s, "[[block]]\nname = {}", toml_str(&inst.name));
        }
        let _ = writeln!(s, "model = {}", toml_str(b.model()));
        for (k, v) in b.options() {
            let _ = writeln!(s, "{k} = {}", toml_str(&v));
        }
        let ps = b.params();
        for (i, spec) in ps.specs().iter().enumerate() {
            let _ = writeln!(
                s,
                "{} = {:?}  # {} [{}]",
                spec.name,
                ps.get(i),
                spec.doc,
                spec.unit
            );
        }
        let rew: Vec<String> = b
            .ports()
            .iter()
            .zip(&inst.wiring)
            .filter(|(p, w)| p.signal != w.as_str())
            .map(|(p, w)| format!("{} = {}", p.name, toml_str(w)))
            .collect();
        if !rew.is_empty() {
            let _ = writeln!(s, "wiring = {{ {} }}", rew.join(", "));
        }
        if let Some(d) = b.diagram() {
            // The definition goes inline, so the file stands on its own.
            let prefix = if ROLE_SECTIONS.contains(&inst.name.as_str()) {
                format!("{}.diagram", inst.name)
            } else {
                "block.diagram".to_string()
            };
            s.push('\n');
            write_table(&mut s, &prefix, &d.def().source);
        }
    }
    s
}

/// Writes `table` under the header `[prefix]`: plain keys first, then sub-tables, then arrays
/// of tables (`[[prefix.key]]`), recursively.
fn write_table(s: &mut String, prefix: &str, table: &toml::Table) {
    let _ = writeln!(s, "[{prefix}]");
    write_table_body(s, prefix, table);
}

fn write_table_body(s: &mut String, prefix: &str, table: &toml::Table) {
    let is_array_of_tables = |v: &toml::Value| {
        v.as_array()
            .is_some_and(|a| !a.is_empty() && a.iter().all(|x| x.is_table()))
    };
    for (k, v) in table {
        if !v.is_table() && !is_array_of_tables(v) {
            let _ = writeln!(s, "{} = {}", toml_key(k), v);
        }
    }
    for (k, v) in table {
        if let Some(t) = v.as_table() {
            s.push('\n');
            write_table(s, &format!("{prefix}.{}", toml_key(k)), t);
        }
    }
    for (k, v) in table {
        if is_array_of_tables(v) {
            for item in v.as_array().into_iter().flatten() {
                let p = format!("{prefix}.{}", toml_key(k));
                let _ = writeln!(s, "\n[[{p}]]");
                if let Some(t) = item.as_table() {
                    write_table_body(s, &p, t);
                }
            }
        }
    }
}

fn toml_key(k: &str) -> String {
    if !k.is_empty()
        && k.chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
    {
        k.to_string()
    } else {
        toml_str(k)
    }
}

fn toml_str(s: &str) -> String {
    toml::Value::String(s.to_string()).to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"
name = "u"
machine_mva = 700.0
nominal_hz = 60.0
[machine]
model = "GENCLS"
h = 4.0
d = 0.0
x_d_prime = 0.3
r_a = 0.0
[governor]
model = "constant_pm"
"#;

    fn err(text: &str) -> UnitFileError {
        match parse_unit(text, Path::new("u.toml")) {
            Ok(_) => panic!("accepted:\n{text}"),
            Err(e) => e,
        }
    }

    #[test]
    fn a_minimal_unit_parses_and_round_trips() {
        let u = parse_unit(GOOD, Path::new("u.toml")).unwrap();
        let text = unit_to_toml(&u);
        let v = parse_unit(&text, Path::new("again.toml")).unwrap();
        assert_eq!(
            u.params().iter().map(|p| p.2).collect::<Vec<_>>(),
            v.params().iter().map(|p| p.2).collect::<Vec<_>>()
        );
        // PSS/E aliases are accepted.
        let aliased = GOOD
            .replace("x_d_prime = 0.3", "Xpd = 0.3")
            .replace("h = 4.0", "H = 4.0");
        parse_unit(&aliased, Path::new("u.toml")).unwrap();
    }

    #[test]
    fn each_bad_unit_file_is_refused_naming_file_and_field() {
        let cases: Vec<(&str, String, &str, &str)> = vec![
            ("missing parameter", GOOD.replace("x_d_prime = 0.3\n", ""), "field", "x_d_prime"),
            ("unknown parameter", GOOD.replace("h = 4.0", "h = 4.0\ninertia = 1.0"), "field", "machine.inertia"),
            ("unknown top-level key", GOOD.replace("name = \"u\"", "name = \"u\"\ncolour = \"red\""), "field", "colour"),
            ("unknown model", GOOD.replace("GENCLS", "GENXYZ"), "field", "machine.model"),
            ("model in the wrong section", GOOD.replace("model = \"constant_pm\"", "model = \"SEXS\""), "field", "governor.model"),
            ("no machine", GOOD.replace("[machine]", "[machin]"), "field", "machin"),
            ("parameter given twice", GOOD.replace("h = 4.0", "h = 4.0\nH = 4.0"), "field", "machine"),
            ("not a number", GOOD.replace("h = 4.0", "h = \"four\""), "field", "machine.h"),
            ("zero inertia", GOOD.replace("h = 4.0", "h = 0.0"), "field", "h"),
            ("negative base", GOOD.replace("machine_mva = 700.0", "machine_mva = -1.0"), "field", "machine_mva"),
            ("syntax error", GOOD.replace("h = 4.0", "h = = 4.0"), "syntax", "line"),
            ("rewiring an unknown port", GOOD.replace("model = \"constant_pm\"", "model = \"constant_pm\"\nwiring = { torque = \"pm\" }"), "wiring", "torque"),
            (
                "exciter on GENCLS",
                GOOD.to_string() + "[exciter]\nmodel = \"SEXS\"\nta_tb = 0.1\ntb = 10.0\nk = 100.0\nte = 0.05\ne_min = 0.0\ne_max = 5.0\n",
                "field",
                "no field winding",
            ),
        ];
        for (what, text, kind, mention) in cases {
            let e = err(&text);
            let msg = e.to_string();
            assert_eq!(e.kind(), kind, "{what}: {msg}");
            assert!(msg.starts_with("u.toml"), "{what}: {msg}");
            assert!(
                msg.contains(mention),
                "{what}: '{msg}' should mention {mention}"
            );
        }
    }

    #[test]
    fn an_input_nobody_drives_is_a_wiring_error() {
        let text = GOOD.to_string() + "[pss]\nmodel = \"STAB3\"\nt_t = 0.1\nt_x1 = 0.04\nt_x2 = 3.0\nk_x = 1.0\nv_lim = 0.1\nwiring = { pe = \"p_elec\" }\n";
        let e = err(&text);
        assert_eq!(e.kind(), "wiring");
        assert!(e.to_string().contains("p_elec"), "{e}");
    }
}

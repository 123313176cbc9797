//! Unit model files (TOML): read and write.
//!
//! ```toml
//! name = "Itaipu 60 Hz unit"
//! description = "free text"
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
        let known = ["name", "description", "machine_mva", "nominal_hz", "block"];
        if !known.contains(&key.as_str())
            && !ROLE_SECTIONS.contains(&key.as_str())
            && !FOREIGN_SECTIONS.contains(&key.as_str())
        {
            return Err(field(key, "unknown key (expected name, description, machine_mva, nominal_hz, [machine], [exciter], [pss], [governor], [[block]], [calibration])".into()));
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
            format!("missing (one of: {})", registry::names()),
        )
    })?;
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

/// Builds a block of model `info` from a unit-file table: every parameter (nuisance offsets
/// default to 0), word options, and `wiring`. Errors are `(field, message)`, the field prefixed
/// with `ctx`. Used for unit files and for the calibrator's replacement blocks alike.
pub fn build_block(
    info: &registry::ModelInfo,
    ctx: &str,
    t: &toml::Table,
) -> Result<BuiltBlock, (String, String)> {
    let mut block = info.create();
    let mut given = vec![false; block.params().specs().len()];
    let mut rewire = vec![];
    for (key, value) in t {
        let f = format!("{ctx}.{key}");
        match key.as_str() {
            "model" | "name" => {}
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
                                info.name,
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
        .filter(|(s, g)| !**g && !s.name.ends_with("_offset"))
        .map(|(s, _)| format!("{} ({}, {} [{}])", s.name, s.alias, s.doc, s.unit))
        .collect();
    if !missing.is_empty() {
        return Err((
            ctx.to_string(),
            format!(
                "{} needs these parameters: {}",
                info.name,
                missing.join("; ")
            ),
        ));
    }
    block
        .validate()
        .map_err(|e| (ctx.to_string(), format!("{}: {e}", info.name)))?;
    Ok((block, rewire))
}

/// Writes a unit as a unit file (every parameter, with its unit and meaning as a comment).
pub fn unit_to_toml(unit: &Unit) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "name = {}", toml_str(&unit.name));
    if !unit.description.is_empty() {
        let _ = writeln!(s, "description = {}", toml_str(&unit.description));
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
    }
    s
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

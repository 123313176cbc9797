//! Writing a unit as `.dyr` records and its side file of bases ([`write_dyr`]).

use std::fmt::Write as _;

use super::layout::Icon;
use crate::registry;
use crate::unit::{Instance, Unit};

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
/// record) are left out, each named in `warnings` (except `constant_pm` without offset), as is
/// every parameter the records cannot hold (X''q ≠ X''d, a set-point offset ≠ 0). The list is the
/// writer's view; [`super::write_dyr_checked`] reads the text back and compares, which is the
/// complete list.
pub fn write_dyr(unit: &Unit, bus: i64, id: &str) -> DyrText {
    let mut dyr = String::new();
    let mut warnings = vec![];
    let mut zr = None;
    let mut zx = None;
    for inst in unit.instances() {
        let b = &inst.block;
        let m =
            registry::find(b.model()).filter(|m| m.dyr.is_some() && m.role.section() == inst.name);
        let Some(m) = m else {
            if b.model() != "constant_pm" {
                warnings.push(format!(
                    "block '{}' ({}) has no PSS/E record here: not written",
                    inst.name,
                    b.model()
                ));
            } else {
                // No governor record holds P_m at P_m0: the same as constant_pm without offset.
                not_held(inst, &[], "no governor record", &mut warnings);
            }
            continue;
        };
        let layout = m.dyr.as_ref().expect("filtered");
        let ps = b.params();
        let get = |n: &str| ps.get(ps.index_of(n).expect("canonical parameter"));
        let mut vals: Vec<String> = vec![];
        let rew = inst.rewiring();
        let opts = b.options();
        // The ports an input code writes, the options an ICON holds.
        let mut coded_ports = vec![];
        let mut icon_keys = vec![];
        for icon in layout.icons {
            match icon {
                Icon::Option { key, default, .. } => {
                    icon_keys.push(*key);
                    let v = opts
                        .iter()
                        .find(|(k, _)| k == key)
                        .map(|(_, v)| v.as_str())
                        .unwrap_or(default);
                    vals.push(v.to_string());
                }
                Icon::Input { name, port, codes } => {
                    coded_ports.push(*port);
                    let default = b
                        .ports()
                        .iter()
                        .find(|p| p.name == *port)
                        .map_or(*port, |p| p.signal);
                    let sig = rew
                        .iter()
                        .find(|(p, _)| p == port)
                        .map(|(_, s)| s.as_str())
                        .unwrap_or(default);
                    match codes.iter().find(|c| c.signal == Some(sig)) {
                        Some(c) => vals.push(c.code.to_string()),
                        None => {
                            let first = codes
                                .iter()
                                .find(|c| c.signal == Some(default))
                                .or_else(|| codes.iter().find(|c| c.signal.is_some()))
                                .expect("checked by the registry test");
                            warnings.push(format!(
                                "{} input {port} wired to '{sig}', which has no PSS/E input code: written as {name} = {} ({})",
                                m.name, first.code, first.meaning
                            ));
                            vals.push(first.code.to_string());
                        }
                    }
                }
                Icon::Zero { .. } | Icon::Ignored { .. } => vals.push("0".into()),
            }
        }
        for (p, s) in &rew {
            if !coded_ports.contains(&p.as_str()) {
                warnings.push(format!(
                    "{} port '{p}' rewired to '{s}': PSS/E has no such connection, not written",
                    inst.name
                ));
            }
        }
        for c in layout.cons {
            vals.push(fmt_num(get(c)));
        }
        let mut held: Vec<&str> = layout.cons.to_vec();
        if let Some(mf) = &layout.machine {
            zr = Some(get("r_a"));
            held.push("r_a");
            let zp = mf.zsorce_x.param().expect("a parameter");
            zx = Some(get(zp));
            held.push(zp);
            for t in mf.ties {
                held.push(t.to.0);
                let (a, b) = (get(t.from.0), get(t.to.0));
                if a != b {
                    warnings.push(format!(
                        "{}: {} = {b} differs from {} = {a}; {}: {} written, {} lost",
                        m.name, t.to.1, t.from.1, t.why, t.from.1, t.to.1
                    ));
                }
            }
        }
        // What the record has no CON for and the reader does not set from the bases reads
        // back at the model's default (the nuisance set-point offsets, for instance).
        not_held(
            inst,
            &held,
            &format!("PSS/E's {} record", m.name),
            &mut warnings,
        );
        for (o, v) in &opts {
            if !(icon_keys.contains(o) || *o == "swing" && v == "pm_over_speed") {
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

/// Warns about every parameter of `inst` outside `held` whose value is not the model's default
/// (what the reader gives it): `where_` names what the unit is written as.
fn not_held(inst: &Instance, held: &[&str], where_: &str, warnings: &mut Vec<String>) {
    let b = &inst.block;
    let Some(info) = registry::find(b.model()) else {
        return;
    };
    let fresh = info.create();
    let (ps, d) = (b.params(), fresh.params());
    for (i, spec) in ps.specs().iter().enumerate() {
        if held.contains(&spec.name) || ps.get(i) == d.get(i) {
            continue;
        }
        warnings.push(format!(
            "{}.{} = {} has no place in {where_}: not written (reads back as {})",
            inst.name,
            spec.name,
            ps.get(i),
            d.get(i)
        ));
    }
}

/// Shortest text that reads back to the same `f64`, always with a decimal point or exponent.
fn fmt_num(x: f64) -> String {
    format!("{x:?}")
}

//! Writing a unit as `.dyr` records and its side file of bases ([`write_dyr`]).

use std::fmt::Write as _;

use super::records::{dyr_model, icon_option, IEEEST_INPUTS};
use crate::registry::{self, Role};
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
        let m = dyr_model(b.model()).filter(|m| m.role.section() == inst.name);
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
        } else {
            // ICONs that are block options (ESST1A's UEL and VOS codes).
            let opts = b.options();
            for icon in m.icons {
                let (opt, default) = icon_option(m.name, icon).expect("ICON mapped to an option");
                let v = opts
                    .iter()
                    .find(|(k, _)| *k == opt)
                    .map(|(_, v)| v.as_str())
                    .unwrap_or(default);
                vals.push(v.to_string());
            }
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
        // What the record has no CON for and the reader does not set from the bases reads
        // back at the model's default (the nuisance set-point offsets, for instance).
        let held: Vec<&str> = m
            .cons
            .iter()
            .copied()
            .chain(
                ["r_a", "x_d_prime", "x_q_pp"]
                    .into_iter()
                    .filter(|_| m.role == Role::Machine),
            )
            .collect();
        not_held(
            inst,
            &held,
            &format!("PSS/E's {} record", m.name),
            &mut warnings,
        );
        for (o, v) in b.options() {
            let is_icon = m
                .icons
                .iter()
                .any(|i| icon_option(m.name, i).map(|x| x.0) == Some(o));
            if !(is_icon || o == "swing" && v == "pm_over_speed") {
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

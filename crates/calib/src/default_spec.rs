//! The calibration spec a unit gets when none is given (no `--calib`, no `[calibration]` table
//! in the unit file, a `.dyr` unit): each block's identifiable parameters freed by the roles its
//! model declares, so that no model needs a hand-written list.
//!
//! | stage | block | freed | objective |
//! |---|---|---|---|
//! | `gen` | machine | inertia, synchronous, transient and subtransient reactances and open-circuit time constants the model has (`h`, `x_d`, `x_q`, `x_d_prime`, `x_q_prime`, `x_d_pp`, `t_d0_prime`, `t_q0_prime`, `t_d0_pp`, `t_q0_pp`), in engineering order; PSS/E's single X'' tied | P and Q |
//! | `avr` | exciter | [`ExciterRoles::identifiable`]: gain, integral gain, field time constant, transient gain reduction | Q |
//! | `pss` | stabiliser | [`PssRoles::identifiable`]: gain, washout, input filter, lead-lags | Q |
//! | `tg` | governor | [`GovernorRoles::identifiable`]: droop or its gain, dashpot, servo, turbine and reheat time constants, governor lead-lag | P and Q |
//!
//! Each parameter is freed within its plausible range ([`itaipu_dynamics::params::ParamSpec`])
//! widened to hold its value, starting at its value, with the spec's default prior tying it to
//! the datasheet value. Limits, rate limits, damping and offsets are not freed: they act only
//! when reached, and a limit the record does not reach is not identified (the diagnosis's
//! `exciter_limit` and `governor` causes free them where the record drives them). A parameter
//! at 0 where 0 switches the block's structure (a bypassed time constant, no integral action)
//! is left at 0. A block without roles (a user diagram without `[exciter_roles]`) is left as
//! it is, with a note in the spec.
//!
//! [`ExciterRoles::identifiable`]: itaipu_dynamics::models::exciter::roles::ExciterRoles::identifiable
//! [`PssRoles::identifiable`]: itaipu_dynamics::models::pss::roles::PssRoles::identifiable
//! [`GovernorRoles::identifiable`]: itaipu_dynamics::models::governor::roles::GovernorRoles::identifiable

use std::fmt::Write as _;

use itaipu_dynamics::registry;
use itaipu_dynamics::unit::Unit;

use crate::bounds::FreeBound;

/// The machine parameters the generator stage frees where the model has them, in engineering
/// order (paper 001 Fig. 10: the simplest machine first, the subtransient last). One list for
/// every machine model: they share the canonical names.
pub const MACHINE_IDENTIFIABLE: &[&str] = &[
    "x_d",
    "h",
    "x_d_prime",
    "x_q",
    "x_q_prime",
    "t_d0_prime",
    "t_q0_prime",
    "x_d_pp",
    "t_d0_pp",
    "t_q0_pp",
];

/// The free parameters of each stage (`(stage, block section, parameter paths)`), and notes on
/// the blocks that declare no roles.
pub fn identifiable(unit: &Unit) -> (Vec<(&'static str, Vec<String>)>, Vec<String>) {
    let mut stages = vec![];
    let mut notes = vec![];
    let nonzero = |path: &str| unit.param(path).is_ok_and(|r| unit.get(r) != 0.0);
    for (stage, section) in [
        ("gen", "machine"),
        ("avr", "exciter"),
        ("pss", "pss"),
        ("tg", "governor"),
    ] {
        let Some(b) = unit.block(section) else {
            continue;
        };
        let names: Option<Vec<String>> = match section {
            "machine" => Some(
                MACHINE_IDENTIFIABLE
                    .iter()
                    .filter(|n| b.params().specs().iter().any(|s| s.name == **n))
                    .map(|n| n.to_string())
                    .collect(),
            ),
            "exciter" => b.exciter_roles().map(|r| r.identifiable()),
            "pss" => b.pss_roles().map(|r| r.identifiable()),
            _ => b.governor_roles().map(|r| r.identifiable()),
        };
        match names {
            Some(names) => {
                let paths: Vec<String> = names
                    .iter()
                    .map(|n| format!("{section}.{n}"))
                    .filter(|p| nonzero(p))
                    .collect();
                if !paths.is_empty() {
                    stages.push((stage, paths));
                }
            }
            None => notes.push(format!(
                "{section} ({}) declares no {section} roles: left as it is",
                b.model()
            )),
        }
    }
    (stages, notes)
}

/// The spec as TOML (a `[calibration]` table), the text a fit writes beside its results.
pub fn default_spec_text(unit: &Unit) -> String {
    let (stages, notes) = identifiable(unit);
    let mut s = String::from(
        "# The default calibration spec (itaipu_calib::default_spec): each block's identifiable\n\
         # parameters freed by the roles its model declares, within their plausible ranges\n\
         # widened to hold the unit's values.\n",
    );
    for n in &notes {
        let _ = writeln!(s, "# {n}");
    }
    s.push_str("[calibration]\nstrategy = \"sequential\"\nseed = 1\n");
    // PSS/E's single X'' (the machine record's ties) stays one parameter.
    let ties: Vec<(String, String)> = unit
        .block("machine")
        .and_then(|m| registry::find(m.model()))
        .and_then(|info| info.dyr)
        .and_then(|d| d.machine)
        .map(|m| {
            m.ties
                .iter()
                .map(|t| {
                    (
                        format!("machine.{}", t.to.0),
                        format!("machine.{}", t.from.0),
                    )
                })
                .collect()
        })
        .unwrap_or_default();
    for (stage, params) in stages {
        let objective = if matches!(stage, "avr" | "pss") {
            "q"
        } else {
            "pq"
        };
        let _ = write!(
            s,
            "\n[[calibration.stage]]\nname = \"{stage}\"\nobjective = \"{objective}\"\n"
        );
        if stage == "gen" && !ties.is_empty() {
            let t: Vec<String> = ties
                .iter()
                .map(|(a, b)| format!("\"{a}\" = \"{b}\""))
                .collect();
            let _ = writeln!(s, "tie = {{ {} }}", t.join(", "));
        }
        s.push_str("free = [\n");
        for p in params {
            let Ok(b) = FreeBound::requested(unit, &p, None) else {
                continue;
            };
            let _ = writeln!(
                s,
                "  {{ param = \"{}\", min = {:?}, max = {:?} }},",
                b.param, b.min, b.max
            );
        }
        s.push_str("]\n");
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit(blocks: &[(&str, &str)]) -> Unit {
        let mut u = Unit::new("u", 700.0, 60.0);
        for (name, model) in blocks {
            u.add(name, registry::find(model).unwrap().create(), &[])
                .unwrap();
        }
        u.finish().unwrap();
        u
    }

    #[test]
    fn every_stage_frees_its_block_s_identifiable_roles() {
        let u = unit(&[
            ("machine", "GENROU"),
            ("exciter", "ESST4B"),
            ("pss", "PSS2A"),
            ("governor", "IEEEG1"),
        ]);
        let (stages, notes) = identifiable(&u);
        assert!(notes.is_empty());
        let names: Vec<&str> = stages.iter().map(|s| s.0).collect();
        assert_eq!(names, ["gen", "avr", "pss", "tg"]);
        assert!(stages[0].1.contains(&"machine.x_q_prime".to_string()));
        assert_eq!(stages[1].1, ["exciter.k_pr", "exciter.k_ir", "exciter.t_a"]);
        assert!(stages[2].1.contains(&"pss.ks1".to_string()));
        // IEEEG1's typical T2 is 0 (no lead): left out, the rest by role.
        assert_eq!(
            stages[3].1,
            [
                "governor.k",
                "governor.t3",
                "governor.t4",
                "governor.t5",
                "governor.t1"
            ]
        );
        let spec = crate::spec::CalibSpec::parse(
            &default_spec_text(&u),
            std::path::Path::new("default.toml"),
        )
        .unwrap();
        assert_eq!(spec.stages.len(), 4);
        assert_eq!(spec.stages[1].free[0].param, "exciter.k_pr");
        // The bounds hold the unit's values.
        for s in &spec.stages {
            for f in &s.free {
                let v = u.get(u.param(&f.param).unwrap());
                assert!(f.min <= v && v <= f.max, "{}: {v} outside", f.param);
            }
        }
    }

    #[test]
    fn pss_e_s_single_x_pp_stays_tied() {
        let u = unit(&[("machine", "GENSAE"), ("exciter", "SEXS")]);
        let text = default_spec_text(&u);
        assert!(
            text.contains("tie = { \"machine.x_q_pp\" = \"machine.x_d_pp\" }"),
            "{text}"
        );
        crate::spec::CalibSpec::parse(&text, std::path::Path::new("d.toml")).unwrap();
    }
}

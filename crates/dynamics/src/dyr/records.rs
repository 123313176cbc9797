//! The models the `.dyr` reader and writer know: for each its role, its ICONs and its CONs in
//! PSS/E order as canonical parameter names, and IEEEST's input codes.

use crate::registry::{self, Role};

/// One model the reader and writer know: its role, ICON names and CONs as canonical parameter
/// names of the model's `param_set!` (the one definition of each parameter).
pub(super) struct DyrModel {
    pub(super) name: &'static str,
    pub(super) role: Role,
    pub(super) icons: &'static [&'static str],
    pub(super) cons: &'static [&'static str],
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
        name: "ST5B",
        role: Role::Exciter,
        icons: &[],
        cons: &[
            "t_r", "t_c1", "t_b1", "t_c2", "t_b2", "k_r", "vr_max", "vr_min", "t_1", "k_c",
            "t_uc1", "t_ub1", "t_uc2", "t_ub2", "t_oc1", "t_ob1", "t_oc2", "t_ob2",
        ],
    },
    DyrModel {
        name: "IEEET1",
        role: Role::Exciter,
        icons: &[],
        cons: &[
            "t_r", "k_a", "t_a", "vr_max", "vr_min", "k_e", "t_e", "k_f", "t_f", "switch", "e1",
            "se1", "e2", "se2",
        ],
    },
    DyrModel {
        name: "ESST1A",
        role: Role::Exciter,
        icons: &["UEL", "VOS"],
        cons: &[
            "t_r", "vi_max", "vi_min", "t_c", "t_b", "t_c1", "t_b1", "k_a", "t_a", "va_max",
            "va_min", "vr_max", "vr_min", "k_c", "k_f", "t_f", "k_lr", "i_lr",
        ],
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
pub(super) const IEEEST_INPUTS: &[(i64, &str, &str)] = &[
    (1, "speed", "rotor speed deviation"),
    (3, "pe", "generator electrical power on MBASE"),
    (5, "v_term", "bus voltage"),
];

/// ICONs that are block options, as `(model, ICON, option key, value when the block does not
/// list the option)`: the reader sets the option to the ICON's integer, the writer writes it back.
pub(super) const ICON_OPTIONS: &[(&str, &str, &str, &str)] =
    &[("ESST1A", "UEL", "uel", "1"), ("ESST1A", "VOS", "vos", "1")];

/// The option an ICON of `model` sets, with its default value.
pub(super) fn icon_option(model: &str, icon: &str) -> Option<(&'static str, &'static str)> {
    ICON_OPTIONS
        .iter()
        .find(|(m, i, _, _)| *m == model && *i == icon)
        .map(|(_, _, o, d)| (*o, *d))
}

pub(super) fn dyr_model(name: &str) -> Option<&'static DyrModel> {
    DYR_MODELS
        .iter()
        .find(|m| m.name.eq_ignore_ascii_case(name))
}

/// The models this module reads and writes.
pub fn supported_models() -> Vec<&'static str> {
    DYR_MODELS.iter().map(|m| m.name).collect()
}

/// The PSS/E alias of a canonical parameter of model `m` (for messages).
pub(super) fn alias_of(m: &DyrModel, name: &str) -> String {
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
}

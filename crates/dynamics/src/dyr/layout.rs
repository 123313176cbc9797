//! A model's `.dyr` record layout, declared in the model's file ([`crate::registry::ModelInfo`]):
//! the ICONs (integer flags: option codes, input-signal codes, remote buses) and the CONs in
//! PSS/E's order as canonical parameter names of the model's `param_set!`.
//!
//! The reader ([`super::read`]) and the writer ([`super::write`]) interpret it; neither names a
//! model. Zero time constants, bypassed blocks and the other value conventions belong to the
//! model's equations, not here.

use crate::block::Block;

/// What follows `IBUS 'MODEL' ID` in a model's record.
#[derive(Debug, Clone, Copy)]
pub struct DyrRecord {
    /// The integer fields, in PSS/E's order (they come first).
    pub icons: &'static [Icon],
    /// The real fields in PSS/E's order: canonical parameter names of the model.
    pub cons: &'static [&'static str],
    /// For a machine: the parameters the power-flow record gives and PSS/E's single X''.
    pub machine: Option<MachineFields>,
}

impl DyrRecord {
    /// A record of CONs only.
    pub const fn cons(cons: &'static [&'static str]) -> Self {
        Self {
            icons: &[],
            cons,
            machine: None,
        }
    }

    /// Every CON, tied and ZSORCE parameter is a parameter of `block`, every option ICON an
    /// option it accepts and every input ICON one of its ports; no CON twice (the check a
    /// registry test makes for every model).
    pub fn check(&self, block: &dyn Block) -> Result<(), String> {
        let has = |n: &str| block.params().specs().iter().any(|s| s.name == n);
        for c in self.cons {
            if !has(c) {
                return Err(format!("CON {c} is not a parameter"));
            }
        }
        let mut cons = self.cons.to_vec();
        cons.sort_unstable();
        cons.dedup();
        if cons.len() != self.cons.len() {
            return Err("a CON is listed twice".into());
        }
        for icon in self.icons {
            match icon {
                Icon::Option { name, key, default } => {
                    let mut b = block.clone_box();
                    b.set_option(key, default)
                        .map_err(|e| format!("ICON {name}: option {key} = {default}: {e}"))?;
                }
                Icon::Input { name, port, codes } => {
                    if !block.ports().iter().any(|p| p.name == *port) {
                        return Err(format!("ICON {name}: no port '{port}'"));
                    }
                    if !codes.iter().any(|c| c.signal.is_some()) {
                        return Err(format!("ICON {name}: no code has a signal"));
                    }
                }
                Icon::Zero { .. } | Icon::Ignored { .. } => {}
            }
        }
        if let Some(m) = &self.machine {
            for n in m
                .ties
                .iter()
                .flat_map(|t| [t.to.0, t.from.0])
                .chain(m.zsorce_x.param())
                .chain(["r_a"])
            {
                if !has(n) {
                    return Err(format!("machine field {n} is not a parameter"));
                }
            }
        }
        Ok(())
    }

    /// The number of fields after the machine identifier.
    pub fn len(&self) -> usize {
        self.icons.len() + self.cons.len()
    }

    /// Whether the record has no field at all.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The names of the fields, ICONs then CONs (the CONs by their PSS/E alias), for messages.
    pub fn field_names(&self, block: &dyn Block) -> Vec<String> {
        let alias = |c: &str| {
            block
                .params()
                .specs()
                .iter()
                .find(|s| s.name == c)
                .map_or(c.to_string(), |s| s.alias.to_string())
        };
        self.icons
            .iter()
            .map(|i| i.name().to_string())
            .chain(self.cons.iter().map(|c| alias(c)))
            .collect()
    }
}

/// One integer field (ICON) of a record.
#[derive(Debug, Clone, Copy)]
pub enum Icon {
    /// A block option set to the ICON's integer (ESST1A's UEL code, PSS2A's M): the option
    /// `key`, and the value written when the block does not list the option.
    Option {
        name: &'static str,
        key: &'static str,
        default: &'static str,
    },
    /// An input-signal code: the block's input `port` is wired to the code's signal.
    Input {
        name: &'static str,
        port: &'static str,
        codes: &'static [InputCode],
    },
    /// An integer only 0 is supported for (a remote bus, a second machine): what it is.
    Zero {
        name: &'static str,
        meaning: &'static str,
    },
    /// An integer without effect on this unit (read, written back as 0): what it is.
    Ignored {
        name: &'static str,
        meaning: &'static str,
    },
}

impl Icon {
    pub fn name(&self) -> &'static str {
        match self {
            Icon::Option { name, .. }
            | Icon::Input { name, .. }
            | Icon::Zero { name, .. }
            | Icon::Ignored { name, .. } => name,
        }
    }
}

/// One value of an input-signal ICON.
#[derive(Debug, Clone, Copy)]
pub struct InputCode {
    pub code: i64,
    /// The unit signal it selects (`None`: the engine has no such signal; refused).
    pub signal: Option<&'static str>,
    pub meaning: &'static str,
}

/// PSS/E's stabiliser input codes (IEEEST's IC, PSS2A's ICS1 and ICS2).
pub const STABILISER_INPUTS: &[InputCode] = &[
    InputCode {
        code: 1,
        signal: Some("speed"),
        meaning: "rotor speed deviation",
    },
    InputCode {
        code: 2,
        signal: None,
        meaning: "bus frequency deviation",
    },
    InputCode {
        code: 3,
        signal: Some("pe"),
        meaning: "generator electrical power on MBASE",
    },
    InputCode {
        code: 4,
        signal: None,
        meaning: "generator accelerating power",
    },
    InputCode {
        code: 5,
        signal: Some("v_term"),
        meaning: "bus voltage",
    },
    InputCode {
        code: 6,
        signal: None,
        meaning: "derivative of the bus voltage",
    },
];

/// What a machine record leaves to the power-flow record (ZSORCE), and PSS/E's single X''.
#[derive(Debug, Clone, Copy)]
pub struct MachineFields {
    /// What ZSORCE X is to this model.
    pub zsorce_x: ZsorceX,
    /// Parameters that take another's value (PSS/E has one X''); the writer warns when they
    /// differ.
    pub ties: &'static [Tie],
}

/// A parameter the record does not hold that takes another's value.
#[derive(Debug, Clone, Copy)]
pub struct Tie {
    /// The parameter set (canonical name) and how messages call it (`x_q_pp`, `X''q`).
    pub to: (&'static str, &'static str),
    /// The CON it takes its value from (`x_d_pp`, `X''d`).
    pub from: (&'static str, &'static str),
    /// Why (`PSS/E has one X''`).
    pub why: &'static str,
}

/// PSS/E's single subtransient reactance: X''q takes X''d's value.
pub const ONE_X_PP: Tie = Tie {
    to: ("x_q_pp", "X''q"),
    from: ("x_d_pp", "X''d"),
    why: "PSS/E has one X''",
};

/// What ZSORCE X (the source reactance of the power-flow machine record) is to a machine.
#[derive(Debug, Clone, Copy)]
pub enum ZsorceX {
    /// It sets this parameter (GENCLS's X'd); a read without it is refused.
    Sets(&'static str),
    /// PSS/E expects it equal to this CON (X''): a difference is a warning.
    Equals(&'static str),
}

impl ZsorceX {
    pub fn param(&self) -> Option<&'static str> {
        match self {
            ZsorceX::Sets(p) | ZsorceX::Equals(p) => Some(p),
        }
    }
}

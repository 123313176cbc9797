//! Why a cause is not scored on a unit and its events: the reasons a cause's extension cannot
//! be built there, each rendered as a sentence an engineer reads in the candidates' table.

use itaipu_dynamics::mode::PlaybackMode;
use itaipu_dynamics::registry::{self, Role};

use super::context::{Acts, Context};

/// Why a cause does not apply ([`super::cause::CauseError::NotApplicable`]): to the unit (it
/// lacks the part the cause acts on, or has it in a kind without what the cause needs), to the
/// playback (the mode does not simulate or compare what the cause changes), or to the events
/// (they do not drive the unit into the cause's regime, or leave its search no room).
#[derive(Debug, Clone, PartialEq)]
pub enum NotApplicable {
    /// The unit has no block of `role` (`purpose`: what the cause needs it for).
    NoBlock {
        role: Role,
        purpose: Option<&'static str>,
    },
    /// The unit's block of `role` is of a model without what the cause needs (`lacks`), with
    /// why when the model says (`why`).
    Lacks {
        role: Role,
        model: String,
        lacks: String,
        why: Option<String>,
    },
    /// The block the extension rewires has no such port: the unit's block of that role does not
    /// take the signal the cause acts on (a constant mechanical power reads no speed).
    NoPort {
        instance: String,
        model: String,
        port: String,
    },
    /// A block the extension adds reads a signal no block of the unit writes: the part of the
    /// unit that writes it (`writer`, the role whose blocks write it) is missing.
    Unwritten {
        block: String,
        signal: String,
        writer: Option<Role>,
    },
    /// The extension adds a block under a name the unit already uses.
    NameTaken { name: String },
    /// The extension rewires a block the unit does not have.
    NoInstance { name: String },
    /// The extension frees (or ties, `in_tie`) a parameter the unit does not have.
    NoParam { param: String, in_tie: bool },
    /// A parameter freed by a factor around its value is not positive.
    NotPositive { param: String, value: f64 },
    /// A quantity at the operating point the cause's search range is read against is not
    /// positive (the field current an OEL's rating is read against).
    NotPositiveAtOperatingPoint { quantity: &'static str },
    /// The regulator's ceiling is not positive, so no range of ceilings can be searched.
    RegulatorCeiling { param: String, value: f64 },
    /// The playback mode does not simulate the part the cause acts through.
    NotSimulated { mode: PlaybackMode, acts: Acts },
    /// The playback mode compares nothing the cause's part drives.
    NotCompared { mode: PlaybackMode, acts: Acts },
    /// No event dips |V| (or steps its set point) by `dip` or more: the AVR is not driven to
    /// its limits.
    NoDip { dip: f64 },
    /// No event dips |V| by `dip` or more or raises the field current by `rise` or more: the
    /// field current is not forced into overload.
    NoFieldForcing { dip: f64, rise: f64 },
    /// The search range a cause computes from the operating point, the evidence or the PMU rate
    /// leaves no room (`problem`: what is wrong with it).
    NoRoom { param: String, problem: String },
}

impl Context {
    /// Why a cause acting through `acts` (the unit's parts its extension changes) cannot show in
    /// this playback: the part is not simulated in the mode, or nothing it drives is compared.
    /// `None` when it can show (always in the phasor playback, where every part is simulated
    /// and P and Q are compared).
    ///
    /// The machine in `exciter_alone` is driven by the measured E_fd: its magnetic state
    /// reaches the compared E_fd only through the field current of the exciter's commutation
    /// term (K_C·I_fd), a second-order path that cannot determine a machine parameter, so a
    /// machine cause is not tried there.
    pub fn not_seen(&self, acts: Acts) -> Option<NotApplicable> {
        use itaipu_dynamics::event::Channel::{Efd, Ifd, P, Q, V};
        use itaipu_dynamics::mode::PlaybackMode::*;
        let mode = self.mode;
        let any = |cs: &[itaipu_dynamics::event::Channel]| cs.iter().any(|c| self.compares(*c));
        let compared = match (acts, mode) {
            (_, Phasor) | (Acts::Unstated, _) => return None,
            (Acts::Exciter, MachineFromEfd)
            | (Acts::Machine, ExciterAlone)
            | (Acts::Terminal, ExciterAlone)
            | (Acts::Mechanical, _) => false,
            (Acts::PowerMeasurement, ClosedLoop) if any(&[P, Q]) => return None,
            (Acts::PowerMeasurement, ClosedLoop) => true,
            (Acts::PowerMeasurement, _) => false,
            (Acts::Exciter, _) if !any(&[Efd, V, Q, P, Ifd]) => true,
            (Acts::Terminal, _) if !any(&[P, Q, V]) => true,
            (Acts::ActivePower, _) if !any(&[P]) => true,
            _ => return None,
        };
        Some(if compared {
            NotApplicable::NotCompared { mode, acts }
        } else {
            NotApplicable::NotSimulated { mode, acts }
        })
    }
}

/// How a role reads in a sentence.
fn role_name(role: Role) -> &'static str {
    match role {
        Role::Machine => "machine",
        Role::Exciter => "exciter",
        Role::Pss => "stabiliser (PSS)",
        Role::Governor => "governor",
        Role::Other => "block",
    }
}

/// The role of a library model's block (`Other` for a model not in the registry).
pub(super) fn role_of_model(model: &str) -> Role {
    registry::find(model).map_or(Role::Other, |m| m.role)
}

/// The role whose library blocks write `signal` by default (a PSS writes `vs`, a governor
/// `pm`), if any: what a unit lacks when nothing writes it.
pub(super) fn writer_of(signal: &str) -> Option<Role> {
    registry::MODELS
        .iter()
        .filter(|m| m.role != Role::Other)
        .find(|m| {
            m.create()
                .ports()
                .iter()
                .any(|p| p.dir == itaipu_dynamics::block::Dir::Out && p.signal == signal)
        })
        .map(|m| m.role)
}

impl std::fmt::Display for NotApplicable {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        use NotApplicable::*;
        match self {
            NoBlock { role, purpose } => {
                let purpose = purpose.map_or(String::new(), |p| format!(" {p}"));
                write!(f, "the unit has no {}{purpose}", role_name(*role))
            }
            Lacks {
                role,
                model,
                lacks,
                why,
            } => {
                let why = why.as_ref().map_or(String::new(), |w| format!(": {w}"));
                write!(f, "{} {model} has no {lacks}{why}", role.section())
            }
            NoPort {
                instance,
                model,
                port,
            } => f.write_str(&no_port(instance, model, port)),
            Unwritten {
                block,
                signal,
                writer,
            } => f.write_str(&unwritten(block, signal, *writer)),
            NameTaken { name } => write!(f, "the unit already has a block named '{name}'"),
            NoInstance { name } => write!(f, "the unit has no block named '{name}' to rewire"),
            NoParam { param, in_tie } => {
                let tie = if *in_tie { "tie: " } else { "" };
                write!(f, "{tie}the unit has no parameter '{param}'")
            }
            NotPositive { param, value } => write!(
                f,
                "{param} = {value} is not > 0, so it cannot be freed by a factor"
            ),
            NotPositiveAtOperatingPoint { quantity } => {
                write!(f, "the {quantity} at the operating point is not positive")
            }
            RegulatorCeiling { param, value } => {
                write!(f, "the regulator ceiling {param} = {value} is not positive")
            }
            NotSimulated { mode, acts } => f.write_str(&not_simulated(*mode, *acts)),
            NotCompared { mode, acts } => f.write_str(&not_compared(*mode, *acts)),
            NoDip { dip } => write!(
                f,
                "no event dips |V| (or steps its set point) by {:.0} % or more, so the AVR is not \
                 driven to its limits",
                100.0 * dip
            ),
            NoFieldForcing { dip, rise } => write!(
                f,
                "no event dips |V| (or steps its set point) by {:.0} % or more or raises the field \
                 current by {:.0} % or more, \
                 so the field current is not forced into overload",
                100.0 * dip,
                100.0 * rise
            ),
            NoRoom { param, problem } => write!(
                f,
                "no search range for {param} at this operating point: {problem}"
            ),
        }
    }
}

/// The rewired block `instance` (a `model`) has no port `port`: for a block of a role (a
/// governor of constant mechanical power reads no speed), the unit has no such part.
fn no_port(instance: &str, model: &str, port: &str) -> String {
    let role = role_of_model(model);
    let summary = registry::find(model).map_or(String::new(), |m| format!(": {}", m.summary));
    match role {
        Role::Other => format!(
            "the unit's block '{instance}' ({model}) has no port '{port}' for the extension to \
             rewire"
        ),
        _ => format!(
            "the unit has no {} that reads '{port}' (its {} is {model}{summary})",
            role_name(role),
            role_name(role)
        ),
    }
}

/// The extension's `block` reads `signal`, which nothing in the unit writes (`writer`: the role
/// whose blocks write it, the part the unit lacks).
fn unwritten(block: &str, signal: &str, writer: Option<Role>) -> String {
    match writer {
        Some(role) => format!(
            "the unit has no {}: nothing writes the signal '{signal}' that the extension's \
             block '{block}' reads",
            role_name(role)
        ),
        None => format!(
            "nothing in the unit writes the signal '{signal}' that the extension's block \
             '{block}' reads"
        ),
    }
}

/// Why mode `m` does not simulate what a cause acting through `acts` changes.
fn not_simulated(m: PlaybackMode, acts: Acts) -> String {
    match acts {
        Acts::Exciter => format!(
            "in mode {m} the measured E_fd drives the machine: the exciter is not simulated"
        ),
        Acts::Machine => format!(
            "in mode {m} the measured E_fd drives the machine, which reaches the compared \
             E_fd only through the field current of the commutation term"
        ),
        Acts::Terminal => format!(
            "in mode {m} the measured |V| is imposed and only E_fd is compared: a load at \
             the terminal changes neither"
        ),
        Acts::PowerMeasurement => {
            format!("mode {m} does not model the measuring device's P and Q against its voltage")
        }
        Acts::Mechanical => format!(
            "in mode {m} the mechanical side is not exercised (P is imposed, or the grid \
             equivalent's frequency is held)"
        ),
        Acts::ActivePower | Acts::Unstated => format!("mode {m} does not simulate it"),
    }
}

/// Why mode `m` compares nothing a cause acting through `acts` drives.
fn not_compared(m: PlaybackMode, acts: Acts) -> String {
    match acts {
        Acts::Exciter => format!("mode {m} compares nothing the exciter drives"),
        Acts::Terminal => format!("mode {m} compares neither P, Q nor |V|"),
        Acts::PowerMeasurement => format!("mode {m} compares neither P nor Q"),
        Acts::ActivePower => format!("mode {m} does not compare P, where the cause shows"),
        Acts::Machine | Acts::Mechanical | Acts::Unstated => {
            format!("mode {m} compares nothing the cause drives")
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The part a unit lacks reads as that part: a missing stabiliser is named from the signal
    /// nothing writes (`vs`, a PSS's output), a governor that reads no speed from its model.
    #[test]
    fn a_missing_part_is_named_by_its_role() {
        assert_eq!(writer_of("vs"), Some(Role::Pss));
        assert_eq!(writer_of("no_such_signal"), None);
        let pss = NotApplicable::Unwritten {
            block: "pss_comp".into(),
            signal: "vs".into(),
            writer: writer_of("vs"),
        };
        assert!(
            pss.to_string()
                .starts_with("the unit has no stabiliser (PSS)"),
            "{pss}"
        );
        let gov = NotApplicable::NoPort {
            instance: "governor".into(),
            model: "constant_pm".into(),
            port: "speed".into(),
        };
        let text = gov.to_string();
        assert!(text.starts_with("the unit has no governor"), "{text}");
        assert!(text.contains("constant_pm"), "{text}");
    }
}

//! Recognising columns and channels by name (role, phasor part, unit) and assigning them to
//! the voltage, current and frequency slots (see the table in the `pmu_import` module
//! documentation).

/// Which quantity a column or channel holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Role {
    V(Part),
    I(Part),
    Freq,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Part {
    Mag,
    Ang,
    Re,
    Im,
}

/// Unit of a column, as a factor to a base: kV (voltages), kA (currents), rad, Hz, or pu.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum ChanUnit {
    /// Multiply by this to get kV, kA, rad or Hz.
    Physical(f64),
    Pu,
}

/// A recognised channel: role, rank (0 positive sequence, 1 phase A), unit if stated.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Recognised {
    pub role: Role,
    pub rank: u8,
    pub unit: Option<ChanUnit>,
}

fn unit_word(w: &str) -> Option<(&'static str, ChanUnit)> {
    Some(match w {
        "kv" => ("kV", ChanUnit::Physical(1.0)),
        "v" | "volt" | "volts" => ("V", ChanUnit::Physical(1e-3)),
        "a" | "amp" | "amps" => ("A", ChanUnit::Physical(1e-3)),
        "ka" => ("kA", ChanUnit::Physical(1.0)),
        "pu" | "p.u." => ("pu", ChanUnit::Pu),
        "deg" | "degree" | "degrees" => ("deg", ChanUnit::Physical(std::f64::consts::PI / 180.0)),
        "rad" | "radian" | "radians" => ("rad", ChanUnit::Physical(1.0)),
        "hz" => ("Hz", ChanUnit::Physical(1.0)),
        _ => return None,
    })
}

/// Splits a name into lower-case words; a bracketed or parenthesised tail is the unit.
fn words(name: &str) -> (Vec<String>, Option<String>) {
    let mut base = name.trim().to_ascii_lowercase();
    let mut unit = None;
    for (o, c) in [('[', ']'), ('(', ')')] {
        if let (Some(a), true) = (base.find(o), base.ends_with(c)) {
            unit = Some(base[a + 1..base.len() - 1].trim().to_string());
            base = base[..a].to_string();
        }
    }
    let w: Vec<String> = base
        .split(|ch: char| ch == '_' || ch == '.' || ch == '-' || ch.is_whitespace())
        .filter(|s| !s.is_empty())
        .map(|s| s.to_string())
        .collect();
    (w, unit)
}

/// Recognises a column or channel name; `Ok(None)` for a name that is none of the roles.
/// A unit word that does not fit the role is an error message.
pub(crate) fn recognise(name: &str) -> Result<Option<Recognised>, String> {
    let (mut w, bracket) = words(name);
    let mut unit_text = bracket;
    if unit_text.is_none() && w.len() >= 2 && unit_word(w.last().expect("len")).is_some() {
        unit_text = w.pop();
    }
    let unit = match &unit_text {
        None => None,
        Some(u) => Some(
            unit_word(u)
                .ok_or_else(|| format!("unknown unit '{u}' (kV, V, A, kA, pu, deg, rad, Hz)"))?,
        ),
    };
    let role_rank = match w.as_slice() {
        [f] if f == "freq" || f == "frequency" || f == "f" => Some((Role::Freq, 0)),
        [k, p] => {
            let part = match p.as_str() {
                "mag" | "magnitude" | "abs" => Some(Part::Mag),
                "ang" | "angle" | "phase" => Some(Part::Ang),
                "re" | "real" => Some(Part::Re),
                "im" | "imag" => Some(Part::Im),
                _ => None,
            };
            match (k.as_str(), part) {
                ("v" | "v1" | "vpos" | "u" | "u1", Some(p)) => Some((Role::V(p), 0)),
                ("va" | "ua", Some(p)) => Some((Role::V(p), 1)),
                ("i" | "i1" | "ipos", Some(p)) => Some((Role::I(p), 0)),
                ("ia", Some(p)) => Some((Role::I(p), 1)),
                _ => None,
            }
        }
        _ => None,
    };
    let Some((role, rank)) = role_rank else {
        return Ok(None);
    };
    if let Some((label, u)) = unit {
        let fits = match role {
            Role::V(Part::Ang) | Role::I(Part::Ang) => matches!(label, "deg" | "rad"),
            Role::V(_) => matches!(label, "kV" | "V" | "pu"),
            Role::I(_) => matches!(label, "kA" | "A" | "pu"),
            Role::Freq => label == "Hz",
        };
        if !fits {
            return Err(format!("unit {label} does not fit this quantity"));
        }
        return Ok(Some(Recognised {
            role,
            rank,
            unit: Some(u),
        }));
    }
    Ok(Some(Recognised {
        role,
        rank,
        unit: None,
    }))
}

/// The name a column or channel is read as: its `map` entry's name, or its own.
pub(crate) fn mapped<'a>(map: &'a [(String, String)], name: &'a str) -> &'a str {
    map.iter()
        .find(|(_, col)| col.trim().eq_ignore_ascii_case(name.trim()))
        .map(|(n, _)| n.as_str())
        .unwrap_or(name)
}

/// A channel that could fill a role: (index, rank, unit, name).
type Candidate = (usize, u8, Option<ChanUnit>, String);

/// Which source channel feeds each part of the phasors.
#[derive(Debug, Clone, Default)]
pub(crate) struct Assignment {
    /// (index, unit, name) per slot: V mag/ang/re/im, I mag/ang/re/im, freq.
    pub slots: [Option<(usize, ChanUnit, String)>; 9],
    pub phase_a: bool,
}

fn slot(role: Role) -> usize {
    let p = |p: Part| match p {
        Part::Mag => 0,
        Part::Ang => 1,
        Part::Re => 2,
        Part::Im => 3,
    };
    match role {
        Role::V(x) => p(x),
        Role::I(x) => 4 + p(x),
        Role::Freq => 8,
    }
}

const SLOT_NAMES: [&str; 9] = [
    "v_mag", "v_ang", "v_re", "v_im", "i_mag", "i_ang", "i_re", "i_im", "freq",
];

/// Assigns named channels (`(index, name, unit from the source if any)`) to roles. The best
/// rank wins; two channels of the same rank for one role are an error; the rest are listed in
/// `ignored`. Errors are messages for the caller to locate.
pub(crate) fn assign(
    names: &[(usize, String, Option<String>)],
    map: &[(String, String)],
    ignored: &mut Vec<String>,
) -> Result<Assignment, String> {
    for (n, col) in map {
        if !names
            .iter()
            .any(|(_, name, _)| name.trim().eq_ignore_ascii_case(col.trim()))
        {
            return Err(format!("map {n}={col}: no column or channel named '{col}'"));
        }
    }
    let mut best: [Vec<Candidate>; 9] = Default::default();
    for (idx, name, src_unit) in names {
        let as_name = mapped(map, name);
        let rec = recognise(as_name).map_err(|m| format!("'{name}': {m}"))?;
        let Some(mut r) = rec else {
            ignored.push(name.clone());
            continue;
        };
        if r.unit.is_none() {
            if let Some(u) = src_unit {
                let u = u.trim().to_ascii_lowercase();
                if !u.is_empty() {
                    let full = format!("{}_{}", SLOT_NAMES[slot(r.role)], u);
                    r.unit = recognise(&full)
                        .map_err(|m| format!("'{name}' [{u}]: {m}"))?
                        .and_then(|x| x.unit);
                }
            }
        }
        best[slot(r.role)].push((*idx, r.rank, r.unit, name.clone()));
    }
    let mut a = Assignment::default();
    for (s, cands) in best.iter().enumerate() {
        let Some(top) = cands.iter().map(|c| c.1).min() else {
            continue;
        };
        let chosen: Vec<_> = cands.iter().filter(|c| c.1 == top).collect();
        if chosen.len() > 1 {
            return Err(format!(
                "{} columns could be {}: {}; rename one with map",
                chosen.len(),
                SLOT_NAMES[s],
                chosen
                    .iter()
                    .map(|c| c.3.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
        for c in cands.iter().filter(|c| c.1 != top) {
            ignored.push(c.3.clone());
        }
        let c = chosen[0];
        let unit = match (c.2, s) {
            (Some(u), _) => u,
            (None, 8) => ChanUnit::Physical(1.0), // frequency in Hz
            (None, _) => {
                return Err(format!(
                    "'{}' ({}): no unit; say it in the name ({}_kv, {} [deg], …) or the channel's unit field",
                    c.3, SLOT_NAMES[s], SLOT_NAMES[s], SLOT_NAMES[s]
                ))
            }
        };
        if top == 1 && s != 8 {
            a.phase_a = true;
        }
        a.slots[s] = Some((c.0, unit, c.3.clone()));
    }
    for (k, what) in [(0usize, "voltage"), (4, "current")] {
        let polar = a.slots[k].is_some() && a.slots[k + 1].is_some();
        let rect = a.slots[k + 2].is_some() && a.slots[k + 3].is_some();
        if polar == rect {
            let have: Vec<&str> = (k..k + 4)
                .filter(|&j| a.slots[j].is_some())
                .map(|j| SLOT_NAMES[j])
                .collect();
            return Err(format!(
                "the {what} phasor needs magnitude and angle or real and imaginary parts, exactly one form (found: {})",
                if have.is_empty() { "none".to_string() } else { have.join(", ") }
            ));
        }
    }
    Ok(a)
}

impl Assignment {
    /// Human-readable list of the channels used.
    pub fn describe(&self) -> Vec<String> {
        self.slots
            .iter()
            .enumerate()
            .filter_map(|(s, x)| {
                x.as_ref()
                    .map(|(_, _, n)| format!("{} <- {n}", SLOT_NAMES[s]))
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_recognised_with_their_units() {
        let r = recognise("V1.MAG [kV]").unwrap().unwrap();
        assert_eq!(
            (r.role, r.rank, r.unit),
            (Role::V(Part::Mag), 0, Some(ChanUnit::Physical(1.0)))
        );
        let r = recognise("ia_ang_deg").unwrap().unwrap();
        assert_eq!((r.role, r.rank), (Role::I(Part::Ang), 1));
        assert_eq!(recognise("Frequency").unwrap().unwrap().role, Role::Freq);
        assert!(recognise("vb_mag_kv").unwrap().is_none());
        assert!(recognise("v_mag_ka").is_err());
    }
}

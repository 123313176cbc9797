//! Faithful round trips: a unit is written as `.dyr` only if the `.dyr` read back is the unit.
//!
//! [`write_dyr_checked`] writes the records ([`super::write_dyr`]), reads them back with the
//! reader every `--unit` uses ([`super::parse_dyr`]) and compares the two units:
//!
//! - **parameter by parameter** (always): every parameter, option, port wiring and block of the
//!   unit that the `.dyr` does not give back is a [`Loss`] with the value written and why the
//!   record cannot hold it (PSS/E's GENSAE and GENSAL have one X''; a set-point offset is no
//!   CON; an extension block has no record; …);
//! - **by simulation** (given events): both are played back on each event and the worst |ΔP|
//!   and |ΔQ| (system base, every sample) and the objective J of each (Σ ΔP² + ΔQ² over the fit
//!   window, as `simulate` prints it) are reported ([`EventCheck`]).
//!
//! The rule ([`DyrWrite::faithful`]): with events, the written model must reproduce the unit
//! within [`ROUND_TRIP_TOL_PU`] on every event; without, nothing may be lost.
//! [`write_dyr_file`] writes the two files only then (or when asked to write a lossy `.dyr`),
//! never over an existing file unless forced, and both or neither (temporary files renamed into
//! place). The plausibility checks of a unit being read ([`crate::plausibility::check_unit`])
//! run on the unit as written, so that a `.dyr` does not only warn once it is read back.

use std::fmt;
use std::path::{Path, PathBuf};

use super::{parse_dyr, side_file, write_dyr, DyrBases, DyrError};
use crate::event::Event;
use crate::plausibility::{self, Finding};
use crate::simulate::{simulate_pq, PreparedEvent, SimError, SimOptions};
use crate::unit::{Instance, Unit};

/// Largest |ΔP| or |ΔQ| [pu, system base] between the unit and its `.dyr` read back for the
/// round trip to count as faithful.
pub const ROUND_TRIP_TOL_PU: f64 = 1e-6;

/// Something of the unit that the written `.dyr` does not give back.
#[derive(Debug, Clone, PartialEq)]
pub struct Loss {
    /// A parameter (`machine.x_q_pp`), a block (`block 'shaft'`), an option
    /// (`machine option swing`) or a port (`pss port u`).
    pub what: String,
    /// Its value in the unit.
    pub unit: String,
    /// What the `.dyr` gives back (`absent` for a block without record).
    pub written: String,
    /// Why the record cannot hold it.
    pub why: String,
}

impl fmt::Display for Loss {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} = {}, written {} ({})",
            self.what, self.unit, self.written, self.why
        )
    }
}

/// The unit and its `.dyr` read back, played back on one event.
#[derive(Debug, Clone, PartialEq)]
pub struct EventCheck {
    pub event: String,
    /// J = Σ ΔP² + ΔQ² over the event's fit window (system base) of the unit.
    pub j_unit: f64,
    /// The same for the `.dyr` read back (`None` if it failed on the event: see `failure`).
    pub j_written: Option<f64>,
    /// Worst |ΔP| and |ΔQ| between the two simulations over every sample [pu, system base]
    /// (infinite if the written model failed).
    pub max_dp: f64,
    pub max_dq: f64,
    /// Why the written model could not be simulated on the event.
    pub failure: Option<String>,
}

impl EventCheck {
    /// Whether the written model reproduces the unit within `tol` on this event.
    pub fn within(&self, tol: f64) -> bool {
        self.failure.is_none() && self.max_dp <= tol && self.max_dq <= tol
    }
}

impl fmt::Display for EventCheck {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match (&self.failure, self.j_written) {
            (Some(why), _) => write!(
                f,
                "on {}: J = {:.4} for the unit; the .dyr read back fails: {why}",
                self.event, self.j_unit
            ),
            (None, jw) => write!(
                f,
                "on {}: J = {:.4} for the unit, J = {:.4} for the .dyr read back (worst |ΔP| {:.3e} pu, |ΔQ| {:.3e} pu)",
                self.event,
                self.j_unit,
                jw.unwrap_or(f64::NAN),
                self.max_dp,
                self.max_dq
            ),
        }
    }
}

/// A unit written as `.dyr`, read back and compared ([`write_dyr_checked`]).
#[derive(Debug, Clone)]
pub struct DyrWrite {
    /// The records.
    pub dyr: String,
    /// The side file of bases (TOML).
    pub bases: String,
    /// What the `.dyr` does not give back (empty: every parameter, option, wiring and block).
    pub lost: Vec<Loss>,
    /// What reading the `.dyr` back reported (warnings of the reader).
    pub notes: Vec<String>,
    /// Plausibility of the unit as written: the checks a unit gets when it is read.
    pub findings: Vec<Finding>,
    /// One comparison per event (empty: parameters compared only).
    pub events: Vec<EventCheck>,
    /// The tolerance of the rule [pu].
    pub tolerance_pu: f64,
}

impl DyrWrite {
    /// The rule: with events, the `.dyr` read back reproduces the unit within the tolerance on
    /// every one; without events, nothing is lost.
    pub fn faithful(&self) -> bool {
        if self.events.is_empty() {
            self.lost.is_empty()
        } else {
            self.events.iter().all(|e| e.within(self.tolerance_pu))
        }
    }

    /// What the comparison found: each event's J for both and the worst differences, or,
    /// without events, that the parameters were compared.
    pub fn comparison(&self) -> String {
        if self.events.is_empty() {
            return format!(
                "parameters compared (no event to play back): {}",
                if self.lost.is_empty() {
                    "every one written"
                } else {
                    "some not written"
                }
            );
        }
        let mut parts: Vec<String> = self.events.iter().map(|e| e.to_string()).collect();
        parts.push(format!("tolerance {:e} pu", self.tolerance_pu));
        parts.join("; ")
    }

    /// [`DyrWrite::comparison`] and what is lost, in one paragraph.
    pub fn summary(&self) -> String {
        let mut s = self.comparison();
        if self.lost.is_empty() {
            if !self.faithful() {
                s.push_str(
                    "; no parameter differs: the difference comes from the writer or the reader",
                );
            }
        } else {
            s.push_str("; lost: ");
            s.push_str(
                &self
                    .lost
                    .iter()
                    .map(|l| l.to_string())
                    .collect::<Vec<_>>()
                    .join("; "),
            );
        }
        s
    }
}

/// Why a `.dyr` was not written.
#[derive(Debug, thiserror::Error)]
pub enum DyrWriteError {
    /// The output or its side file exists and overwriting was not asked for.
    #[error("{} exists; refusing to overwrite", path.display())]
    Exists { path: PathBuf },
    /// The `.dyr` would not be the unit (and a lossy write was not asked for).
    #[error("refusing to write {}: the .dyr read back is not the unit: {}", path.display(), report.summary())]
    Unfaithful {
        path: PathBuf,
        report: Box<DyrWrite>,
    },
    /// The unit itself does not simulate on an event (nothing to compare with).
    #[error("event '{event}': the unit: {source}")]
    Simulation { event: String, source: SimError },
    /// The written text does not read back (a writer bug, or a unit the reader refuses, such
    /// as GENCLS with an exciter).
    #[error("the written .dyr does not read back: {0}")]
    ReadBack(DyrError),
    #[error("cannot write {}: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
}

impl DyrWriteError {
    /// Short identifier of the error kind.
    pub fn kind(&self) -> &'static str {
        match self {
            DyrWriteError::Exists { .. } => "exists",
            DyrWriteError::Unfaithful { .. } => "lossy",
            DyrWriteError::Simulation { source, .. } => source.kind(),
            DyrWriteError::ReadBack(_) => "read_back",
            DyrWriteError::Io { .. } => "io",
        }
    }
}

/// Options of [`write_dyr_file`].
#[derive(Debug, Clone)]
pub struct DyrWriteOptions {
    /// Bus number and machine identifier of the records.
    pub bus: i64,
    pub id: String,
    /// Write even when the `.dyr` is not the unit.
    pub lossy: bool,
    /// Replace existing files.
    pub force: bool,
    /// The simulations of the comparison.
    pub sim: SimOptions,
    /// The rule's tolerance [pu].
    pub tolerance_pu: f64,
}

impl Default for DyrWriteOptions {
    fn default() -> Self {
        Self {
            bus: 1,
            id: "1".into(),
            lossy: false,
            force: false,
            sim: SimOptions::default(),
            tolerance_pu: ROUND_TRIP_TOL_PU,
        }
    }
}

/// Writes `unit` as `.dyr` records for `bus`, `id`, reads them back and compares (see the
/// module documentation); `path` names the `.dyr` in the findings and in the reader's messages
/// (nothing is written). An `Err` only when there is nothing to compare: the text does not read
/// back, or the unit itself fails on an event.
pub fn write_dyr_checked(
    unit: &Unit,
    bus: i64,
    id: &str,
    events: &[Event],
    sim: &SimOptions,
    tolerance_pu: f64,
    path: &Path,
) -> Result<DyrWrite, DyrWriteError> {
    let text = write_dyr(unit, bus, id);
    let side = side_file(path);
    let bases = DyrBases::parse(&text.bases, &side, None).map_err(DyrWriteError::ReadBack)?;
    let back =
        parse_dyr(&text.dyr, path, Some((bus, id)), &bases).map_err(DyrWriteError::ReadBack)?;
    let lost = compare(unit, &back.unit);
    let findings = plausibility::check_unit(&back.unit, path);
    let mut checks = vec![];
    for event in events {
        let ev = PreparedEvent::new(event);
        let (p0, q0) = simulate_pq(&mut unit.clone(), &ev, sim).map_err(|source| {
            DyrWriteError::Simulation {
                event: event.name.clone(),
                source,
            }
        })?;
        let j_unit = fit_window_j(event, &p0, &q0);
        checks.push(match simulate_pq(&mut back.unit.clone(), &ev, sim) {
            Ok((p1, q1)) => EventCheck {
                event: event.name.clone(),
                j_unit,
                j_written: Some(fit_window_j(event, &p1, &q1)),
                max_dp: worst(&p0, &p1),
                max_dq: worst(&q0, &q1),
                failure: None,
            },
            Err(e) => EventCheck {
                event: event.name.clone(),
                j_unit,
                j_written: None,
                max_dp: f64::INFINITY,
                max_dq: f64::INFINITY,
                failure: Some(e.to_string()),
            },
        });
    }
    Ok(DyrWrite {
        dyr: text.dyr,
        bases: text.bases,
        lost,
        notes: back.warnings.iter().map(|w| w.to_string()).collect(),
        findings,
        events: checks,
        tolerance_pu,
    })
}

/// [`write_dyr_checked`], then writes the `.dyr` to `out` and its bases beside it
/// ([`side_file`]) if the round trip is faithful or `opts.lossy`; refuses existing files unless
/// `opts.force` (checked before the comparison). Both files or neither: each is written to a
/// temporary file beside it first, then renamed into place.
pub fn write_dyr_file(
    unit: &Unit,
    out: &Path,
    events: &[Event],
    opts: &DyrWriteOptions,
) -> Result<DyrWrite, DyrWriteError> {
    let side = side_file(out);
    if !opts.force {
        for p in [out, side.as_path()] {
            if p.exists() {
                return Err(DyrWriteError::Exists { path: p.into() });
            }
        }
    }
    let w = write_dyr_checked(
        unit,
        opts.bus,
        &opts.id,
        events,
        &opts.sim,
        opts.tolerance_pu,
        out,
    )?;
    if !w.faithful() && !opts.lossy {
        return Err(DyrWriteError::Unfaithful {
            path: out.into(),
            report: Box::new(w),
        });
    }
    write_both(&[(out, &w.dyr), (&side, &w.bases)])?;
    Ok(w)
}

/// Writes every file to `.<name>.partial-<pid>` beside it, then renames them all into place;
/// on a failure the temporary files are removed and no target is touched before every
/// temporary file is complete.
fn write_both(files: &[(&Path, &String)]) -> Result<(), DyrWriteError> {
    let tmp = |p: &Path| {
        let name = p
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        p.with_file_name(format!(".{name}.partial-{}", std::process::id()))
    };
    let mut written: Vec<PathBuf> = vec![];
    let cleanup = |w: &[PathBuf]| {
        for t in w {
            let _ = std::fs::remove_file(t);
        }
    };
    for (p, text) in files {
        let t = tmp(p);
        if let Err(source) = std::fs::write(&t, text.as_bytes()) {
            cleanup(&written);
            let _ = std::fs::remove_file(&t);
            return Err(DyrWriteError::Io {
                path: p.to_path_buf(),
                source,
            });
        }
        written.push(t);
    }
    for (k, (p, _)) in files.iter().enumerate() {
        if let Err(source) = std::fs::rename(&written[k], p) {
            cleanup(&written[k..]);
            return Err(DyrWriteError::Io {
                path: p.to_path_buf(),
                source,
            });
        }
    }
    Ok(())
}

/// J = Σ ΔP² + ΔQ² over the event's fit window (the misfit `simulate` prints).
fn fit_window_j(event: &Event, p: &[f64], q: &[f64]) -> f64 {
    let r = &event.record;
    (0..r.time_s.len())
        .filter(|&k| event.fit.contains(r.time_s[k]))
        .map(|k| (p[k] - r.p_pu[k]).powi(2) + (q[k] - r.q_pu[k]).powi(2))
        .sum()
}

/// Largest |a − b| (infinite if any difference is not a number).
fn worst(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).fold(0.0, |m: f64, (x, y)| {
        let d = (x - y).abs();
        if d.is_nan() {
            f64::INFINITY
        } else {
            m.max(d)
        }
    })
}

/// Everything of `unit` that `back` (its `.dyr` read back) does not have, with why.
fn compare(unit: &Unit, back: &Unit) -> Vec<Loss> {
    let mut lost = vec![];
    for (what, a, b) in [
        ("machine_mva", unit.machine_mva, back.machine_mva),
        ("nominal_hz", unit.nominal_hz, back.nominal_hz),
    ] {
        if a != b {
            lost.push(Loss {
                what: what.into(),
                unit: a.to_string(),
                written: b.to_string(),
                why: "the side file of bases".into(),
            });
        }
    }
    for inst in unit.instances() {
        match back.instances().iter().find(|i| i.name == inst.name) {
            Some(b) => compare_block(inst, b, &mut lost),
            None => lost.extend(absent(inst)),
        }
    }
    for b in back.instances() {
        if !unit.instances().iter().any(|i| i.name == b.name) {
            lost.push(Loss {
                what: format!("block '{}'", b.name),
                unit: "absent".into(),
                written: b.block.model().into(),
                why: "the .dyr reads back with a block the unit does not have".into(),
            });
        }
    }
    lost
}

/// A block of the unit the `.dyr` has no record for: a loss unless it is `constant_pm` at its
/// defaults (no governor record holds P_m at P_m0, which is what it does).
fn absent(inst: &Instance) -> Vec<Loss> {
    let b = &inst.block;
    if b.model() == "constant_pm" {
        let ps = b.params();
        let fresh = crate::registry::find("constant_pm").map(|i| i.create());
        return ps
            .specs()
            .iter()
            .enumerate()
            .filter(|(i, _)| fresh.as_ref().map(|f| f.params().get(*i)) != Some(ps.get(*i)))
            .map(|(i, s)| Loss {
                what: format!("{}.{}", inst.name, s.name),
                unit: ps.get(i).to_string(),
                written: "absent".into(),
                why: "constant_pm is written as no governor record, which holds P_m at its initial value; PSS/E has no offset for it".into(),
            })
            .collect();
    }
    vec![Loss {
        what: format!("block '{}'", inst.name),
        unit: b.model().into(),
        written: "absent".into(),
        why: format!(
            "no PSS/E record for {} in the {} slot",
            b.model(),
            inst.name
        ),
    }]
}

fn compare_block(a: &Instance, b: &Instance, lost: &mut Vec<Loss>) {
    let (ma, mb) = (a.block.model(), b.block.model());
    if ma != mb {
        lost.push(Loss {
            what: format!("block '{}'", a.name),
            unit: ma.into(),
            written: mb.into(),
            why: "written as another model".into(),
        });
        return;
    }
    let (pa, pb) = (a.block.params(), b.block.params());
    for (i, s) in pa.specs().iter().enumerate() {
        let (x, y) = (pa.get(i), pb.get(i));
        if x.to_bits() != y.to_bits() && x != y {
            lost.push(Loss {
                what: format!("{}.{}", a.name, s.name),
                unit: x.to_string(),
                written: y.to_string(),
                why: why_param(ma, s.name),
            });
        }
    }
    let (oa, ob) = (a.block.options(), b.block.options());
    for (k, v) in &oa {
        let w = ob.iter().find(|(k2, _)| k2 == k).map(|(_, v)| v.as_str());
        if w != Some(v.as_str()) {
            lost.push(Loss {
                what: format!("{} option {k}", a.name),
                unit: v.clone(),
                written: w.unwrap_or("absent").into(),
                why: "no PSS/E form".into(),
            });
        }
    }
    let (ra, rb) = (a.rewiring(), b.rewiring());
    let port_of = |r: &[(String, String)], p: &str| {
        r.iter()
            .find(|(q, _)| q == p)
            .map(|(_, s)| s.clone())
            .unwrap_or_else(|| "default".into())
    };
    let mut ports: Vec<&String> = ra.iter().chain(&rb).map(|(p, _)| p).collect();
    ports.sort();
    ports.dedup();
    for p in ports {
        let (x, y) = (port_of(&ra, p), port_of(&rb, p));
        if x != y {
            lost.push(Loss {
                what: format!("{} port {p}", a.name),
                unit: format!("wired to {x}"),
                written: format!("wired to {y}"),
                why: input_codes_reach(ma, p)
                    .unwrap_or_else(|| "PSS/E has no such connection".into()),
            });
        }
    }
}

/// For a port an input-code ICON of `model`'s record wires: the signals its codes reach.
fn input_codes_reach(model: &str, port: &str) -> Option<String> {
    let layout = crate::registry::find(model)?.dyr?;
    layout.icons.iter().find_map(|i| match i {
        super::Icon::Input { port: p, codes, .. } if *p == port => Some(format!(
            "{model}'s input codes reach {} only",
            codes
                .iter()
                .filter_map(|c| c.signal)
                .collect::<Vec<_>>()
                .join(", ")
        )),
        _ => None,
    })
}

/// Why the `.dyr` record of `model` does not give parameter `name` back.
fn why_param(model: &str, name: &str) -> String {
    match name {
        "x_q_pp" => format!(
            "PSS/E's {model} record has one X'' (X''q = X''d): X''d is written; the PSS/E records with a separate X''q (GENQEC) are models the engine does not implement"
        ),
        n if n.ends_with("_offset") => format!(
            "a set-point offset is no CON of PSS/E's {model} record (PSS/E initialises the reference from the power flow)"
        ),
        _ => format!("not carried by PSS/E's {model} record as written"),
    }
}

//! The catalog of causes: for each, what it looks like in the residual evidence, the extension
//! block that models it, and which parameters a re-fit frees (the extension's own, then the
//! unit's parameters it interacts with).
//!
//! One definition serves two uses: [`extend`] builds the extended unit that `diagnose` re-fits,
//! and [`hide`] builds the same extension with chosen values, so that `synth` can hide a cause
//! in the truth of a synthetic event.

use std::collections::BTreeMap;

use itaipu_dynamics::block::Block;
use itaipu_dynamics::registry::{self, Role};
use itaipu_dynamics::unit::Unit;
use serde::Serialize;

use crate::problem::Prior;

/// One entry of the catalog.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct CauseInfo {
    /// Identifier (`torsional_mode`, …), as written in verdicts and on the command line.
    pub id: &'static str,
    /// A short title for tables.
    pub title: &'static str,
    /// What the cause looks like in the residual evidence.
    pub signature: &'static str,
    /// The model extension fitted for it.
    pub extension: &'static str,
    /// The parameters that characterise it (reported in the verdict), extension-relative
    /// (`block.param` inside the extended unit).
    pub key_params: &'static [&'static str],
}

/// Every cause `diagnose` knows, in the order they are tried.
pub static CAUSES: &[CauseInfo] = &[
    CauseInfo {
        id: "torsional_mode",
        title: "torsional mode of the turbine-generator shaft",
        signature: "a lightly damped oscillation in the P residual above the electromechanical modes, \
                    present after every disturbance",
        extension: "two_mass_shaft between the governor and the machine (H_t, mode frequency, damping ratio), \
                    machine.h becomes the generator mass",
        key_params: &["shaft.f_torsion_hz", "shaft.zeta"],
    },
    CauseInfo {
        id: "exciter_limit",
        title: "exciter output limits reached",
        signature: "Q residual confined to the dip and the first recovery seconds (the field voltage \
                    saturates on its ceiling or floor), small before and long after",
        extension: "exciter ceiling E_MAX and floor E_MIN freed (with the AVR gain)",
        key_params: &["exciter.e_max", "exciter.e_min"],
    },
    CauseInfo {
        id: "saturation",
        title: "magnetic saturation other than modelled",
        signature: "Q residual that grows with the flux (voltage) level and a Q bias after the event",
        extension: "machine saturation S(1.0), S(1.2) freed (with the AVR gain, T_E, X'_d and H)",
        key_params: &["machine.s10", "machine.s12"],
    },
    CauseInfo {
        id: "governor",
        title: "governor action missing or mis-modelled",
        signature: "slow P residual that follows the frequency deviation (seconds), growing through the \
                    record",
        extension: "HYGOV (added, or refitted) with a speed deadband and its gate rate limit VELM free",
        key_params: &["deadband.db", "governor.velm"],
    },
    CauseInfo {
        id: "measurement_skew",
        title: "power channels skewed against the voltage channel",
        signature: "P and Q residuals shaped like the time derivative of the response (largest where P and Q \
                    change fastest), cross-correlated with the input at a lag",
        extension: "pmu_measurement block: a fractional delay of the P and Q channels",
        key_params: &["measurement.pq_delay_s"],
    },
    CauseInfo {
        id: "terminal_load",
        title: "unmodelled load between the machine and the PMU",
        signature: "P and Q residuals proportional to the voltage deviation (largest in the dip), no lag",
        extension: "terminal_load block: a constant-impedance P and Q load at the terminal bus",
        key_params: &["load.p_load", "load.q_load"],
    },
    CauseInfo {
        id: "pss_state",
        title: "PSS in service other than modelled",
        signature: "electromechanical swing in the P residual with the wrong damping after the event",
        extension: "the PSS removed when the model has one; a STAB3 added when it has none",
        key_params: &["pss.in_service"],
    },
    CauseInfo {
        id: "oel",
        title: "over-excitation limiter acting after the event",
        signature: "Q residual that appears seconds after the event, while the field current stays high, \
                    and grows (the limiter pulls the field back)",
        extension: "inverse-time OEL on the field current (pickup, I²t capacity, integral gain), with the AVR \
                    gain, T_E, X'_d and H",
        key_params: &["oel.i_pickup", "oel.a_max"],
    },
];

/// Looks a cause up by id.
pub fn find(id: &str) -> Option<&'static CauseInfo> {
    CAUSES.iter().find(|c| c.id == id)
}

/// Ids of all causes, for messages.
pub fn ids() -> String {
    CAUSES.iter().map(|c| c.id).collect::<Vec<_>>().join(", ")
}

/// A free parameter of a candidate re-fit.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FreeBound {
    pub param: String,
    pub min: f64,
    pub max: f64,
    pub start: f64,
    /// Grid points to scan this parameter over before the swarm (0 = none): for a parameter
    /// whose objective has narrow valleys (a mode frequency, a delay, a limit that is hit or
    /// not), the best grid point becomes the start.
    pub scan: usize,
    /// Held at its start during the global search and freed only in the final L-BFGS polish
    /// (for the many calibrated parameters re-freed with [`super::DiagnoseOptions::refit`]).
    pub polish_only: bool,
    /// The datasheet prior of a calibrated parameter (the calibration's), so that a re-fit that
    /// bends it pays the same price as the calibration did.
    #[serde(skip)]
    pub prior: Option<Prior>,
}

/// What the operating point and the evidence tell the catalog about a unit on an event.
#[derive(Debug, Clone, Default)]
pub struct Context {
    /// Field voltage at the pre-event operating point [pu], if the unit has an exciter.
    pub efd0: Option<f64>,
    /// Field current X_adI_fd at the operating point [pu].
    pub xadifd0: Option<f64>,
    /// PMU reporting rate [samples/s].
    pub rate_hz: f64,
    /// Frequency of the dominant oscillation in the P residual above 1 Hz, if any [Hz].
    pub mode_hint_hz: Option<f64>,
    /// A resonance of the P residual in the shaft band that passes [`resonance_stands_out`]
    /// (the most significant over the events), if any.
    pub shaft_resonance: Option<crate::evidence::SpectralPeak>,
    /// Deepest voltage dip of the events after the onset, as a fraction of the pre-event |V|
    /// (`None`: unknown, e.g. when hiding a cause, and no regime is required).
    pub deepest_dip: Option<f64>,
    /// Largest sustained frequency change of the events (last quarter against pre-event) [Hz].
    pub sustained_df_hz: Option<f64>,
    /// Largest rise of the field current X_adI_fd of the unit as given over its pre-event value,
    /// as a fraction (`None`: unknown).
    pub field_current_rise: Option<f64>,
}

/// Largest chance that noise alone gives a resonance, for it to name a torsional mode: one in
/// a million (with the band's windows counted), the "very strong" end of the usual scales.
pub const RESONANCE_P: f64 = 1e-6;
/// Smallest prominence of a resonance over its neighbourhood (see
/// [`crate::evidence::SpectralPeak::prominence`]): twice its neighbours' power. The shoulder
/// of a low-frequency misfit leaking into the band has a prominence near or below 1.
pub const RESONANCE_PROMINENCE: f64 = 2.0;

/// Whether a resonance of the P residual is a mode the model lacks rather than noise or leakage.
pub fn resonance_stands_out(p: &crate::evidence::SpectralPeak) -> bool {
    p.p_value < RESONANCE_P && p.prominence >= RESONANCE_PROMINENCE
}

/// The evidence that names `cause` by itself, when a re-fit cannot measure it: a torsional
/// mode kept ringing by random turbine torque is a resonance in the P residual that no
/// deterministic playback reproduces, so its re-fit gains nothing, while the spectrum shows it
/// far above the measurement noise.
pub fn named_by_evidence(cause: &str, ctx: &Context) -> Option<String> {
    match cause {
        "torsional_mode" => ctx.shaft_resonance.as_ref().map(|p| {
            format!(
                "the P residual has a resonance at {:.2} Hz with {:.1} times the band's noise power \
                 over {:.1} Hz ({:.1} times its neighbours'; chance from noise alone {:.1e}), which \
                 no deterministic playback reproduces: a shaft mode kept ringing by the turbine's \
                 torque",
                p.freq_hz,
                p.ratio,
                crate::evidence::PEAK_WINDOW_HZ,
                p.prominence,
                p.p_value
            )
        }),
        _ => None,
    }
}

/// Smallest P/Q skew a diagnosis names, in sample intervals. Between samples the playback only
/// knows the voltage by interpolation, and the unit's fastest responses (subtransient flux,
/// the exciter) follow it within the sample interval, so a delay of a fraction of a sample
/// trades against those: on practice records without any skew, the fitted delay comes out at
/// 0.2-0.45 sample intervals. Half a sample is also the resolution a delay is scored to.
pub const SKEW_RESOLUTION_SAMPLES: f64 = 0.5;

/// Why the fitted extension of `cause` is below what the data can resolve (then it is not
/// named, whatever its gain), from its fitted parameters `(path, value)`.
pub fn below_resolution(cause: &str, fitted: &[(String, f64)], ctx: &Context) -> Option<String> {
    match cause {
        "measurement_skew" => {
            let tau = fitted
                .iter()
                .find(|(p, _)| p == "measurement.pq_delay_s")?
                .1;
            let samples = tau * ctx.rate_hz;
            (samples < SKEW_RESOLUTION_SAMPLES).then(|| {
                format!(
                    "the fitted delay ({:.1} ms, {samples:.2} sample intervals) is below half a sample \
                     interval, which the playback's own timing between samples can account for",
                    1e3 * tau
                )
            })
        }
        _ => None,
    }
}

/// Dip from which a high-gain AVR is taken to run to its limits.
pub const LIMIT_DIP: f64 = 0.05;
/// Rise of the field current from which an over-excitation limiter can pick up: a voltage step
/// down that the AVR answers with a sustained field forcing reaches the limiter's pickup
/// (typically 1.05-1.1 × rated, a few percent above a loaded unit's field current) without any
/// dip. Below it, a limiter just above the operating point would only trim a bent AVR gain.
pub const OEL_IFD_RISE: f64 = 0.05;
/// Sustained frequency change from which a governor is taken to act [Hz].
pub const GOVERNOR_DF_HZ: f64 = 0.02;
/// Swarm-length factor of a candidate whose regime the events reach and that re-frees a
/// calibration's bent stage parameters (limits, governor, PSS).
const DEEP_SEARCH: usize = 5;

/// A unit extended for one cause, with what to free in the re-fit.
#[derive(Clone)]
pub struct Extension {
    pub cause: &'static str,
    pub unit: Unit,
    /// The extension's own parameters (counted in the information criterion).
    pub extension_free: Vec<FreeBound>,
    /// Parameters of the unit the extension interacts with (freed in the baseline re-fit too).
    pub interacting_free: Vec<FreeBound>,
    /// Structural parameters that are not continuous (e.g. a PSS switched out): counted in the
    /// information criterion on top of `extension_free`.
    pub discrete_params: usize,
    /// `(from, to)`: `to` follows `from` (paths in `unit`).
    pub ties: Vec<(String, String)>,
    /// Human-readable description of what was changed.
    pub description: String,
    /// Fixed results to report (e.g. `pss.in_service = 0`).
    pub fixed: Vec<(String, f64)>,
    /// Multiplier of the swarm's iterations for this candidate (a structural change that moves
    /// many interacting parameters at once needs a longer search).
    pub search_factor: usize,
}

fn role_of(block: &dyn Block) -> Role {
    registry::find(block.model()).map_or(Role::Other, |m| m.role)
}

/// The instance name of the block with `role`.
pub fn instance_with_role(unit: &Unit, role: Role) -> Option<String> {
    unit.instances()
        .iter()
        .find(|i| role_of(i.block.as_ref()) == role)
        .map(|i| i.name.clone())
}

fn model_of(unit: &Unit, name: &str) -> String {
    unit.block(name)
        .map(|b| b.model().to_string())
        .unwrap_or_default()
}

fn new_block(model: &str, values: &[(&str, f64)]) -> Result<Box<dyn Block>, String> {
    let info =
        registry::find(model).ok_or_else(|| format!("model {model} is not in the registry"))?;
    let mut b = info.create();
    for (name, v) in values {
        let ps = b.params_mut();
        let k = ps
            .index_of(name)
            .ok_or_else(|| format!("{model} has no parameter {name}"))?;
        ps.set(k, *v);
    }
    Ok(b)
}

fn value(unit: &Unit, path: &str) -> Result<f64, String> {
    unit.param(path)
        .map(|r| unit.get(r))
        .map_err(|e| e.to_string())
}

fn has_param(unit: &Unit, path: &str) -> bool {
    unit.param(path).is_ok()
}

fn fb(param: &str, min: f64, max: f64, start: f64) -> FreeBound {
    FreeBound {
        param: param.to_string(),
        min,
        max,
        start: start.clamp(min, max),
        scan: 0,
        polish_only: false,
        prior: None,
    }
}

fn scanned(mut b: FreeBound, points: usize) -> FreeBound {
    b.scan = points;
    b
}

/// Adds block `name` (the wiring is resolved once all edits are made).
fn add_block(unit: &mut Unit, name: &str, block: Box<dyn Block>) -> Result<(), String> {
    unit.add(name, block, &[]).map_err(|e| e.to_string())
}

/// Rewires ports of the existing instance `name`, keeping its other connections.
fn rewire(unit: &mut Unit, name: &str, ports: &[(&str, &str)]) -> Result<(), String> {
    let rw: Vec<(String, String)> = ports
        .iter()
        .map(|(a, b)| (a.to_string(), b.to_string()))
        .collect();
    unit.rewire(name, &rw).map_err(|e| e.to_string())
}

/// Set-point offsets that every re-fit frees as nuisance parameters (`models.md`: a playback
/// is open loop, and a small error in the initial voltage or speed reference moves the response).
pub const NUISANCE: &[&str] = &["v_ref_offset", "n_ref_offset", "pm_offset"];

/// The unit's nuisance offsets, each within its declared range (widened to hold its value).
pub fn nuisance(unit: &Unit) -> Vec<FreeBound> {
    unit.params()
        .into_iter()
        .filter(|(path, _, _)| NUISANCE.iter().any(|n| path.rsplit('.').next() == Some(*n)))
        .map(|(path, spec, v)| fb(&path, spec.range.0.min(v), spec.range.1.max(v), v))
        .collect()
}

/// Frees the positive parameter `path` of `u` within `[v/factor, v·factor]` around its value
/// `v`, clipped to the model's declared range (a calibrated value may sit on the bound of the
/// calibration that bent it, so the band is wide). `None` if it does not exist or is not > 0.
fn around(u: &Unit, path: &str, factor: f64) -> Option<FreeBound> {
    let (_, spec, v) = u.params().into_iter().find(|(p, _, _)| p == path)?;
    (v > 0.0).then(|| {
        let lo = (v / factor).max(spec.range.0).min(v);
        let hi = (v * factor).min(spec.range.1).max(v);
        fb(path, lo, hi, v)
    })
}

/// The calibrated parameters a calibration without a field-side cause (an exciter limit, an
/// OEL, a saturation curve) bends to make up for it: the AVR gain K_A and exciter time constant
/// T_E within ×3 (a bent value may sit on its calibration's bound), X'_d and H within ×1.6.
/// T'_d0 stays as given (see `trial::NOMINAL_OFFSETS`).
fn field_side(u: &Unit, exciter: Option<&str>, machine: &str) -> Vec<FreeBound> {
    let avr = exciter.into_iter().flat_map(|x| {
        [
            around(u, &format!("{x}.k"), 3.0),
            around(u, &format!("{x}.te"), 3.0),
        ]
    });
    avr.chain([
        around(u, &format!("{machine}.x_d_prime"), 1.6),
        around(u, &format!("{machine}.h"), 1.6),
    ])
    .flatten()
    .collect()
}

/// Builds the extension of `unit` for `cause`. `Ok(None)` when the cause does not apply to this
/// unit (e.g. no exciter for `exciter_limit`); the reason is in the string.
pub fn extend(
    cause: &str,
    unit: &Unit,
    ctx: &Context,
) -> Result<Result<Extension, String>, String> {
    let info = find(cause).ok_or_else(|| format!("unknown cause '{cause}' (known: {})", ids()))?;
    let mut u = unit.clone();
    u.ensure_finished().map_err(|e| e.to_string())?;
    let machine = instance_with_role(&u, Role::Machine).ok_or("the unit has no machine")?;
    let exciter = instance_with_role(&u, Role::Exciter);
    let pss = instance_with_role(&u, Role::Pss);
    let governor = instance_with_role(&u, Role::Governor);
    let mut ext = Extension {
        cause: info.id,
        unit: u.clone(),
        extension_free: vec![],
        interacting_free: vec![],
        discrete_params: 0,
        ties: vec![],
        description: info.extension.to_string(),
        fixed: vec![],
        search_factor: 1,
    };
    let not_applicable = |why: &str| Ok(Err(why.to_string()));
    match info.id {
        "torsional_mode" => {
            if governor.is_none() {
                return not_applicable("no governor block to feed the turbine mass");
            }
            if u.block("shaft").is_some() {
                return not_applicable("the unit already has a block named 'shaft'");
            }
            let h_path = format!("{machine}.h");
            let h = value(&u, &h_path)?;
            // Split the calibrated (rigid) inertia: 15 % to the turbine to start with.
            let h_t = 0.15 * h;
            let nyquist = 0.5 * ctx.rate_hz;
            let f_hi = (0.9 * nyquist).clamp(1.0, 25.0);
            // A resonance in the residual pins the frequency (the spectrum's resolution is a
            // few hundredths of a hertz): the re-fit searches within 2 % of it.
            let resonance = ctx
                .shaft_resonance
                .as_ref()
                .map(|p| p.freq_hz)
                .filter(|f| *f > 1.0 && *f < f_hi);
            let f_start = resonance
                .or(ctx.mode_hint_hz.filter(|f| *f > 1.0 && *f < f_hi))
                .unwrap_or(0.5 * f_hi);
            let (f_min, f_max) = match resonance {
                Some(f) => (0.98 * f, (1.02 * f).min(f_hi)),
                None => (1.0, f_hi),
            };
            let shaft = new_block(
                "two_mass_shaft",
                &[
                    ("h_turbine", h_t),
                    ("h_generator", h - h_t),
                    ("f_torsion_hz", f_start),
                    ("zeta", 0.05),
                    ("d_turbine", 0.0),
                ],
            )?;
            let h_r = u.param(&h_path).map_err(|e| e.to_string())?;
            u.set(h_r, h - h_t);
            add_block(&mut u, "shaft", shaft)?;
            rewire(&mut u, &machine, &[("pm", "p_shaft")])?;
            ext.extension_free = vec![
                scanned(fb("shaft.f_torsion_hz", f_min, f_max, f_start), 48),
                fb("shaft.zeta", 0.0005, 0.5, 0.05),
                fb("shaft.h_turbine", 0.02 * h, 0.6 * h, h_t),
            ];
            ext.interacting_free = vec![fb(&h_path, 0.4 * h, 1.05 * h, h - h_t)];
            ext.ties = vec![(h_path, "shaft.h_generator".into())];
        }
        "exciter_limit" => {
            let Some(x) = exciter else {
                return not_applicable("no exciter");
            };
            let (pmax, pmin) = (format!("{x}.e_max"), format!("{x}.e_min"));
            if !has_param(&u, &pmax) || !has_param(&u, &pmin) {
                return not_applicable(&format!(
                    "exciter {} has no E_MAX/E_MIN limits",
                    model_of(&u, &x)
                ));
            }
            if ctx.deepest_dip.is_some_and(|d| d < LIMIT_DIP) {
                // A limit just above the operating point would only clamp E_fd to make up for a
                // mis-calibrated AVR gain.
                return not_applicable(&format!(
                    "no event dips |V| by {:.0} % or more, so the AVR is not driven to its limits",
                    100.0 * LIMIT_DIP
                ));
            }
            let efd0 = ctx
                .efd0
                .ok_or("the field voltage at the operating point is unknown")?;
            let (emax, emin) = (value(&u, &pmax)?, value(&u, &pmin)?);
            let hi = emax.max(efd0 + 3.0).max(2.0 * efd0);
            ext.extension_free = vec![
                scanned(fb(&pmax, efd0 + 0.05, hi, emax.min(hi)), 24),
                fb(&pmin, emin.min(-2.0), efd0 - 0.05, emin.min(efd0 - 0.05)),
            ];
            // The AVR gain and time constant, X'_d and H: a calibration without the right limit
            // bends them to make up for it. T'_d0 stays as given: on the ceiling the field flux
            // rises at E_MAX/T'_d0, so P and Q cannot tell the two apart (see
            // `trial::NOMINAL_OFFSETS`). T_E is scanned with E_MAX: on and off the ceiling the
            // two trade along a curved valley (a faster exciter reaches the ceiling sooner, as a
            // higher ceiling would).
            ext.interacting_free = field_side(&u, Some(&x), &machine);
            let te = format!("{x}.te");
            for b in ext.interacting_free.iter_mut().filter(|b| b.param == te) {
                b.scan = 8;
            }
            ext.search_factor = DEEP_SEARCH;
        }
        "saturation" => {
            let (s10, s12) = (format!("{machine}.s10"), format!("{machine}.s12"));
            if !has_param(&u, &s10) || !has_param(&u, &s12) {
                return not_applicable(&format!(
                    "machine {} has no S(1.0), S(1.2)",
                    model_of(&u, &machine)
                ));
            }
            let (a, b) = (value(&u, &s10)?, value(&u, &s12)?);
            ext.extension_free = vec![fb(&s10, 0.0, 0.4, a), fb(&s12, 0.02, 1.5, b)];
            // Saturation sets the incremental field-to-flux gain: a calibration with the wrong
            // curve bends the AVR and X'_d to make up for it; and a calibration that is off for
            // any other reason must not be "repaired" by a saturation curve (its baseline
            // re-fits them too).
            ext.interacting_free = field_side(&u, exciter.as_deref(), &machine);
        }
        "governor" => {
            let Some(g) = governor else {
                return not_applicable("no governor block");
            };
            if u.block("deadband").is_some() {
                return not_applicable("the unit already has a block named 'deadband'");
            }
            let model = model_of(&u, &g);
            if !model.eq_ignore_ascii_case("HYGOV") {
                // Governor action missing: put a typical HYGOV in its place.
                let hygov = registry::find("HYGOV")
                    .ok_or("HYGOV is not in the registry")?
                    .create();
                u.put(&g, hygov, &[]).map_err(|e| e.to_string())?;
                ext.description = format!(
                    "HYGOV (typical values) in place of {model}, with a speed deadband; {}",
                    info.extension
                );
            }
            add_block(
                &mut u,
                "deadband",
                new_block("speed_deadband", &[("db", 0.0)])?,
            )?;
            rewire(&mut u, &g, &[("speed", "speed_db")])?;
            let velm = value(&u, &format!("{g}.velm"))?;
            ext.extension_free = vec![
                scanned(fb("deadband.db", 0.0, 0.004, 0.0), 9),
                scanned(fb(&format!("{g}.velm"), 0.005, 0.5, velm), 9),
            ];
            let (r, tw) = (
                value(&u, &format!("{g}.r_perm"))?,
                value(&u, &format!("{g}.t_w"))?,
            );
            // On a frequency excursion the machine's inertia carries the power the governor does
            // not: a calibration without the governor's nonlinearity bends H to make up for it.
            ext.interacting_free = vec![
                fb(&format!("{g}.r_perm"), 0.01, 0.15, r),
                fb(&format!("{g}.t_w"), 0.3, 4.0, tw),
            ];
            ext.interacting_free
                .extend(around(&u, &format!("{machine}.h"), 1.6));
            ext.interacting_free
                .extend(around(&u, &format!("{machine}.x_d_prime"), 1.6));
            if let Some(x) = &exciter {
                ext.interacting_free
                    .extend(around(&u, &format!("{x}.k"), 3.0));
            }
            if ctx.sustained_df_hz.is_none_or(|df| df > GOVERNOR_DF_HZ) {
                ext.search_factor = DEEP_SEARCH;
            }
            if !model.eq_ignore_ascii_case("HYGOV") {
                // A new governor: every parameter the fit needs is new, count them all.
                ext.extension_free.append(&mut ext.interacting_free);
            }
        }
        "measurement_skew" => {
            if u.block("measurement").is_some() {
                return not_applicable("the unit already has a measurement block");
            }
            add_block(&mut u, "measurement", new_block("pmu_measurement", &[])?)?;
            let max = 3.0 / ctx.rate_hz.max(1.0);
            ext.extension_free = vec![scanned(
                fb(
                    "measurement.pq_delay_s",
                    0.0,
                    max,
                    0.5 / ctx.rate_hz.max(1.0),
                ),
                13,
            )];
        }
        "terminal_load" => {
            if u.block("load").is_some() {
                return not_applicable("the unit already has a block named 'load'");
            }
            add_block(&mut u, "load", new_block("terminal_load", &[])?)?;
            ext.extension_free = vec![
                fb("load.p_load", 0.0, 0.15, 0.0),
                fb("load.q_load", -0.15, 0.15, 0.0),
            ];
        }
        "pss_state" => {
            let Some(x) = exciter else {
                return not_applicable("no exciter for a PSS to act on");
            };
            if let Some(p) = pss {
                u = u.without(&[p.as_str()]).map_err(|e| e.to_string())?;
                ext.description = format!("the PSS ({}) taken out of service", model_of(unit, &p));
                ext.discrete_params = 1;
                ext.fixed = vec![("pss.in_service".into(), 0.0)];
            } else {
                add_block(
                    &mut u,
                    "pss",
                    registry::find("STAB3")
                        .ok_or("STAB3 is not in the registry")?
                        .create(),
                )?;
                ext.description = "a STAB3 PSS (typical values) put in service".into();
                ext.extension_free =
                    vec![fb("pss.k_x", 0.2, 5.0, 1.0), fb("pss.t_x2", 0.5, 8.0, 3.0)];
                ext.discrete_params = 1;
                ext.fixed = vec![("pss.in_service".into(), 1.0)];
            }
            // A calibration with the PSS as modelled tuned the AVR, the inertia and the field
            // dynamics to make up for it: they move with the PSS's state (a longer search).
            ext.search_factor = DEEP_SEARCH;
            for (p, factor) in [
                (format!("{x}.k"), 3.0),
                (format!("{x}.te"), 3.0),
                (format!("{machine}.h"), 1.6),
                (format!("{machine}.x_d_prime"), 2.5),
                (format!("{machine}.t_d0_prime"), 1.6),
            ] {
                ext.interacting_free.extend(around(&u, &p, factor));
            }
            let d = format!("{machine}.d");
            if let Ok(v) = value(&u, &d) {
                ext.interacting_free.push(fb(&d, 0.0, v.max(0.0) + 3.0, v));
            }
        }
        "oel" => {
            let Some(x) = exciter else {
                return not_applicable("no exciter for an OEL to act on");
            };
            let has_voel = u
                .block(&x)
                .is_some_and(|b| b.ports().iter().any(|p| p.name == "voel"));
            if !has_voel {
                return not_applicable(&format!("exciter {} has no OEL input", model_of(&u, &x)));
            }
            if u.block("oel").is_some() {
                return not_applicable("the unit already has an OEL");
            }
            if ctx.deepest_dip.is_some_and(|d| d < LIMIT_DIP)
                && ctx.field_current_rise.is_none_or(|r| r < OEL_IFD_RISE)
            {
                // Without a dip or a sustained field forcing the field current is not driven
                // into overload; a limiter picking up just above the operating point would only
                // trim a mis-calibrated AVR gain.
                return not_applicable(&format!(
                    "no event dips |V| by {:.0} % or more or raises the field current by {:.0} % or more, \
                     so the field current is not forced into overload",
                    100.0 * LIMIT_DIP,
                    100.0 * OEL_IFD_RISE
                ));
            }
            let i0 = ctx
                .xadifd0
                .ok_or("the field current at the operating point is unknown")?;
            if !(i0 > 0.0) {
                return not_applicable("the field current at the operating point is not positive");
            }
            // Rated field current = the pre-event one, so pickup and limit read as multiples of it
            // (the pickup stays at least 1 % above, so the limiter starts inactive).
            let oel = new_block(
                "oel",
                &[
                    ("ifd_rated", i0),
                    ("i_pickup", 1.2),
                    ("i_limit", 1.2),
                    ("a_max", 2.0),
                    ("k_cool", 0.05),
                    ("k_i", 0.01),
                    ("voel_min", -0.5),
                ],
            )?;
            add_block(&mut u, "oel", oel)?;
            // Pickup and I²t capacity scanned jointly: together they set when the limiter acts
            // (a lower pickup with a larger capacity acts as late), and off that valley the
            // objective is flat (the limiter never acts) or far worse (it acts at the wrong
            // time).
            ext.extension_free = vec![
                scanned(fb("oel.i_pickup", 1.01, 1.6, 1.2), 12),
                scanned(fb("oel.a_max", 0.02, 30.0, 0.3), 8),
                fb("oel.k_i", 0.002, 0.2, 0.03),
            ];
            ext.ties = vec![("oel.i_pickup".into(), "oel.i_limit".into())];
            // A calibration without the limiter bends the AVR and the field dynamics to make
            // up for the field being pulled back (as for `exciter_limit`).
            ext.interacting_free = field_side(&u, Some(&x), &machine);
            ext.search_factor = DEEP_SEARCH;
        }
        _ => unreachable!("every catalog id is handled"),
    }
    u.ensure_finished().map_err(|e| e.to_string())?;
    // Every re-fit also frees the set-point offsets (nuisance parameters).
    for n in nuisance(&u) {
        let known = |v: &Vec<FreeBound>| v.iter().any(|f| f.param == n.param);
        if !known(&ext.extension_free) && !known(&ext.interacting_free) {
            ext.interacting_free.push(n);
        }
    }
    ext.unit = u;
    Ok(Ok(ext))
}

/// Why a cause cannot be hidden.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum HideError {
    /// Unknown cause, unknown or tied parameter: a bad request.
    #[error("{0}")]
    Request(String),
    /// The cause does not apply to this unit (e.g. no exciter for `exciter_limit`).
    #[error("cannot hide {cause} in unit '{unit}': {why}")]
    NotApplicable {
        cause: String,
        unit: String,
        why: String,
    },
    /// The extension could not be built on this unit.
    #[error("{0}")]
    Build(String),
}

/// The parameters a hide of `ext` (built on `unit`) may set: those the extension frees and
/// those of the blocks it adds, except the ones tied to another parameter.
pub fn hideable_params(unit: &Unit, ext: &Extension) -> Vec<String> {
    let old: Vec<&str> = unit.instances().iter().map(|i| i.name.as_str()).collect();
    let mut known: Vec<String> = vec![];
    let candidates = ext
        .extension_free
        .iter()
        .chain(&ext.interacting_free)
        .map(|f| f.param.clone())
        .chain(
            ext.unit
                .params()
                .into_iter()
                .map(|(p, _, _)| p)
                .filter(|p| !old.contains(&p.split('.').next().unwrap_or(""))),
        );
    for p in candidates {
        if !known.contains(&p) && !ext.ties.iter().any(|(_, to)| *to == p) {
            known.push(p);
        }
    }
    known
}

/// The unit with `cause` hidden in it: the extension of [`extend`] with `values` set
/// (`block.param` paths among [`hideable_params`], e.g. `shaft.f_torsion_hz`), ties applied.
/// Returns the extension too (what was added, for reports).
pub fn hide(
    cause: &str,
    unit: &Unit,
    ctx: &Context,
    values: &BTreeMap<String, f64>,
) -> Result<(Unit, Extension), HideError> {
    let ext = extend(cause, unit, ctx)
        .map_err(|e| {
            if find(cause).is_none() {
                HideError::Request(e)
            } else {
                HideError::Build(e)
            }
        })?
        .map_err(|why| HideError::NotApplicable {
            cause: cause.to_string(),
            unit: unit.name.clone(),
            why,
        })?;
    let known = hideable_params(unit, &ext);
    for path in values.keys() {
        if let Some((from, _)) = ext.ties.iter().find(|(_, to)| to == path) {
            return Err(HideError::Request(format!(
                "{cause}: {path} follows {from}; set {from} instead"
            )));
        }
        if !known.contains(path) {
            return Err(HideError::Request(format!(
                "{cause}: unknown parameter '{path}' (its parameters: {})",
                known.join(", ")
            )));
        }
    }
    let mut u = ext.unit.clone();
    let set = |u: &mut Unit, path: &str, v: f64| -> Result<(), HideError> {
        let r = u.param(path).map_err(|e| HideError::Build(e.to_string()))?;
        u.set(r, v);
        Ok(())
    };
    // Extension parameters start at their search start unless given.
    for f in &ext.extension_free {
        set(&mut u, &f.param, f.start)?;
    }
    for (path, v) in values {
        set(&mut u, path, *v)?;
    }
    for (from, to) in &ext.ties {
        let v = u.get(u.param(from).map_err(|e| HideError::Build(e.to_string()))?);
        set(&mut u, to, v)?;
    }
    Ok((u, ext))
}

//! The practice set (`shared/practice/`): PMU events made by an independent implementation, each
//! with a nominal ("vendor") model and an answer key, run the way a user would run them.
//!
//! A case is read from `cases/<name>/data.csv` (the canonical measurement columns) and
//! `cases/<name>/nominal.json` (bases and the nominal GENSAE + SEXS + STAB3 + HYGOV with PSS/E
//! parameter names). [`practice_spec`] is the ONE calibration spec every case gets: it frees the
//! 20 parameters a nominal model may get wrong within the same relative bounds of their nominal
//! values (plus the two set-point offsets as nuisance), whatever the case. The answer key
//! (`answers/<name>.json`) is read by [`AnswerKey::read`] only, and only the scoring step uses
//! it: nothing in the fit or the diagnosis sees it.

use std::path::{Path, PathBuf};

use itaipu_dynamics::event::{read_csv, Event, Window};
use itaipu_dynamics::unit::Unit;
use itaipu_dynamics::unit_file::parse_unit;
use serde_json::Value;

use crate::diagnose::{calibrated_set, diagnose, DiagnoseOptions, DiagnoseResult};
use crate::fit::{fit, FitOptions, FitResult, Progress};
use crate::spec::{CalibSpec, SpecError};

/// Relative bounds of every free parameter around its nominal value: `[lo·x₀, hi·x₀]`.
pub const RELATIVE_BOUNDS: (f64, f64) = (0.5, 2.0);

/// Length of the pre-event window every case is initialised from [s] (the practice README's
/// floor is computed from the first second).
pub const INIT_S: f64 = 1.0;

/// The 20 parameters a nominal model may get wrong, by stage, as `(section, PSS/E name, our
/// parameter)`. X''q follows X''d (tied: the practice units have X''q = X''d, as PSS/E's GENSAE).
pub const FREE: &[(&str, &str, &str, &str)] = &[
    ("gen", "machine", "H", "h"),
    ("gen", "machine", "Xd", "x_d"),
    ("gen", "machine", "Xq", "x_q"),
    ("gen", "machine", "Xpd", "x_d_prime"),
    ("gen", "machine", "Xppd", "x_d_pp"),
    ("gen", "machine", "Tpd0", "t_d0_prime"),
    ("gen", "machine", "Tppd0", "t_d0_pp"),
    ("gen", "machine", "Tppq0", "t_q0_pp"),
    ("avr", "exciter", "K", "k"),
    ("avr", "exciter", "TA_TB", "ta_tb"),
    ("avr", "exciter", "TB", "tb"),
    ("avr", "exciter", "TE", "te"),
    ("pss", "pss", "KX", "k_x"),
    ("pss", "pss", "TX1", "t_x1"),
    ("pss", "pss", "TX2", "t_x2"),
    ("tg", "governor", "R", "r_perm"),
    ("tg", "governor", "r", "r_temp"),
    ("tg", "governor", "Tr", "t_r"),
    ("tg", "governor", "Tg", "t_g"),
    ("tg", "governor", "Tw", "t_w"),
];

/// The calibratable parameters of the models a data family's unit may have in place of the
/// practice family's exciter and PSS (`data/families/other_unit`: ESST1A, IEEEST), as `(model,
/// stage, PSS/E name, our parameter)`: the exciter's gain, transient gain reduction and bridge lag
/// (as SEXS's K, TA/TB, TB, TE), the stabiliser's gain and lead time constants (as STAB3's KX,
/// TX1, TX2). A machine of another model (GENSAL) is freed by the machine rows of [`FREE`] (the
/// same parameters).
pub const FREE_OTHER_MODELS: &[(&str, &str, &str, &str)] = &[
    ("ESST1A", "avr", "KA", "k_a"),
    ("ESST1A", "avr", "TC", "t_c"),
    ("ESST1A", "avr", "TB", "t_b"),
    ("ESST1A", "avr", "TA", "t_a"),
    ("IEEEST", "pss", "KS", "ks"),
    ("IEEEST", "pss", "T1", "t1"),
    ("IEEEST", "pss", "T3", "t3"),
];

/// The practice family's exciter, PSS and governor models: the sections of [`FREE`] and
/// [`OTHER_NAMES`] other than the machine's are theirs. A `nominal.json` section of another
/// model gives its PSS/E names as they are (the unit file reads every model's PSS/E aliases).
const PRACTICE_MODELS: &[&str] = &["GENSAE", "SEXS", "STAB3", "HYGOV"];

/// The parameters [`practice_spec`] frees in `unit`, as `(stage, path)`: the rows of [`FREE`]
/// for the machine (any model that has them) and for the practice family's exciter, PSS and
/// governor, the rows of [`FREE_OTHER_MODELS`] for the models they name.
fn free_params(unit: &Unit) -> Vec<(&'static str, String)> {
    let model = |section: &str| unit.block(section).map(|b| b.model()).unwrap_or("");
    let mut out = vec![];
    for stage in ["gen", "avr", "pss", "tg"] {
        for (_, section, _, p) in FREE.iter().filter(|f| f.0 == stage) {
            if *section == "machine" || PRACTICE_MODELS.contains(&model(section)) {
                out.push((stage, format!("{section}.{p}")));
            }
        }
        for (m, _, _, p) in FREE_OTHER_MODELS.iter().filter(|f| f.1 == stage) {
            let section = if stage == "avr" { "exciter" } else { "pss" };
            if model(section) == *m {
                out.push((stage, format!("{section}.{p}")));
            }
        }
    }
    out
}

/// The nuisance set-point offsets freed with their stage (the floor in every key fits them).
const NUISANCE: &[(&str, &str, f64)] = &[
    ("avr", "exciter.v_ref_offset", 0.01),
    ("tg", "governor.n_ref_offset", 0.005),
];

/// PSS/E names of `nominal.json` → this project's parameter names, per section (the ones not
/// in [`FREE`]).
const OTHER_NAMES: &[(&str, &str, &str)] = &[
    ("machine", "D", "d"),
    ("machine", "Xppq", "x_q_pp"),
    ("machine", "Xl", "x_l"),
    ("machine", "S10", "s10"),
    ("machine", "S12", "s12"),
    ("machine", "R_a", "r_a"),
    ("exciter", "EMIN", "e_min"),
    ("exciter", "EMAX", "e_max"),
    ("pss", "Tt", "t_t"),
    ("pss", "VLIM", "v_lim"),
    ("governor", "Tf", "t_f"),
    ("governor", "VELM", "velm"),
    ("governor", "GMAX", "g_max"),
    ("governor", "GMIN", "g_min"),
    ("governor", "At", "a_t"),
    ("governor", "Dturb", "d_turb"),
    ("governor", "qNL", "q_nl"),
];

/// Keys of `nominal.json` sections that carry no model parameter.
const IGNORED: &[&str] = &["model", "in_service", "h0"];

/// One practice case as a user has it: the measured event and the nominal unit.
pub struct PracticeCase {
    pub name: String,
    pub dir: PathBuf,
    pub event: Event,
    pub unit: Unit,
}

/// Why a practice case, its answer key or the engine check could not be read or run. Messages
/// name the file and, where there is one, the key.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PracticeError {
    /// A file or folder could not be read.
    #[error("{0}")]
    Io(String),
    /// A file's content: JSON syntax, a missing or unknown key, a unit that does not build.
    #[error("{0}")]
    Format(String),
    /// The case's record (`data.csv`) or the event built from it.
    #[error("{0}")]
    Record(String),
    /// The engine check ([`truth_j`]): its spec, fit or playback.
    #[error("{0}")]
    Engine(String),
}

impl PracticeError {
    /// Short stable identifier of the variant (`"io"`, `"format"`, `"record"`, `"engine"`).
    pub fn kind(&self) -> &'static str {
        match self {
            PracticeError::Io(_) => "io",
            PracticeError::Format(_) => "format",
            PracticeError::Record(_) => "record",
            PracticeError::Engine(_) => "engine",
        }
    }
}

fn read_json(path: &Path) -> Result<Value, PracticeError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| PracticeError::Io(format!("{}: cannot read: {e}", path.display())))?;
    serde_json::from_str(&text)
        .map_err(|e| PracticeError::Format(format!("{}: {e}", path.display())))
}

fn our_name(section: &str, psse: &str) -> Option<&'static str> {
    FREE.iter()
        .find(|(_, s, p, _)| *s == section && *p == psse)
        .map(|(_, _, _, o)| *o)
        .or_else(|| {
            OTHER_NAMES
                .iter()
                .find(|(s, p, _)| *s == section && *p == psse)
                .map(|(_, _, o)| *o)
        })
}

/// The unit TOML of a `nominal.json` (every parameter mapped by name; an unknown name is an
/// error naming the file and the key, not dropped).
pub fn unit_toml_from_nominal(
    nominal: &Value,
    path: &Path,
    name: &str,
) -> Result<String, PracticeError> {
    let num = |v: &Value, field: &str| {
        v.as_f64().ok_or_else(|| {
            PracticeError::Format(format!("{}: {field}: not a number", path.display()))
        })
    };
    let bases = &nominal["bases"];
    let mut out = format!(
        "name = \"{name}-nominal\"\nmachine_mva = {}\nnominal_hz = {}\n",
        num(&bases["machine_mva"], "bases.machine_mva")?,
        num(&bases["f_nominal_hz"], "bases.f_nominal_hz")?,
    );
    for section in ["machine", "exciter", "pss", "governor"] {
        let Some(table) = nominal[section].as_object() else {
            continue;
        };
        let model = table.get("model").and_then(|m| m.as_str()).ok_or_else(|| {
            PracticeError::Format(format!("{}: {section}.model missing", path.display()))
        })?;
        // A PSS out of service is no PSS block (as the catalog's `pss_state` models it).
        if table.get("in_service").and_then(|v| v.as_bool()) == Some(false) {
            continue;
        }
        out.push_str(&format!("\n[{section}]\nmodel = \"{model}\"\n"));
        let practice_model = PRACTICE_MODELS.contains(&model);
        for (k, v) in table {
            if IGNORED.contains(&k.as_str()) {
                continue;
            }
            // Another model's PSS/E names go to the unit file as they are: it reads the model's
            // PSS/E aliases and names the file and the key of one it does not know.
            let ours = if practice_model {
                our_name(section, k).ok_or_else(|| {
                    PracticeError::Format(format!(
                        "{}: {section}.{k}: no such parameter of {model}",
                        path.display()
                    ))
                })?
            } else {
                k.as_str()
            };
            out.push_str(&format!(
                "{ours} = {}\n",
                num(v, &format!("{section}.{k}"))?
            ));
        }
    }
    Ok(out)
}

impl PracticeCase {
    /// Reads case `dir` (`data.csv`, `nominal.json`); never the answer key.
    pub fn load(dir: &Path) -> Result<PracticeCase, PracticeError> {
        let name = dir
            .file_name()
            .map(|n| n.to_string_lossy().to_string())
            .unwrap_or_else(|| "case".into());
        let nominal_path = dir.join("nominal.json");
        let nominal = read_json(&nominal_path)?;
        let text = unit_toml_from_nominal(&nominal, &nominal_path, &name)?;
        let unit =
            parse_unit(&text, &nominal_path).map_err(|e| PracticeError::Format(e.to_string()))?;
        let system_mva = nominal["bases"]["system_mva"].as_f64().ok_or_else(|| {
            PracticeError::Format(format!(
                "{}: bases.system_mva missing",
                nominal_path.display()
            ))
        })?;
        let csv = dir.join("data.csv");
        let record =
            read_csv(&csv, unit.nominal_hz).map_err(|e| PracticeError::Record(e.to_string()))?;
        let t0 = record.start_s();
        let event = Event::from_record(
            &name,
            record,
            system_mva,
            unit.nominal_hz,
            Some(Window::new(t0, t0 + INIT_S)),
            None,
        )
        .map_err(|e| PracticeError::Record(e.to_string()))?;
        Ok(PracticeCase {
            name,
            dir: dir.to_path_buf(),
            event,
            unit,
        })
    }
}

/// The one calibration spec of the practice set, for `unit` (the nominal model) and the record
/// of `event`: every parameter of [`FREE`] whose block the unit has (for a unit with an ESST1A
/// or IEEEST, those of [`FREE_OTHER_MODELS`] in their place), within [`RELATIVE_BOUNDS`] of its
/// nominal value, stages gen, avr, pss, tg, default search settings; X''q tied to X''d.
///
/// Every stage and the joint pass compare `channels = "recorded"` ([`Channels::Recorded`]):
/// P and Q, and every field channel the record holds (E_fd, X_ad I_fd) weighted by its noise,
/// as an engineer with those recordings would: P and Q alone leave X_d and the exciter's gain
/// free to bend so that the field runs off by many noise widths, which hides a ceiling or a
/// saturation inside the calibration. A record without them is fitted on P and Q.
///
/// [`Channels::Recorded`]: crate::spec::Channels::Recorded
pub fn practice_spec(unit: &Unit) -> Result<CalibSpec, SpecError> {
    let (lo, hi) = RELATIVE_BOUNDS;
    let mut text = String::from("[calibration]\n");
    let compare = "channels = \"recorded\"\n";
    let params = free_params(unit);
    for stage in ["gen", "avr", "pss", "tg"] {
        let mut free = vec![];
        for (_, path) in params.iter().filter(|f| f.0 == stage) {
            if let Ok(r) = unit.param(path) {
                let x0 = unit.get(r);
                free.push(format!(
                    "  {{ param = \"{path}\", min = {}, max = {} }},\n",
                    lo * x0,
                    hi * x0
                ));
            }
        }
        for (s, path, b) in NUISANCE {
            if *s == stage && unit.param(path).is_ok() {
                free.push(format!(
                    "  {{ param = \"{path}\", min = {}, max = {b} }},\n",
                    -b
                ));
            }
        }
        if free.is_empty() {
            continue;
        }
        text.push_str(&format!(
            "\n[[calibration.stage]]\nname = \"{stage}\"\n{compare}"
        ));
        if stage == "gen" {
            text.push_str("tie = { \"machine.x_q_pp\" = \"machine.x_d_pp\" }\n");
        }
        text.push_str("free = [\n");
        for f in free {
            text.push_str(&f);
        }
        text.push_str("]\n");
    }
    text.push_str(&format!("\n[calibration.joint]\n{compare}"));
    CalibSpec::parse(&text, Path::new("<practice spec>"))
}

/// What the scoring step reads of `answers/<case>.json`.
#[derive(Debug, Clone)]
pub struct AnswerKey {
    /// The catalog cause that should be named (`none` for a clean case).
    pub cause: String,
    pub effect: String,
    pub variant: String,
    /// J of the true parameters without / with the effect (set-point offsets fitted).
    pub floor_j: f64,
    pub floor_j_with_effect: f64,
    /// The key parameter to score: (our parameter, true value, tolerance, relative?).
    pub key: Option<KeyParam>,
    /// The parameters the nominal model gets wrong: (our path, nominal, true).
    pub nominal_errors: Vec<(String, f64, f64)>,
}

/// A scored parameter of the named extension.
#[derive(Debug, Clone)]
pub struct KeyParam {
    /// What is compared, in words.
    pub what: String,
    /// Parameters of the extension whose product (or single value) is compared.
    pub params: Vec<String>,
    pub truth: f64,
    /// Absolute tolerance.
    pub tol: f64,
}

impl AnswerKey {
    /// Reads `answers/<case>.json` beside `cases/`.
    pub fn read(practice_root: &Path, case: &str) -> Result<AnswerKey, PracticeError> {
        let path = practice_root.join("answers").join(format!("{case}.json"));
        let a = read_json(&path)?;
        let effect = a["hidden_effect"]["type"]
            .as_str()
            .unwrap_or("none")
            .to_string();
        let variant = a["hidden_effect"]["variant"]
            .as_str()
            .unwrap_or("")
            .to_string();
        // A family's key may name the cause itself (`unexplained` for an effect outside the
        // catalog); the practice keys name the effect only.
        let named_cause = a["hidden_effect"]["cause"].as_str().map(str::to_string);
        let cause = match effect.as_str() {
            "torsional" => "torsional_mode",
            "exciter_ceiling" => "exciter_limit",
            "saturation" => "saturation",
            "governor_deadband" => "governor",
            "measurement_skew" => "measurement_skew",
            "terminal_load" => "terminal_load",
            "pss_missing" => "pss_state",
            "oel" => "oel",
            _ => "none",
        }
        .to_string();
        let cause = named_cause.unwrap_or(cause);
        let oracle = &a["diagnostics"]["oracle"];
        let n = a["pmu"]["samples"].as_f64().unwrap_or(0.0);
        let j = |k: &str| {
            let p = oracle[k]["P"]["rms"].as_f64().unwrap_or(f64::NAN);
            let q = oracle[k]["Q"]["rms"].as_f64().unwrap_or(f64::NAN);
            n * (p * p + q * q)
        };
        let hp = &a["hidden_effect"]["params"];
        let rate = a["pmu"]["rate_sps"].as_f64().unwrap_or(60.0);
        let f = |k: &str| hp[k].as_f64().unwrap_or(f64::NAN);
        let key = match effect.as_str() {
            "torsional" => Some(KeyParam {
                what: "torsional mode [Hz]".into(),
                params: vec!["shaft.f_torsion_hz".into()],
                truth: f("f_tor_hz"),
                tol: 0.05 * f("f_tor_hz"),
            }),
            "measurement_skew" => Some(KeyParam {
                what: "P/Q delay [s]".into(),
                params: vec!["measurement.pq_delay_s".into()],
                truth: f("skew_s"),
                tol: 0.5 / rate,
            }),
            "exciter_ceiling" if variant == "constant" => Some(KeyParam {
                what: "E_fd ceiling [pu]".into(),
                params: vec!["exciter.e_max".into()],
                truth: f("EMAX"),
                tol: 0.05 * f("EMAX"),
            }),
            "oel" => Some(KeyParam {
                what: "OEL pickup current X_adI_fd [pu]".into(),
                params: vec!["oel.ifd_rated".into(), "oel.i_pickup".into()],
                truth: f("ifd_rated") * f("I_pu"),
                tol: 0.05 * f("ifd_rated") * f("I_pu"),
            }),
            _ => None,
        };
        let mut nominal_errors = vec![];
        if let Some(errs) = a["nominal_errors"].as_object() {
            for (k, v) in errs {
                let (section, psse) = k.split_once('.').unwrap_or(("", k));
                let ours = our_name(section, psse).unwrap_or(psse);
                nominal_errors.push((
                    format!("{section}.{ours}"),
                    v["nominal"].as_f64().unwrap_or(f64::NAN),
                    v["true"].as_f64().unwrap_or(f64::NAN),
                ));
            }
        }
        Ok(AnswerKey {
            cause,
            effect,
            variant,
            floor_j: j("true_params_without_effect"),
            floor_j_with_effect: j("true_params_with_effect"),
            key,
            nominal_errors,
        })
    }
}

/// The protocol's diagnosis options: the whole calibrated set of `spec`'s `stages` re-freed in
/// every re-fit, with the calibration's prior around the case's nominal unit (what
/// `itaipu-calib diagnose --fit` does with a fit's outputs).
pub fn diagnose_options(
    case: &PracticeCase,
    spec: &CalibSpec,
    stages: &[String],
    calibrated: &Unit,
) -> DiagnoseOptions {
    DiagnoseOptions {
        refit: calibrated_set(spec, stages, &case.unit, calibrated),
        ..Default::default()
    }
}

/// The whole protocol on one case, as a user would run it: the default staged fit of the
/// nominal unit with the one [`practice_spec`], then `diagnose` on the calibrated unit with
/// [`diagnose_options`]. The answer key is not read.
pub fn fit_and_diagnose(
    case: &PracticeCase,
    progress: &dyn Progress,
) -> Result<(FitResult, DiagnoseResult), PracticeError> {
    let engine = |e: &dyn std::fmt::Display| PracticeError::Engine(format!("{}: {e}", case.name));
    let spec = practice_spec(&case.unit).map_err(|e| engine(&e))?;
    let opts = FitOptions::from_spec(&spec);
    let events = std::slice::from_ref(&case.event);
    let fitted = fit(&case.unit, &spec, events, &[], &opts, progress).map_err(|e| engine(&e))?;
    let d = diagnose(
        &fitted.unit,
        events,
        &[],
        &diagnose_options(case, &spec, &opts.stages, &fitted.unit),
        progress,
    )
    .map_err(|e| engine(&e))?;
    Ok((fitted, d))
}

/// The true unit of a case without its hidden effect (`true_unit` of the answer key), for the
/// engine check: the key's floor J is the playback of the record through it with the set-point
/// offsets fitted. Reads the answer key: never used by a calibration or a diagnosis.
pub fn true_unit(practice_root: &Path, case: &str) -> Result<Unit, PracticeError> {
    let path = practice_root.join("answers").join(format!("{case}.json"));
    let a = read_json(&path)?;
    let mut t = a["true_unit"].clone();
    // The practice keys' units are all 737 MVA; a family's key states its unit's base.
    let mva = a["true_unit"]["machine_mva"].as_f64().unwrap_or(737.0);
    t["bases"] = serde_json::json!({"machine_mva": mva, "f_nominal_hz": a["true_unit"]["fn_hz"]});
    let text = unit_toml_from_nominal(&t, &path, case)?;
    parse_unit(&text, &path).map_err(|e| PracticeError::Format(e.to_string()))
}

/// The engine check: J of the case's true unit (from the key, [`true_unit`]) on its event with
/// only the two set-point offsets fitted (no prior, local method only), which the key's floor
/// J is (for a case whose effect is not part of the true unit's parameters). Reads the key.
/// The event is played back as recorded whatever its `input_lowpass_hz`: the key's floor is the
/// true unit driven by the recorded voltage.
pub fn truth_j(practice_root: &Path, case: &PracticeCase) -> Result<f64, PracticeError> {
    let truth = true_unit(practice_root, &case.name)?;
    let mut event = case.event.clone();
    event.input_lowpass_hz = None;
    let mut text =
        String::from("[calibration]\nprior = 0\n[[calibration.stage]]\nname = \"tg\"\nfree = [\n");
    for (_, path, b) in NUISANCE {
        text.push_str(&format!(
            "  {{ param = \"{path}\", min = {}, max = {b} }},\n",
            -b
        ));
    }
    text.push_str("]\n");
    let spec = CalibSpec::parse(&text, Path::new("<offsets>"))
        .map_err(|e| PracticeError::Engine(e.to_string()))?;
    let mut opts = crate::fit::FitOptions::from_spec(&spec);
    opts.pso_iterations = 0;
    let events = std::slice::from_ref(&event);
    let r = crate::fit::fit(&truth, &spec, events, &[], &opts, &crate::fit::Silent)
        .map_err(|e| PracticeError::Engine(e.to_string()))?;
    crate::fit::fitness(&r.unit, &event, false)
        .map(|(f, _)| f.j_pq)
        .map_err(|e| PracticeError::Engine(e.to_string()))
}

/// The case folders of a practice root (`<root>/cases/*`), sorted.
pub fn case_dirs(root: &Path) -> Result<Vec<PathBuf>, PracticeError> {
    let cases = root.join("cases");
    let mut v: Vec<PathBuf> = std::fs::read_dir(&cases)
        .map_err(|e| PracticeError::Io(format!("{}: {e}", cases.display())))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join("nominal.json").exists())
        .collect();
    v.sort();
    Ok(v)
}

/// What one case gave and how it scores against its key.
#[derive(Debug, Clone, serde::Serialize)]
pub struct CaseScore {
    pub case: String,
    pub hidden: String,
    /// J = Σ ΔP² + ΔQ² of the calibrated unit (the default `fit --stage all`).
    pub j_fit: f64,
    /// J of the true parameters without the effect (the key's floor).
    pub floor_j: f64,
    pub fit_ratio: f64,
    pub fit_s: f64,
    /// The diagnosis verdict (None when not run).
    pub named: Option<String>,
    pub cause_ok: Option<bool>,
    /// Key parameter: what, truth, found, within tolerance.
    pub key: Option<(String, f64, Option<f64>, bool)>,
    pub diagnose_s: f64,
    /// Calibrated / true value of the parameters the nominal got wrong.
    pub nominal_errors: Vec<(String, f64, f64, f64)>,
    /// The named cause's grade (`strong`, `moderate`), when one is named.
    pub grade: Option<String>,
    /// The named cause's stated posterior probability, when one is named.
    pub probability: Option<f64>,
}

impl CaseScore {
    /// How the verdict scores against the key: `right` (the hidden cause, or `none` on a clean
    /// case), `wrong name` (a cause named that is not the hidden one: the worst outcome, an
    /// engineer acts on it), `miss` (an effect case diagnosed `none`, `unexplained` or
    /// `inconclusive`), `false alarm` (a clean case diagnosed anything but `none`), `not run`.
    pub fn outcome(&self) -> &'static str {
        let Some(named) = &self.named else {
            return "not run";
        };
        let names_a_cause = !crate::diagnose::NO_CAUSE_VERDICTS.contains(&named.as_str())
            && !named.starts_with("error");
        if self.cause_ok == Some(true) {
            "right"
        } else if self.hidden == "none" {
            "false alarm"
        } else if names_a_cause {
            "wrong name"
        } else {
            "miss"
        }
    }
}

/// Scores a calibrated unit and an optional diagnosis against the key.
pub fn score(
    case: &str,
    key: &AnswerKey,
    calibrated: &Unit,
    j_fit: f64,
    fit_s: f64,
    diagnosis: Option<(&str, Option<&Unit>, f64)>,
) -> CaseScore {
    let nominal_errors = key
        .nominal_errors
        .iter()
        .map(|(p, nom, truth)| {
            let got = calibrated
                .param(p)
                .map(|r| calibrated.get(r))
                .unwrap_or(f64::NAN);
            (p.clone(), *nom, *truth, got)
        })
        .collect();
    let (named, cause_ok, key_score, diagnose_s) = match diagnosis {
        None => (None, None, None, 0.0),
        Some((named, extended, secs)) => {
            let ok = named == key.cause;
            let k = key.key.as_ref().map(|k| {
                let found = if ok {
                    extended.and_then(|u| {
                        k.params
                            .iter()
                            .map(|p| u.param(p).ok().map(|r| u.get(r)))
                            .product::<Option<f64>>()
                    })
                } else {
                    None
                };
                let within = found.is_some_and(|f| (f - k.truth).abs() <= k.tol);
                (k.what.clone(), k.truth, found, within)
            });
            (Some(named.to_string()), Some(ok), k, secs)
        }
    };
    CaseScore {
        case: case.to_string(),
        hidden: key.cause.clone(),
        j_fit,
        floor_j: key.floor_j,
        fit_ratio: j_fit / key.floor_j,
        fit_s,
        named,
        cause_ok,
        key: key_score,
        diagnose_s,
        nominal_errors,
        grade: None,
        probability: None,
    }
}

/// The practice examples' `INPUT_LOWPASS_HZ`: a cut-off in Hz (`Some(Some(f))`), `none` to play
/// the records back as recorded (`Some(None)`), or unset (`None`: each event's default,
/// [`itaipu_dynamics::event::smoothing::default_cutoff`]).
///
/// # Errors
/// A value that is neither a number nor `none`.
pub fn input_lowpass_env() -> Result<Option<Option<f64>>, String> {
    let Ok(s) = std::env::var("INPUT_LOWPASS_HZ") else {
        return Ok(None);
    };
    if s.trim().eq_ignore_ascii_case("none") {
        return Ok(Some(None));
    }
    s.trim()
        .parse()
        .map(|f| Some(Some(f)))
        .map_err(|_| format!("INPUT_LOWPASS_HZ={s}: expected a cut-off in Hz or none"))
}

//! Effects outside the catalog (issue 26, item 4), hidden through user-defined diagrams and run
//! through the practice protocol: for each trial the truth is the bundled synthetic unit with a
//! cause file's block hidden in it (`data/causes/*.toml`, `UserCause::hide`), the record is
//! synthesised from it with PMU noise (fixed seed), then the nominal unit is calibrated with the
//! one practice spec and diagnosed with the whole catalog and no user cause, as a user would;
//! the verdict must not be a catalog cause (an engineer would act on it). The same calibrated
//! unit is then diagnosed again with the matching cause file (`--user-cause`), which may name it.
//!
//! `cargo run --release -p itaipu-calib --example outside_catalog [FILE…]` (about 1 min per trial
//! on 2 cores; with arguments, only the trials whose cause file contains one of them). Prints one line per trial: the effect's largest change of P and Q on the noiseless
//! record, the fitted J, the verdict without and with the cause file, and whether a catalog
//! cause was named (`WRONG`). `INPUT_LOWPASS_HZ=f` plays each record's |V| and angle back
//! low-passed at `f` Hz between their edges instead of the default 4 Hz, `none` as recorded
//! (`Event::set_input_lowpass`).

use std::path::{Path, PathBuf};
use std::time::Instant;

use itaipu_calib::diagnose::trial::{base_unit, probe, trial_noise};
use itaipu_calib::diagnose::user_cause::UserCause;
use itaipu_calib::diagnose::{catalog, diagnose};
use itaipu_calib::fit::{FitOptions, Silent};
use itaipu_calib::practice::{diagnose_options, fit_and_diagnose, practice_spec, PracticeCase};
use itaipu_dynamics::simulate::{simulate, SimOptions, Traces};
use itaipu_dynamics::synthetic::{synthesize, EventKind, VoltageProfile};

/// One effect hidden in the truth: the cause file, the parameter set, its value, the event.
struct Trial {
    file: &'static str,
    param: &'static str,
    value: f64,
    kind: EventKind,
}

const TRIALS: &[Trial] = &[
    Trial {
        file: "reactive_droop.toml",
        param: "droop.x_c",
        value: 0.06,
        kind: EventKind::FaultDip,
    },
    Trial {
        file: "avr_transducer.toml",
        param: "transducer.t_r",
        value: 0.08,
        kind: EventKind::FaultDip,
    },
    Trial {
        file: "avr_transducer.toml",
        param: "transducer.t_r",
        value: 0.15,
        kind: EventKind::VoltageStep,
    },
    Trial {
        file: "governor_speed_filter.toml",
        param: "speed_filter.t_f",
        value: 0.45,
        kind: EventKind::FrequencyExcursion,
    },
    // Added at stop 47: the same files at other strengths and events, and two effects of other
    // kinds (a phase-lead stage the PSS model lacks, an under-excitation limiter the datasheet omits).
    Trial {
        file: "reactive_droop.toml",
        param: "droop.x_c",
        value: 0.03,
        kind: EventKind::FaultDip,
    },
    Trial {
        file: "reactive_droop.toml",
        param: "droop.x_c",
        value: 0.05,
        kind: EventKind::VoltageStep,
    },
    Trial {
        file: "avr_transducer.toml",
        param: "transducer.t_r",
        value: 0.3,
        kind: EventKind::FaultDip,
    },
    Trial {
        file: "governor_speed_filter.toml",
        param: "speed_filter.t_f",
        value: 1.0,
        kind: EventKind::FrequencyExcursion,
    },
    Trial {
        file: "pss_lead_lag.toml",
        param: "pss_comp.t_lead",
        value: 0.4,
        kind: EventKind::FaultDip,
    },
    Trial {
        file: "uel.toml",
        param: "uel.q_min",
        value: -0.1,
        kind: EventKind::VoltageStep,
    },
    // Added at the end of stop 47, run once with its rules in place: the last but two is a
    // wrong name the rules do not catch (a strong droop on a dip named `saturation`).
    Trial {
        file: "pss_lead_lag.toml",
        param: "pss_comp.t_lead",
        value: 1.0,
        kind: EventKind::FaultDip,
    },
    Trial {
        file: "pss_lead_lag.toml",
        param: "pss_comp.t_lead",
        value: 0.03,
        kind: EventKind::FaultDip,
    },
    Trial {
        file: "avr_transducer.toml",
        param: "transducer.t_r",
        value: 0.3,
        kind: EventKind::VoltageStep,
    },
    Trial {
        file: "governor_speed_filter.toml",
        param: "speed_filter.t_f",
        value: 1.0,
        kind: EventKind::FaultDip,
    },
    Trial {
        file: "reactive_droop.toml",
        param: "droop.x_c",
        value: 0.1,
        kind: EventKind::FaultDip,
    },
    Trial {
        file: "reactive_droop.toml",
        param: "droop.x_c",
        value: 0.02,
        kind: EventKind::VoltageStep,
    },
    Trial {
        file: "reactive_droop.toml",
        param: "droop.x_c",
        value: 0.05,
        kind: EventKind::FrequencyExcursion,
    },
];

/// The record length [s], rate [samples/s] and system base [MVA] of every trial.
const DURATION_S: f64 = 20.0;
const RATE_HZ: f64 = 60.0;
const BASE_MVA: f64 = 737.0;
const SEED: u64 = 11;

fn causes_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/causes")
}

fn largest_change(a: &Traces, b: &Traces, signal: &str) -> f64 {
    let (x, y) = (a.get(signal).unwrap(), b.get(signal).unwrap());
    x.iter()
        .zip(y)
        .map(|(p, q)| (p - q).abs())
        .fold(0.0, f64::max)
}

/// A verdict's cause; an `unexplained` that a look-alike outside the catalog explains says
/// which (`unexplained~reactive_droop`).
fn label(v: &itaipu_calib::diagnose::Verdict) -> String {
    match v.competing.first() {
        Some((c, _)) if v.cause == "unexplained" => format!("unexplained~{c}"),
        _ => v.cause.to_string(),
    }
}

fn main() {
    let base = base_unit();
    let sim = SimOptions::default();
    println!(
        "{:<27} {:<7} {:>6} {:>8} {:>8} {:>8} {:<30} {:<38} {:>6}",
        "cause file",
        "event",
        "value",
        "max dP",
        "max dQ",
        "J fit",
        "verdict",
        "with its cause file",
        "s"
    );
    // Optional arguments: run only the trials whose cause file contains one of them.
    let only: Vec<String> = std::env::args().skip(1).collect();
    let trials: Vec<&Trial> = TRIALS
        .iter()
        .filter(|t| only.is_empty() || only.iter().any(|o| t.file.contains(o.as_str())))
        .collect();
    let mut wrong = 0;
    for t in &trials {
        let t0 = Instant::now();
        let cause = UserCause::read(&causes_dir().join(t.file)).unwrap_or_else(|e| panic!("{e}"));
        let profile = VoltageProfile::preset(t.kind, DURATION_S, RATE_HZ, SEED);
        let (noiseless, ctx) = probe(&base, &profile).unwrap_or_else(|e| panic!("{e}"));
        let truth = cause
            .hide(&base, &ctx, &[(t.param, t.value)])
            .unwrap_or_else(|e| panic!("{e}"));
        let (with, without) = (
            simulate(&truth, &noiseless, &sim).expect("the truth plays back"),
            simulate(&base, &noiseless, &sim).expect("the base plays back"),
        );
        let (dp, dq) = (
            largest_change(&with, &without, "pe"),
            largest_change(&with, &without, "qe"),
        );
        let event = synthesize(
            "trial",
            &truth,
            &profile,
            BASE_MVA,
            &trial_noise(SEED),
            &sim,
        )
        .expect("the truth plays back the preset");
        let mut event = event;
        if let Some(fc) = itaipu_calib::practice::input_lowpass_env().expect("INPUT_LOWPASS_HZ") {
            event.set_input_lowpass(fc).expect("a uniform record");
        }
        let case = PracticeCase {
            name: t.file.into(),
            dir: PathBuf::from("."),
            event,
            unit: base.clone(),
        };
        let (fitted, d) = fit_and_diagnose(&case, &Silent).unwrap_or_else(|e| panic!("{e}"));
        // OUT=DIR keeps each diagnosis as DIR/<file>-<event>-<value>[-with].json.
        let name = format!(
            "{}-{:?}-{}",
            t.file.trim_end_matches(".toml"),
            t.kind,
            t.value
        );
        let keep = |suffix: &str, report: &itaipu_calib::diagnose::Diagnosis| {
            if let (Ok(dir), Ok(text)) =
                (std::env::var("OUT"), serde_json::to_string_pretty(report))
            {
                std::fs::create_dir_all(&dir).ok();
                std::fs::write(Path::new(&dir).join(format!("{name}{suffix}.json")), text).ok();
            }
        };
        keep("", &d.report);
        let catalog_named = catalog::find(d.report.verdict.cause.as_str()).is_some();
        let verdict = label(&d.report.verdict);
        wrong += usize::from(catalog_named);
        // The same calibrated unit, diagnosed with the cause file as well.
        let spec = practice_spec(&case.unit).expect("the practice spec");
        let opts = FitOptions::from_spec(&spec);
        let mut dopts = diagnose_options(&case, &spec, &opts.stages, &fitted.unit);
        dopts.user_causes = vec![cause.clone()];
        let with_file = diagnose(
            &fitted.unit,
            std::slice::from_ref(&case.event),
            &[],
            &dopts,
            &Silent,
        )
        .map(|d| {
            keep("-with", &d.report);
            let v = &d.report.verdict;
            match v.key_parameters.iter().find(|(p, _, _)| p == t.param) {
                Some((_, x, _)) => format!("{} ({}={x:.3})", v.cause, t.param),
                None => label(v),
            }
        })
        .unwrap_or_else(|e| format!("error: {e}"));
        println!(
            "{:<27} {:<7} {:>6} {:>8.4} {:>8.4} {:>8.5} {:<30} {:<38} {:>6.1}",
            t.file,
            match t.kind {
                EventKind::FaultDip => "dip",
                EventKind::VoltageStep => "step",
                EventKind::FrequencyExcursion => "freq",
                EventKind::Ambient => "ambient",
            },
            t.value,
            dp,
            dq,
            fitted
                .report
                .stages
                .last()
                .map_or(f64::NAN, |s| s.objective_after),
            if catalog_named {
                format!("{verdict} WRONG")
            } else {
                verdict
            },
            with_file,
            t0.elapsed().as_secs_f64()
        );
    }
    println!(
        "catalog causes named for effects outside the catalog: {wrong} of {}",
        trials.len()
    );
}

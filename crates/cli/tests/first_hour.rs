//! A new user's first hour with the `itaipu-calib` binary on the bundled data (issue 62): one
//! headline for one unit and record from `fit` and `diagnose`, a truncated COMTRADE record
//! warned of everywhere (or refused), a missing file named as missing, reports that say what
//! each number compares, a terminal that says each thing once, and help text that matches the
//! code.

use std::path::{Path, PathBuf};
use std::process::Command;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn tmp(tag: &str) -> PathBuf {
    let p = std::env::temp_dir().join(format!("itaipu-hour-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&p);
    std::fs::create_dir_all(&p).unwrap();
    p
}

/// Runs the binary in the repository: (exit code, stdout, stderr).
fn run(args: &[&str]) -> (i32, String, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_itaipu-calib"))
        .current_dir(repo())
        .args(args)
        .output()
        .unwrap();
    (
        o.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

fn json(p: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A quick search: the path through the commands, not the optimum, is under test.
const QUICK: [&str; 6] = [
    "--particles",
    "6",
    "--pso-iterations",
    "4",
    "--local-iterations",
    "3",
];

/// The README's path (COMTRADE import, fit of the .dyr, diagnose of the fit): the fit's report
/// and the diagnosis of its calibrated unit give one headline, the same number, σ and words,
/// and the diagnosis' evidence is against the σ its noise table shows.
#[test]
fn fit_and_diagnose_of_one_unit_and_record_give_one_headline() {
    let t = tmp("headline");
    let ev = t.join("ev");
    let (code, out, err) = run(&[
        "import",
        "data/itaipu/pmu/itaipu.cfg",
        "--system-mva",
        "1000",
        "--nominal-hz",
        "60",
        "--v-base-kv",
        "18",
        "--out",
        s(&ev),
    ]);
    assert_eq!(code, 0, "{err}");
    // The import warns of the record's end drop-out, and import.json keeps it.
    assert!(out.contains("measurement drop-out"), "{out}");
    let imp = json(&ev.join("import.json"));
    assert!(
        imp["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .any(|w| w.as_str().unwrap().contains("drop-out")),
        "{imp}"
    );
    assert_eq!(imp["samples_declared"], 280);

    let fit = t.join("fit");
    let event = ev.join("event.toml");
    let mut args = vec![
        "fit",
        "--event",
        s(&event),
        "--unit",
        "data/itaipu/unit.dyr",
        "--calib",
        "data/itaipu/calibration.toml",
        "--stage",
        "gen",
        "--no-plot",
        "--out",
        s(&fit),
    ];
    args.extend(QUICK);
    let (code, fit_out, err) = run(&args);
    assert_eq!(code, 0, "{err}");
    // Progress in a log: a line per phase, no iteration lines.
    assert!(!err.contains("best objective"), "{err}");
    // Each warning once: the drop-out said before the run is not repeated after it.
    let said = |text: &str| (fit_out.clone() + &err).matches(text).count();
    assert_eq!(
        said("the record ends in a measurement drop-out"),
        1,
        "{err}{fit_out}"
    );

    let diag = t.join("diag");
    let mut args = vec![
        "diagnose",
        "--event",
        s(&event),
        "--fit",
        s(&fit),
        "--cause",
        "saturation",
        "--no-plot",
        "--out",
        s(&diag),
    ];
    args.extend(QUICK);
    let (code, diag_out, err) = run(&args);
    assert_eq!(code, 0, "{err}");
    // A log gets a few summary lines, not a line per re-fit phase and iteration.
    let progress = err.lines().filter(|l| !l.starts_with("warning:")).count();
    assert!(progress <= 12, "{progress} lines:\n{err}");

    let f = json(&fit.join("report.json"));
    let d = json(&diag.join("diagnosis.json"));
    let (hf, hd) = (&f["headline"], &d["headline"]);
    assert!(hf["worst"].as_f64().unwrap() > 1.0, "{hf}");
    assert_eq!(hf["worst"], hd["worst"], "fit {hf}\ndiagnosis {hd}");
    assert_eq!(hf["sigma"], hd["sigma"]);
    assert_eq!(hf["sentence"], hd["sentence"]);
    let sentence = hf["sentence"].as_str().unwrap();
    assert!(sentence.contains("× the noise σ"), "{sentence}");
    // The same sentence on the terminal, in both HTML reports (markup aside).
    assert!(fit_out.contains(sentence), "{fit_out}");
    assert!(
        diag_out.replace("\n         ", " ").contains(sentence),
        "{diag_out}"
    );
    let text = |p: &Path| {
        let html = std::fs::read_to_string(p).unwrap();
        let mut out = String::new();
        let mut tag = false;
        for c in html.chars() {
            match c {
                '<' => tag = true,
                '>' => tag = false,
                c if !tag => out.push(c),
                _ => {}
            }
        }
        out.replace("&#39;", "'")
    };
    for page in [fit.join("report.html"), diag.join("report.html")] {
        assert!(text(&page).contains(sentence), "{}", page.display());
    }
    // The fit's noise table and the diagnosis' σ, noise table and evidence: one number each.
    let sp = f["noise"][0]["sigma_p"].as_f64().unwrap();
    assert_eq!(d["noise"]["sigma_p"].as_f64().unwrap(), sp);
    for sig in d["evidence"][0]["signals"].as_array().unwrap() {
        let name = sig["signal"].as_str().unwrap();
        let table = d["noise"]["sigmas"]
            .as_array()
            .unwrap()
            .iter()
            .find(|x| x[0] == name)
            .unwrap()[1]
            .as_f64()
            .unwrap();
        assert_eq!(sig["noise_floor_rms"].as_f64().unwrap(), table, "{name}");
    }
    // The fit report's events table counts samples (no `null`).
    assert!(!text(&fit.join("report.html")).contains("null"));
    let _ = std::fs::remove_dir_all(&t);
}

/// A COMTRADE `.dat` cut at a record boundary: imported with a warning that import.json,
/// event.toml and every later report repeat, or refused with `--refuse-truncated`.
#[test]
fn a_truncated_comtrade_record_is_warned_of_everywhere_or_refused() {
    let t = tmp("trunc");
    let rec = t.join("rec");
    std::fs::create_dir_all(&rec).unwrap();
    std::fs::copy(
        repo().join("data/itaipu/pmu/itaipu.cfg"),
        rec.join("itaipu.cfg"),
    )
    .unwrap();
    let dat = std::fs::read(repo().join("data/itaipu/pmu/itaipu.dat")).unwrap();
    // 125 of the 280 records (24 bytes each: sample number, time stamp, four 32-bit channels).
    let record = dat.len() / 280;
    std::fs::write(rec.join("itaipu.dat"), &dat[..125 * record]).unwrap();
    let cfg = rec.join("itaipu.cfg");
    let import = |out: &Path, extra: &[&str]| {
        let mut a = vec![
            "import",
            s(&cfg),
            "--system-mva",
            "1000",
            "--nominal-hz",
            "60",
            "--v-base-kv",
            "18",
            "--out",
            s(out),
        ];
        a.extend_from_slice(extra);
        run(&a)
    };
    let (code, _, err) = import(&t.join("refused"), &["--refuse-truncated"]);
    assert_eq!(code, 3, "{err}");
    assert!(
        err.contains("holds 125 samples") && err.contains("declares 280"),
        "{err}"
    );
    assert!(!t.join("refused").exists());

    let ev = t.join("ev");
    let (code, out, err) = import(&ev, &[]);
    assert_eq!(code, 0, "{err}");
    assert!(
        out.contains("125 samples read") && out.contains("truncated"),
        "{out}"
    );
    let imp = json(&ev.join("import.json"));
    assert_eq!(imp["samples_declared"], 280);
    assert_eq!(imp["samples_read"], 125);
    assert!(imp["warnings"].to_string().contains("truncated"), "{imp}");
    assert!(std::fs::read_to_string(ev.join("event.toml"))
        .unwrap()
        .contains("import_notes"));
    // Every command that reads the event says it again, and its report keeps it.
    let fit = t.join("fit");
    let event = ev.join("event.toml");
    let mut args = vec![
        "fit",
        "--event",
        s(&event),
        "--stage",
        "gen",
        "--no-plot",
        "--out",
        s(&fit),
    ];
    args.extend(QUICK);
    let (code, _, err) = run(&args);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("truncated"), "{err}");
    let kinds: Vec<String> = json(&fit.join("report.json"))["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w["kind"].as_str().unwrap().to_string())
        .collect();
    assert!(kinds.contains(&"import".to_string()), "{kinds:?}");
    let _ = std::fs::remove_dir_all(&t);
}

/// A file that is not there is said to be missing, not a missing side file's base.
#[test]
fn a_missing_unit_file_is_named_as_missing() {
    for args in [
        vec!["dyr", "read", "nope.dyr"],
        vec![
            "fit",
            "--unit",
            "nope.dyr",
            "--calib",
            "data/itaipu/calibration.toml",
        ],
    ] {
        let (code, _, err) = run(&args);
        assert_eq!(code, 4, "{args:?}: {err}");
        assert!(
            err.contains("nope.dyr: cannot read") && err.contains("No such file"),
            "{args:?}: {err}"
        );
        assert!(!err.contains("mbase"), "{args:?}: {err}");
    }
}

/// `simulate --mode exciter_alone` headlines the E_fd it compares; a fit with playback modes
/// reports every compared channel's noise, each stage's comparison, and one J column per mode.
#[test]
fn playback_modes_are_reported_by_what_they_compare() {
    let t = tmp("modes");
    let (code, out, err) = run(&[
        "simulate",
        "--event",
        "data/mostar/event.toml",
        "--unit",
        "data/mostar/calibrated.toml",
        "--mode",
        "exciter_alone",
        "--no-plot",
        "--out",
        s(&t.join("sim")),
    ]);
    assert_eq!(code, 0, "{err}");
    let misfit = out.lines().find(|l| l.starts_with("misfit")).unwrap();
    assert!(
        misfit.contains("RMS efd") && !misfit.contains("RMS Q"),
        "{misfit}"
    );

    let fit = t.join("fit");
    let mut args = vec![
        "fit",
        "--event",
        "data/mostar/event.toml",
        "--unit",
        "data/mostar/unit.toml",
        "--calib",
        "data/mostar/calibration.toml",
        "--stage",
        "gen,avr",
        "--no-polish",
        "--no-plot",
        "--out",
        s(&fit),
    ];
    args.extend(QUICK);
    let (code, out, err) = run(&args);
    assert_eq!(code, 0, "{err}");
    // No P+Q J table mixing the modes in the text either.
    assert!(!out.contains("fitness J = sum(dP^2 + dQ^2)"), "{out}");
    let r = json(&fit.join("report.json"));
    // The last pass compares E_fd in exciter_alone: its noise is measured there.
    let noise = &r["noise"][0];
    assert_eq!(noise["channels"][0]["signal"], "Efd", "{noise}");
    assert!(noise["channels"][0]["floor"]["sigma"].as_f64().unwrap() > 0.0);
    assert!(
        r["headline"]["worst"].as_f64().is_some(),
        "{}",
        r["headline"]
    );
    let html = std::fs::read_to_string(fit.join("report.html")).unwrap();
    assert!(html.contains("noise σ Efd [pu]"));
    assert!(!html.contains("noise level of an event could not be measured"));
    assert!(
        html.contains("exciter_alone: efd"),
        "the avr stage's comparison"
    );
    assert!(html.contains("J mostar-avr-step machine_from_efd (q)"));
    assert!(html.contains("J mostar-avr-step exciter_alone (efd)"));
    let _ = std::fs::remove_dir_all(&t);
}

/// `fit --help` names the search the code runs: the swarm, then Levenberg-Marquardt by default.
#[test]
fn fit_help_names_the_default_local_method() {
    let (code, out, _) = run(&["fit", "--help"]);
    assert_eq!(code, 0);
    let flat = out.split_whitespace().collect::<Vec<_>>().join(" ");
    assert!(flat.contains(itaipu_calib::spec::SEARCH_METHOD), "{out}");
    assert!(!flat.contains("then L-BFGS"), "{out}");
}

/// The bundled example warns of no value its own spec sets.
#[test]
fn the_bundled_spec_sets_no_value_the_tool_warns_of() {
    let spec =
        itaipu_calib::CalibSpec::from_file(&repo().join("data/itaipu/calibration.toml")).unwrap();
    let unit = itaipu_calib::job::load_unit(&repo().join("data/itaipu/unit.toml"))
        .unwrap()
        .unit;
    let mut u = unit.clone();
    for st in &spec.stages {
        for (p, v) in &st.set {
            if p.starts_with("pss.") {
                let r = u.param(p).unwrap();
                u.set(r, *v);
            }
        }
    }
    let findings = itaipu_dynamics::plausibility::check_unit(&u, Path::new("u"));
    assert!(
        findings.iter().all(|f| !f.column.contains("pss.")),
        "{findings:?}"
    );
}

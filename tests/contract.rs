//! One answer whatever the path (issue 25). The same record gives the same answer to 1e-9
//! whichever front end or file reaches it: the command line on an import's written files and
//! the library's job on the same import in memory (the Python module calls the same job;
//! `tests/python/test_contract.py` holds Python in memory, Python from files and a one-job fleet
//! to the command line's numbers). Across file formats of the bundled Itaipu record (the
//! bundled CSV, its C37.118 CSV export with 17 significant digits, its COMTRADE recording with
//! 32-bit samples) the data differ in the last bits of the conversions (1e-15) or by the
//! format's resolution (5e-10 of full scale): every decision is the same (onset, init window,
//! sample instants), the starting unit's J agrees to 1e-12 (1e-8 from COMTRADE), the noise floor and the verdict are
//! the same; the fit's J agrees to 1e-5 (a staged swarm and a budget-limited
//! Levenberg-Marquardt on finite-difference Jacobians carry a 1e-15 difference in the data to
//! about 1e-6 of the J they stop at).

use std::path::{Path, PathBuf};

use itaipu_calib::fit::Silent;
use itaipu_calib::job;
use itaipu_calib::request::{FitRequest, Search, Stage};
use itaipu_calib_e2e::{cli, data, TempDir};
use itaipu_dynamics::event::Event;
use itaipu_dynamics::pmu_import::{import, ImportOptions};

/// A quick staged fit: the contract holds for any budget; this one keeps CI short.
const QUICK: [&str; 12] = [
    "--stage",
    "gen,avr,pss",
    "--particles",
    "10",
    "--pso-iterations",
    "12",
    "--local-iterations",
    "8",
    "--seed",
    "5",
    "--threads",
    "2",
];

fn json(p: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

/// J of the last stage on the event in a fit's `report.json`.
fn j_of(report: &serde_json::Value) -> f64 {
    let st = report["stages"].as_array().unwrap().last().unwrap();
    st["fitness"][0]["j_pq"].as_f64().unwrap()
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs().max(1e-300)
}

/// `itaipu-calib fit --event EVENT` (the bundled unit and spec) into `out`; its report.
fn cli_fit(event: &Path, out: &Path) -> serde_json::Value {
    let (e, o) = (event.to_str().unwrap(), out.to_str().unwrap());
    let mut args = vec!["fit", "--event", e, "--out", o, "--no-plot"];
    args.extend_from_slice(&QUICK);
    assert_eq!(cli(&args), 0, "fit on {e}");
    json(&out.join("report.json"))
}

fn imports(tmp: &TempDir) -> Vec<(&'static str, PathBuf)> {
    let mut out = vec![("bundled CSV", data("itaipu/event.toml"))];
    for (what, src) in [
        ("COMTRADE import", "itaipu/pmu/itaipu.cfg"),
        ("C37.118 CSV import", "itaipu/pmu/itaipu_c37.csv"),
    ] {
        let dir = tmp.path().join(what.replace(' ', "-"));
        let code = cli(&[
            "import",
            data(src).to_str().unwrap(),
            "--system-mva",
            "1000",
            "--nominal-hz",
            "60",
            "--v-base-kv",
            "18",
            "--out",
            dir.to_str().unwrap(),
        ]);
        assert_eq!(code, 0, "import {src}");
        out.push((what, dir.join("event.toml")));
    }
    out
}

#[test]
fn every_path_to_the_itaipu_record_gives_one_answer() {
    let tmp = TempDir::new("contract");
    let paths = imports(&tmp);
    // The same decisions on every path: onset and init window from the data.
    let events: Vec<Event> = paths
        .iter()
        .map(|(_, p)| Event::from_toml_file(p).unwrap())
        .collect();
    let opts = ImportOptions {
        v_base_kv: Some(18.0),
        ..ImportOptions::new(1000.0, 60.0)
    };
    let (in_memory, _) = import(&data("itaipu/pmu/itaipu.cfg"), &opts).unwrap();
    for (k, e) in events.iter().chain([&in_memory]).enumerate() {
        assert_eq!(e.onset_s(), events[0].onset_s(), "path {k}: onset");
        assert_eq!(e.init, events[0].init, "path {k}: init window");
        assert_eq!(
            e.record.time_s, events[0].record.time_s,
            "path {k}: time stamps"
        );
    }

    // The fit through the command line on every path.
    let mut reports = vec![];
    for (k, (what, p)) in paths.iter().enumerate() {
        let r = cli_fit(p, &tmp.path().join(format!("fit-{k}")));
        println!("{what}: J = {:.12}", j_of(&r));
        reports.push((*what, r));
    }
    // The library's job on each import in memory (what Python's fit on an Event does): the
    // command line's numbers on the import's written files, to 1e-9.
    for (k, src) in [
        (1usize, "itaipu/pmu/itaipu.cfg"),
        (2, "itaipu/pmu/itaipu_c37.csv"),
    ] {
        let (ev, _) = import(&data(src), &opts).unwrap();
        let r = library_fit(ev);
        let (a, b) = (j_of(&r), j_of(&reports[k].1));
        assert!(
            rel(a, b) < 1e-9,
            "{src} in memory: J {a} against {b} from its files"
        );
        assert_eq!(r["noise"], reports[k].1["noise"], "{src}: noise");
        assert_eq!(
            r["warnings"].as_array().map(Vec::len),
            reports[k].1["warnings"].as_array().map(Vec::len)
        );
    }

    // Across formats: the same start, noise floor and warnings; the fit's J to 1e-5.
    let j0 = j_of(&reports[0].1);
    let noise0 = &reports[0].1["noise"][0];
    let start0 = reports[0].1["start_fitness"][0]["j_pq"].as_f64().unwrap();
    for (what, r) in &reports {
        // The starting unit's J: to 1e-12 (the last bits of the conversions), to 1e-8 from the
        // COMTRADE file's 32-bit samples (5e-10 of full scale).
        let tol_start = if what.starts_with("COMTRADE") {
            1e-8
        } else {
            1e-12
        };
        let start = r["start_fitness"][0]["j_pq"].as_f64().unwrap();
        assert!(
            rel(start, start0) < tol_start,
            "{what}: start J {start} against {start0}"
        );
        let j = j_of(r);
        assert!(rel(j, j0) < 1e-5, "{what}: J {j} against {j0}");
        for s in ["sigma_p", "sigma_q"] {
            let (a, b) = (
                r["noise"][0][s].as_f64().unwrap(),
                noise0[s].as_f64().unwrap(),
            );
            assert!(rel(a, b) < 1e-4, "{what}: noise {s} {a} against {b}");
        }
        // Every path reports the record's edge drop-out, as the bundled one does.
        let kinds: Vec<&str> = r["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .map(|w| w["kind"].as_str().unwrap())
            .collect();
        assert!(kinds.contains(&"edge_dropout"), "{what}: {kinds:?}");
    }

    // The diagnosis of one calibrated unit (the bundled path's) on each path's event: the same
    // verdict, noise floor and headline ratio.
    let calibrated = tmp.path().join("fit-0").join("calibrated.toml");
    let mut diagnoses = vec![];
    for (k, (_, event)) in paths.iter().enumerate() {
        let out = tmp.path().join(format!("diag-{k}"));
        let code = cli(&[
            "diagnose",
            "--event",
            event.to_str().unwrap(),
            "--unit",
            calibrated.to_str().unwrap(),
            "--cause",
            "measurement_skew,saturation",
            "--particles",
            "8",
            "--pso-iterations",
            "6",
            "--local-iterations",
            "5",
            "--out",
            out.to_str().unwrap(),
            "--no-plot",
        ]);
        assert_eq!(code, 0, "diagnose {k}");
        diagnoses.push(json(&out.join("diagnosis.json")));
    }
    let headline = |d: &serde_json::Value| {
        d["evidence"][0]["signals"]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| s["rms_over_noise"].as_f64().unwrap())
            .fold(f64::NAN, f64::max)
    };
    let a = &diagnoses[0];
    for (b, what) in diagnoses[1..].iter().zip(&paths[1..]) {
        let tol = if what.0.starts_with("COMTRADE") {
            1e-6
        } else {
            1e-9
        };
        assert_eq!(a["verdict"]["cause"], b["verdict"]["cause"]);
        for s in ["sigma_p", "sigma_q"] {
            let (x, y) = (
                a["noise"][s].as_f64().unwrap(),
                b["noise"][s].as_f64().unwrap(),
            );
            assert!(rel(x, y) < tol, "diagnosis noise {s}: {x} against {y}");
        }
        assert!(
            rel(headline(a), headline(b)) < tol,
            "headline ratio {} against {}",
            headline(a),
            headline(b)
        );
    }
    // The fit report's noise table and the diagnosis' noise floor are one definition: on the
    // calibrated unit they are the same numbers (the diagnosis' reference only re-fits the
    // set-point offsets, which the pre-event residual's standard deviation does not see).
    let fit_noise = reports[0].1["noise"][0]["sigma_q"].as_f64().unwrap();
    let diag_noise = a["noise"]["sigma_q"].as_f64().unwrap();
    assert!(
        rel(fit_noise, diag_noise) < 0.05,
        "fit report σQ {fit_noise} against the diagnosis' {diag_noise}"
    );
}

/// The library's fit job on `event` with the bundled unit and spec and the command line's
/// quick settings; its report as `report.json` holds it.
fn library_fit(event: Event) -> serde_json::Value {
    let inputs = job::FitInputs {
        unit: job::load_unit(&data("itaipu/unit.toml")).unwrap().unit,
        unit_path: Some(data("itaipu/unit.toml")),
        spec: job::FitInputs::read_spec(Some(&data("itaipu/calibration.toml")), None)
            .unwrap()
            .0,
        spec_path: Some(data("itaipu/calibration.toml")),
        spec_text: None,
        events: vec![event],
        held_out: vec![],
    };
    let request = FitRequest {
        stages: Stage::parse_list(&["gen,avr,pss"]).unwrap(),
        strategy: None,
        search: Search {
            seed: Some(5),
            particles: Some(10),
            pso_iterations: Some(12),
            local_iterations: Some(8),
            threads: Some(2),
        },
        no_polish: false,
    };
    let (fit_opts, warnings) = job::prepare_fit(&inputs, &request).unwrap();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap();
    let run = pool
        .install(|| {
            job::run_fit(
                &inputs,
                &fit_opts,
                warnings,
                &Silent,
                &Default::default(),
                Default::default(),
            )
        })
        .unwrap();
    run.report.to_json().unwrap()
}

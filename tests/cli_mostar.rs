//! End-to-end: the bundled Mostar AVR step test (no voltage angle, non-uniform time base, two
//! set-point steps) through the command line: a staged fit in the playback modes and the
//! simulation in each mode; bad inputs stop with exit 3 and write nothing.

use std::path::Path;

use itaipu_calib_e2e::{cli, data, TempDir};

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The bundled spec's stages with a tiny search: every stage names its mode, every fitness row
/// reports the three modes, and the stage folders hold the mode's traces.
#[test]
fn a_staged_fit_of_the_mostar_record_runs_in_its_playback_modes() {
    let tmp = TempDir::new("mostar-fit");
    let out = tmp.path().join("fit");
    let (ev, unit, cal) = (
        data("mostar/event.toml"),
        data("mostar/unit.toml"),
        data("mostar/calibration.toml"),
    );
    let code = cli(&[
        "fit",
        "--event",
        s(&ev),
        "--unit",
        s(&unit),
        "--calib",
        s(&cal),
        "--out",
        s(&out),
        "--particles",
        "4",
        "--pso-iterations",
        "2",
        "--local-iterations",
        "2",
        "--no-plot",
    ]);
    assert_eq!(code, 0);
    let r = json(&out.join("report.json"));
    let stages = r["stages"].as_array().unwrap();
    let compare: Vec<&str> = stages
        .iter()
        .map(|st| st["compare"].as_str().unwrap())
        .collect();
    assert_eq!(
        compare,
        [
            "machine_from_efd: q 1",
            "exciter_alone: efd 1",
            "closed_loop: v 425, q 5.81, efd 1.87"
        ]
    );
    let modes = |row: &serde_json::Value| -> Vec<String> {
        row["modes"]
            .as_array()
            .unwrap()
            .iter()
            .map(|m| m["mode"].as_str().unwrap().to_string())
            .collect()
    };
    assert_eq!(
        modes(&r["start_fitness"][0]),
        ["machine_from_efd", "exciter_alone", "closed_loop"]
    );
    // RaPId's values at the start: the numbers of data/mostar/README.md.
    let j0 = r["start_fitness"][0]["modes"][1]["j"].as_f64().unwrap();
    assert!((j0 - 218.9661).abs() < 1e-3, "{j0}");
    for st in stages {
        assert!(
            st["objective_after"].as_f64().unwrap()
                <= st["objective_before"].as_f64().unwrap() + 1e-12
        );
    }
    for stage in ["gen", "avr", "joint"] {
        let head = std::fs::read_to_string(out.join(stage).join("traces.csv")).unwrap();
        let head = head.lines().next().unwrap();
        assert!(
            head.contains("v_meas_pu") && head.contains("efd_meas_pu"),
            "{stage}: {head}"
        );
    }
    // The calibrated unit simulates in each mode.
    for mode in ["exciter_alone", "machine_from_efd", "closed_loop"] {
        let sim = tmp.path().join(format!("sim-{mode}"));
        let unit = out.join("calibrated.toml");
        assert_eq!(
            cli(&[
                "simulate",
                "--event",
                s(&ev),
                "--unit",
                s(&unit),
                "--mode",
                mode,
                "--out",
                s(&sim),
            ]),
            0,
            "{mode}"
        );
        assert!(sim.join("traces.csv").exists() && sim.join("plot.svg").exists());
    }
}

/// `diagnose --mode` on the bundled record with a tiny search and two causes: the closed loop
/// compares |V|, Q and E_fd, each with its own noise floor; a cause the mode cannot show (the
/// governor: the grid equivalent holds the frequency) says why; the plots draw the compared
/// signals' residuals.
#[test]
fn the_mostar_record_is_diagnosed_in_the_mode_named() {
    let tmp = TempDir::new("mostar-diagnose");
    let out = tmp.path().join("diag");
    let code = cli(&[
        "diagnose",
        "--event",
        s(&data("mostar/event.toml")),
        "--unit",
        s(&data("mostar/calibrated.toml")),
        "--mode",
        "closed_loop",
        "--cause",
        "governor,terminal_load",
        "--particles",
        "4",
        "--pso-iterations",
        "2",
        "--local-iterations",
        "2",
        "--out",
        s(&out),
    ]);
    assert_eq!(code, 0);
    let d = json(&out.join("diagnosis.json"));
    assert_eq!(d["noise"]["playback"], "closed_loop: |V|, Q, Efd");
    let sigmas: Vec<&str> = d["noise"]["sigmas"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x[0].as_str().unwrap())
        .collect();
    assert_eq!(sigmas, ["|V|", "Q", "Efd"]);
    let gov = d["candidates"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["cause"] == "governor")
        .unwrap();
    assert_eq!(gov["applicable"], false);
    assert!(gov["note"].as_str().unwrap().contains("closed_loop"));
    let load = d["candidates"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["cause"] == "terminal_load")
        .unwrap();
    assert_eq!(load["applicable"], true, "{}", load["note"]);
    let svg = std::fs::read_to_string(out.join("residual-mostar-avr-step.svg")).unwrap();
    assert!(svg.contains("Efd residual") && svg.contains("|V| residual"));
}

/// A record without an angle in a phasor playback (simulate, diagnose without --mode, or a fit
/// whose stages are phasor stages), a compared channel the record lacks, a step outside the record, E_fd in volts, a
/// duplicated time stamp: each stops with exit 3, and the --out folder is not created.
#[test]
fn bad_mostar_inputs_stop_before_anything_is_written() {
    let tmp = TempDir::new("mostar-bad");
    let (ev, unit, cal) = (
        data("mostar/event.toml"),
        data("mostar/unit.toml"),
        data("mostar/calibration.toml"),
    );
    let csv = std::fs::read_to_string(data("mostar/mostar.csv")).unwrap();
    let toml = std::fs::read_to_string(&ev).unwrap();
    // A copy of the event with its CSV and TOML edited.
    let edited = |tag: &str, csv_text: &str, toml_text: &str| {
        tmp.write(&format!("{tag}/mostar.csv"), csv_text);
        tmp.write(&format!("{tag}/event.toml"), toml_text)
    };
    let step_outside = edited(
        "outside",
        &csv,
        &toml.replace("time_s = 10.245", "time_s = 19.0"),
    );
    let mut lines: Vec<String> = csv.lines().map(String::from).collect();
    lines[101] = lines[100].clone();
    let duplicated = edited("dup", &(lines.join("\n") + "\n"), &toml);
    let volts: String = csv
        .lines()
        .enumerate()
        .map(|(k, l)| {
            if k == 0 {
                format!("{l}\n")
            } else {
                let (head, efd) = l.rsplit_once(',').unwrap();
                format!("{head},{}\n", efd.parse::<f64>().unwrap() * 125.0)
            }
        })
        .collect();
    let volts = edited("volts", &volts, &toml);
    let ifd_spec = tmp.write(
        "ifd.toml",
        "[calibration]\n[[calibration.stage]]\nname = \"gen\"\nmode = \"machine_from_efd\"\nchannels = { q = 1.0, ifd = 1.0 }\nfree = [ { param = \"machine.x_d\", min = 0.6, max = 2.0 } ]\n",
    );
    let itaipu_spec = data("itaipu/calibration.toml");
    let cases: Vec<(&str, Vec<String>)> = vec![
        (
            "phasor simulate",
            vec!["simulate".into(), "--event".into(), s(&ev).into()],
        ),
        (
            "phasor fit",
            vec![
                "fit".into(),
                "--event".into(),
                s(&ev).into(),
                "--calib".into(),
                s(&itaipu_spec).into(),
                "--stage".into(),
                "avr".into(),
            ],
        ),
        (
            "phasor diagnose",
            vec!["diagnose".into(), "--event".into(), s(&ev).into()],
        ),
        (
            "diagnose E_fd in volts",
            vec![
                "diagnose".into(),
                "--mode".into(),
                "exciter_alone".into(),
                "--event".into(),
                s(&volts).into(),
            ],
        ),
        (
            "missing channel",
            vec![
                "fit".into(),
                "--event".into(),
                s(&ev).into(),
                "--calib".into(),
                s(&ifd_spec).into(),
            ],
        ),
        (
            "step outside",
            vec![
                "simulate".into(),
                "--mode".into(),
                "closed_loop".into(),
                "--event".into(),
                s(&step_outside).into(),
            ],
        ),
        (
            "duplicated time",
            vec![
                "simulate".into(),
                "--mode".into(),
                "closed_loop".into(),
                "--event".into(),
                s(&duplicated).into(),
            ],
        ),
        (
            "E_fd in volts",
            vec![
                "simulate".into(),
                "--mode".into(),
                "exciter_alone".into(),
                "--event".into(),
                s(&volts).into(),
            ],
        ),
    ];
    let _ = cal;
    for (what, mut args) in cases {
        let out = tmp.path().join(format!("out-{}", what.replace(' ', "-")));
        args.extend([
            "--unit".into(),
            s(&unit).into(),
            "--out".into(),
            s(&out).into(),
        ]);
        let argv: Vec<&str> = args.iter().map(|a| a.as_str()).collect();
        assert_eq!(cli(&argv), 3, "{what}");
        assert!(!out.exists(), "{what}: {} was written", out.display());
    }
}

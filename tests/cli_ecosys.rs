//! End-to-end: the README's newcomer path on the command line — the bundled unit as a PSS/E
//! `.dyr`, the bundled record as a COMTRADE recording, `import`, `fit` with the `.dyr` as the
//! unit, `dyr write` back — and the two commands' handling of bad input (exit codes, nothing
//! overwritten).

use itaipu_calib_e2e::{cli, cli_on, data, file_names, TempDir, FIT_BUDGET};
use itaipu_dynamics::event::Event;
use itaipu_dynamics::unit_file::read_unit;

fn s(p: &std::path::Path) -> &str {
    p.to_str().expect("a UTF-8 path")
}

/// `import CFG` on the Itaipu bases (1000 MVA system, 60 Hz, 18 kV) into `out`.
fn import(cfg: &std::path::Path, out: &std::path::Path) -> u8 {
    cli(&[
        "import",
        s(cfg),
        "--system-mva",
        "1000",
        "--nominal-hz",
        "60",
        "--v-base-kv",
        "18",
        "--out",
        s(out),
    ])
}

#[test]
fn comtrade_and_dyr_of_the_bundled_event_calibrate_like_the_bundled_files() {
    let tmp = TempDir::new("ecosys");
    let ev_dir = tmp.path().join("ev");
    let cfg = data("itaipu/pmu/itaipu.cfg");
    assert_eq!(import(&cfg, &ev_dir), 0);
    assert_eq!(
        file_names(&ev_dir),
        ["event.toml", "import.json", "itaipu.csv", "manifest.json"],
        "the event folder"
    );
    // The imported record is the bundled one within the recording's 16-bit resolution.
    let imported = Event::from_toml_file(&ev_dir.join("event.toml")).unwrap();
    let bundled = Event::from_toml_file(&data("itaipu/event.toml")).unwrap();
    let (a, b) = (&imported.record, &bundled.record);
    assert_eq!(a.time_s.len(), b.time_s.len());
    let worst = |x: &[f64], y: &[f64]| {
        x.iter()
            .zip(y)
            .map(|(u, v)| (u - v).abs())
            .fold(0.0, f64::max)
    };
    assert!(worst(&a.p_pu, &b.p_pu) < 5e-3, "P");
    assert!(worst(&a.q_pu, &b.q_pu) < 5e-3, "Q");
    assert!(worst(&a.v_mag_pu, &b.v_mag_pu) < 1e-3, "|V|");
    // Importing again into the same folder is refused: nothing is overwritten.
    assert_ne!(import(&cfg, &ev_dir), 0);

    // The .dyr (bases in unit.bases.toml beside it) is the bundled unit file's machine.
    let dyr = data("itaipu/unit.dyr");
    let unit_toml = tmp.path().join("from_dyr.toml");
    assert_eq!(cli(&["dyr", "read", s(&dyr), "--out", s(&unit_toml)]), 0);
    let from_dyr = read_unit(&unit_toml).unwrap();
    let bundled_unit = read_unit(&data("itaipu/unit.toml")).unwrap();
    for p in ["machine.x_d", "machine.h", "exciter.k", "pss.t_x1"] {
        let get = |u: &itaipu_dynamics::unit::Unit| u.get(u.param(p).unwrap());
        assert!(
            (get(&from_dyr) - get(&bundled_unit)).abs() < 1e-9,
            "{p}: {} against {}",
            get(&from_dyr),
            get(&bundled_unit)
        );
    }

    // fit on the imported event with the .dyr as the unit (a short search: the path, not the
    // optimum, is under test), then write the calibrated unit back as .dyr.
    let fit_dir = tmp.path().join("fit");
    let calib = data("itaipu/calibration.toml");
    let code = cli_on(
        "fit",
        ev_dir.join("event.toml"),
        &dyr,
        &fit_dir,
        &[
            &["--calib", s(&calib), "--stage", "gen", "--no-plot"][..],
            &FIT_BUDGET[..],
        ]
        .concat(),
    );
    assert_eq!(code, 0);
    for f in [
        "report.json",
        "report.html",
        "calibrated.toml",
        "manifest.json",
    ] {
        assert!(fit_dir.join(f).is_file(), "fit wrote {f}");
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(fit_dir.join("report.json")).unwrap())
            .unwrap();
    let stages = report["stages"].as_array().unwrap();
    let j = |st: &serde_json::Value, key: &str| st[key].as_f64().unwrap_or(f64::NAN);
    let first = &stages[0];
    assert!(
        j(first, "objective_after") <= j(first, "objective_before"),
        "the gen stage does not end worse than it starts: {first}"
    );
    let back = tmp.path().join("calibrated.dyr");
    let cal_toml = fit_dir.join("calibrated.toml");
    let write = |extra: &[&str]| {
        cli(&[
            &["dyr", "write", s(&cal_toml), "--out", s(&back)][..],
            extra,
        ]
        .concat())
    };
    // The gen stage frees X''q apart from X''d; PSS/E's GENSAE holds one X'', so the .dyr does
    // not play back as the calibrated unit on the fit's event (found from the fit's manifest):
    // refused, nothing written. --lossy writes it.
    let cal = read_unit(&cal_toml).unwrap();
    let x = |p: &str| cal.get(cal.param(p).unwrap());
    assert_ne!(x("machine.x_q_pp"), x("machine.x_d_pp"));
    assert_eq!(write(&[]), 4);
    assert!(!back.exists() && !tmp.path().join("calibrated.bases.toml").exists());
    assert_eq!(write(&["--lossy"]), 0);
    let text = std::fs::read_to_string(&back).unwrap();
    assert!(
        text.contains("'GENSAE'") && text.contains("'SEXS'"),
        "{text}"
    );
    assert!(tmp.path().join("calibrated.bases.toml").is_file());
    // The written .dyr reads back to the calibrated machine.
    let again = tmp.path().join("again.toml");
    assert_eq!(cli(&["dyr", "read", s(&back), "--out", s(&again)]), 0);
    let rt = read_unit(&again).unwrap();
    for p in ["machine.x_d", "machine.h", "machine.t_d0_prime"] {
        let (x, y) = (cal.get(cal.param(p).unwrap()), rt.get(rt.param(p).unwrap()));
        assert!((x - y).abs() <= 1e-9 * x.abs().max(1.0), "{p}: {x} -> {y}");
    }
}

#[test]
fn bad_imports_and_dyr_files_exit_with_their_codes_and_write_nothing() {
    let tmp = TempDir::new("ecosys-bad");
    // A COMTRADE .cfg that is not one: bad event data, exit 3.
    let cfg = tmp.write("broken.cfg", "this is not a COMTRADE configuration\n");
    let out = tmp.path().join("ev");
    assert_eq!(import(&cfg, &out), 3);
    assert!(!out.join("event.toml").exists(), "no event from a bad file");
    // A .dyr without its bases (no side file, no --mbase): usage error, exit 2.
    let dyr = tmp.write(
        "lone.dyr",
        &std::fs::read_to_string(data("itaipu/unit.dyr")).unwrap(),
    );
    let unit_out = tmp.path().join("lone.toml");
    assert_eq!(cli(&["dyr", "read", s(&dyr), "--out", s(&unit_out)]), 2);
    assert!(!unit_out.exists());
    // A record with a CON that is not a number: bad model file, exit 4.
    let bad = tmp.write("bad.dyr", "1 'SEXS' 1 0.1 10.0 100.0 x 0.0 5.0 /\n");
    let code = cli(&[
        "dyr",
        "read",
        s(&bad),
        "--mbase",
        "737",
        "--nominal-hz",
        "60",
        "--out",
        s(&tmp.path().join("bad.toml")),
    ]);
    assert_eq!(code, 4);
}

//! End-to-end: `itaipu-calib diagnose` on synthetic events made by `synth` (a hidden PMU skew,
//! and a clean record), its output files, plots and HTML report, and its handling of bad input.
//! Budgets are tiny (8 particles, 6 swarm and 5 L-BFGS iterations) so that each run takes a
//! second or two.

use std::path::{Path, PathBuf};

use itaipu_calib_e2e::{cli_on, data, file_names, synth_skewed_dip, TempDir, DIAGNOSE_BUDGET};

const UNIT: &str = "synthetic/unit_gensae_sexs_stab3_hygov.toml";

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// A 10 s synthetic fault dip (event `synthetic-dip-1`) from the generic unit, with the power
/// channels delayed by `skew_ms`; returns the event file.
fn synth(tmp: &TempDir, skew_ms: &str) -> PathBuf {
    let out = tmp.path().join(format!("synth-{skew_ms}"));
    assert_eq!(synth_skewed_dip(&out, skew_ms), 0);
    out.join("event.toml")
}

fn diagnose(event: &Path, out: &Path, extra: &[&str]) -> u8 {
    let mut args = DIAGNOSE_BUDGET.to_vec();
    args.extend_from_slice(extra);
    cli_on("diagnose", event, data(UNIT), out, &args)
}

/// A 12 ms skew of the P and Q channels is named, its delay recovered (12.0 ms observed with
/// this budget), and the extended unit written to disk carries it and reads back as a unit.
#[test]
fn diagnose_names_a_hidden_pmu_skew_and_writes_the_extended_unit() {
    let tmp = TempDir::new("diag-skew");
    let event = synth(&tmp, "12");
    // An existing folder with the files of an earlier run: --force replaces the folder whole
    // (issue 13: nothing of an earlier run may sit beside the new results).
    let out = tmp.path().join("diag");
    tmp.write("diag/diagnosis.json", "{}");
    let mine = tmp.write("diag/evidence_old.svg", "stale");
    let code = diagnose(
        &event,
        &out,
        &[
            "--cause",
            "measurement_skew",
            "--cause",
            "saturation",
            "--no-plot",
            "--force",
            "--threads",
            "1",
        ],
    );
    assert_eq!(code, 0);
    assert!(!mine.exists(), "--force replaces the folder whole");
    itaipu_calib_cli::output::verify(&out).unwrap();
    assert_eq!(
        file_names(&out),
        [
            "diagnosis.json",
            "extended.toml",
            "manifest.json",
            "report.html"
        ],
        "--no-plot: no svg files"
    );

    let d = json(&out.join("diagnosis.json"));
    assert_eq!(d["unit"], "synthetic-gensae-hygov");
    assert_eq!(d["events"], serde_json::json!(["synthetic-dip-1"]));
    assert_eq!(d["threads"], 1, "--threads 1 runs in a pool of one thread");
    let causes: Vec<&str> = d["candidates"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["cause"].as_str().unwrap())
        .collect();
    assert_eq!(
        causes.len(),
        2,
        "only the requested causes are tried: {causes:?}"
    );
    assert!(
        causes.contains(&"measurement_skew") && causes.contains(&"saturation"),
        "{causes:?}"
    );
    assert_eq!(causes[0], "measurement_skew", "ranked first by ΔBIC");
    let skew = &d["candidates"][0];
    assert_eq!(skew["significant"], true);
    assert!(
        skew["gains"]["delta_bic"].as_f64().unwrap()
            > d["candidates"][1]["gains"]["delta_bic"]
                .as_f64()
                .unwrap_or(f64::NEG_INFINITY)
    );

    let v = &d["verdict"];
    assert_eq!(v["cause"], "measurement_skew");
    let key = v["key_parameters"].as_array().unwrap();
    assert_eq!(key[0][0], "measurement.pq_delay_s");
    let delay = key[0][1].as_f64().unwrap();
    assert!(
        (delay - 0.012).abs() < 0.003,
        "fitted skew {:.2} ms, true 12 ms",
        delay * 1e3
    );
    // The extension brings the residual down to near the noise: evidence after < before.
    let rms = |ev: &serde_json::Value, sig: &str| {
        ev[0]["signals"]
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s["signal"] == sig)
            .unwrap()["rms_over_noise"]
            .as_f64()
            .unwrap()
    };
    for sig in ["P", "Q"] {
        let (before, after) = (rms(&d["evidence"], sig), rms(&d["evidence_after"], sig));
        assert!(after < 0.5 * before, "{sig}: RMS/noise {before} -> {after}");
    }

    // extended.toml is a unit file with the measurement block at the fitted delay.
    let unit = itaipu_dynamics::unit_file::read_unit(&out.join("extended.toml"))
        .expect("extended.toml reads back as a unit");
    let r = unit
        .param("measurement.pq_delay_s")
        .expect("the extended unit has the measurement block");
    assert!(
        (unit.get(r) - delay).abs() < 1e-9 * delay.max(1e-3),
        "extended.toml delay {} vs verdict {delay}",
        unit.get(r)
    );
    assert!(
        unit.description.contains("measurement_skew"),
        "{}",
        unit.description
    );

    // The HTML report is written without plots and says so.
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(
        html.contains("measurement_skew")
            && html.contains("Plots not drawn")
            && !html.contains("<svg")
    );
}

/// Without --no-plot: the three plots per event, drawn with their decorations, and a report
/// that inlines them and needs nothing else.
#[test]
fn diagnose_draws_plots_and_a_self_contained_html_report() {
    let tmp = TempDir::new("diag-plot");
    let event = synth(&tmp, "12");
    let out = tmp.path().join("diag");
    assert_eq!(diagnose(&event, &out, &["--cause", "measurement_skew"]), 0);
    let svg = |name: &str| {
        let p = out.join(format!("{name}-synthetic-dip-1.svg"));
        let text = std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        assert!(
            text.trim_start().starts_with("<svg") && text.trim_end().ends_with("</svg>"),
            "{name}"
        );
        text
    };
    let residual = svg("residual");
    assert!(
        residual.contains("±σP noise") && residual.contains("±σQ noise"),
        "noise bands in the legend"
    );
    assert!(
        residual.contains("most SSE: dip"),
        "the dip window (where the skew's error lives) is shaded"
    );
    assert!(
        residual.contains("with measurement_skew"),
        "the residual after the extension is drawn"
    );
    let spectrum = svg("spectrum");
    assert!(
        spectrum.contains("peak ") && spectrum.contains("<circle"),
        "the spectral peak is marked"
    );
    let before_after = svg("before-after");
    assert!(
        before_after.contains("measured")
            && before_after.contains("unit as given")
            && before_after.contains("extended (measurement_skew)")
    );

    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.starts_with("<!DOCTYPE html>") && html.trim_end().ends_with("</html>"));
    assert_eq!(
        html.matches("<svg").count(),
        3,
        "the three plots are inlined"
    );
    for svg_text in [&residual, &spectrum, &before_after] {
        let title = svg_text
            .lines()
            .find(|l| l.starts_with("synthetic-dip-1:"))
            .expect("plot title");
        assert!(html.contains(title), "inlined plot with title {title}");
    }
    let lower = html.to_lowercase();
    for banned in ["<script", "src=\"http", "href=\"http", "<link", "@import"] {
        assert!(
            !lower.contains(banned),
            "the report must stand alone: found {banned}"
        );
    }
    // Text is escaped: the verdict statement's "->" arrows appear as "-&gt;", its apostrophes
    // as "&#39;".
    let d = json(&out.join("diagnosis.json"));
    let statement = d["verdict"]["statement"].as_str().unwrap();
    assert!(statement.contains("->") && statement.contains('\''));
    assert!(html.contains(
        &statement
            .replace('&', "&amp;")
            .replace('<', "&lt;")
            .replace('>', "&gt;")
            .replace('"', "&quot;")
            .replace('\'', "&#39;")
    ));
    for section in [
        "Verdict: measurement_skew",
        "Candidates",
        "Noise and the reference",
        "Evidence",
        "Ljung-Box",
        "share of SSE",
        "correlation",
        "damping ratio",
    ] {
        assert!(html.contains(section), "report lacks {section}");
    }
}

/// On a clean record no cause is named, and no extended unit is written (`--no-look-alikes`
/// is accepted).
#[test]
fn diagnose_writes_no_extended_unit_when_no_cause_is_named() {
    let tmp = TempDir::new("diag-clean");
    let event = synth(&tmp, "0");
    let out = tmp.path().join("diag");
    assert_eq!(
        diagnose(
            &event,
            &out,
            &[
                "--cause",
                "measurement_skew",
                "--no-plot",
                "--no-look-alikes"
            ]
        ),
        0
    );
    let d = json(&out.join("diagnosis.json"));
    let cause = d["verdict"]["cause"].as_str().unwrap();
    assert!(
        cause == "none" || cause == "unexplained",
        "verdict {cause} on a clean record"
    );
    assert_eq!(d["candidates"][0]["significant"], false);
    assert!(d["evidence_after"].as_array().unwrap().is_empty());
    assert!(!out.join("extended.toml").exists());
    assert_eq!(
        file_names(&out),
        ["diagnosis.json", "manifest.json", "report.html"]
    );
}

#[test]
fn diagnose_refuses_bad_input_before_running() {
    let tmp = TempDir::new("diag-bad");
    let out = tmp.path().join("o");
    let o = out.to_str().unwrap();
    let (event, unit) = (data("itaipu/event.toml"), data("itaipu/unit.toml"));
    let (event, unit) = (event.to_str().unwrap(), unit.to_str().unwrap());
    // Usage errors: an unknown cause (also next to a known one), no threads.
    assert_eq!(
        cli_on("diagnose", event, unit, o, &["--cause", "gremlins"]),
        2
    );
    assert_eq!(
        cli_on(
            "diagnose",
            event,
            unit,
            o,
            &["--cause", "saturation,gremlins"]
        ),
        2
    );
    assert_eq!(cli_on("diagnose", event, unit, o, &["--threads", "0"]), 2);
    // A --refit parameter the unit does not have, bounds upside down, a malformed range.
    for refit in [
        "machine.nope",
        "machine.h=6:3",
        "machine.h=3",
        "exciter.k=1:x",
    ] {
        assert_eq!(
            cli_on("diagnose", event, unit, o, &["--refit", refit]),
            2,
            "--refit {refit}"
        );
    }
    // Bad event data, bad unit.
    let missing = tmp.path().join("missing.toml");
    assert_eq!(cli_on("diagnose", &missing, unit, o, &[]), 3);
    assert_eq!(
        cli_on(
            "diagnose",
            event,
            unit,
            o,
            &["--held-out", missing.to_str().unwrap()]
        ),
        3
    );
    let bad_unit = tmp.write("bad_unit.toml", "name = \"x\"\nmachine_mva = 100.0\n");
    assert_eq!(cli_on("diagnose", event, &bad_unit, o, &[]), 4);
    // A unit that cannot initialise on the event (E_fd0 above the exciter ceiling): exit 5, as
    // simulate and fit, found by the playback before the diagnosis.
    let text = std::fs::read_to_string(data(UNIT)).unwrap();
    assert!(text.contains("e_max = 4.5"));
    let stuck = tmp.write("stuck.toml", &text.replace("e_max = 4.5", "e_max = 0.5"));
    let synth_event = synth(&tmp, "0");
    assert_eq!(
        cli_on(
            "diagnose",
            &synth_event,
            &stuck,
            o,
            &["--cause", "saturation"]
        ),
        5
    );
    assert!(!out.exists(), "no output folder for a refused run");
    // An existing, non-empty --out folder is left alone without --force.
    let keep = tmp.write("full/mine.txt", "mine");
    let full = keep.parent().unwrap();
    assert_eq!(cli_on("diagnose", event, unit, full, &[]), 7);
    assert_eq!(file_names(full), ["mine.txt"]);
    assert_eq!(std::fs::read_to_string(&keep).unwrap(), "mine");
}

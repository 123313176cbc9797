//! The `itaipu-calib` binary interrupted by SIGINT / SIGTERM during a `fit`: a partial folder
//! marked by `partial.json` whose finished stages `simulate` can read, and `--resume` that
//! completes it with the same numbers as an uninterrupted run (issue 13).
#![cfg(unix)]

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn tmp(tag: &str) -> PathBuf {
    let p = std::env::temp_dir().join(format!("itaipu-int-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&p);
    std::fs::create_dir_all(&p).unwrap();
    p
}

fn bin() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_itaipu-calib"));
    c.current_dir(repo());
    c
}

/// Small but not instant: three stages and the joint pass on the Itaipu record.
const FIT: [&str; 11] = [
    "fit",
    "--stage",
    "gen,avr,pss",
    "--particles",
    "12",
    "--pso-iterations",
    "40",
    "--lbfgs-iterations",
    "10",
    "--seed",
    "3",
];

fn run(args: &[&str], out: &Path, extra: &[&str]) -> (i32, String) {
    let o = bin()
        .args(args)
        .args(["--no-plot", "--out", out.to_str().unwrap()])
        .args(extra)
        .output()
        .unwrap();
    (
        o.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// Starts the fit, sends `signal` as soon as the avr stage starts (the gen stage is then
/// finished and written), and returns the exit code and stderr.
fn interrupted(out: &Path, signal: &str) -> (i32, String) {
    let mut child = bin()
        .args(FIT)
        .args(["--no-plot", "--out", out.to_str().unwrap()])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let pid = child.id().to_string();
    let mut log = String::new();
    let mut sent = false;
    let mut after = vec![];
    for line in BufReader::new(child.stderr.take().unwrap()).lines() {
        let line = line.unwrap();
        if sent {
            after.push(line.clone());
        }
        if !sent && line.starts_with("[avr]") {
            let ok = Command::new("kill")
                .args([signal, &pid])
                .status()
                .unwrap()
                .success();
            assert!(ok, "kill {signal} {pid}");
            sent = true;
        }
        log.push_str(&line);
        log.push('\n');
    }
    let code = child.wait().unwrap().code().unwrap_or(-1);
    assert!(sent, "the avr stage never started:\n{log}");
    // After the signal the log stops: no further phase or progress, no failure penalty shown
    // as an objective; only the closing message.
    assert!(
        after.iter().all(|l| !l.starts_with('[')
            && !l.contains("best objective")
            && !l.contains("1000000000000000019884624838656")),
        "{log}"
    );
    (code, log)
}

fn json(p: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

#[test]
fn sigint_leaves_a_marked_partial_folder_and_resume_gives_the_same_numbers() {
    let dir = tmp("sigint");
    // The uninterrupted reference.
    let reference = dir.join("ref");
    let (code, log) = run(&FIT, &reference, &[]);
    assert_eq!(code, 0, "{log}");
    itaipu_calib_cli::output::verify(&reference).unwrap();

    let out = dir.join("fit");
    let (code, log) = interrupted(&out, "-INT");
    assert_eq!(code, 130, "{log}");
    assert!(log.contains("interrupted by SIGINT"), "{log}");
    // Clearly marked: partial.json, no manifest, no report, no calibrated unit.
    assert!(!out.join("manifest.json").exists());
    assert!(!out.join("report.json").exists());
    assert!(!out.join("calibrated.toml").exists());
    let partial = json(&out.join("partial.json"));
    assert_eq!(partial["complete"], false);
    assert_eq!(partial["interrupted_by"], "SIGINT");
    let finished: Vec<String> = partial["finished_stages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s.as_str().unwrap().to_string())
        .collect();
    assert_eq!(
        finished.first().map(String::as_str),
        Some("gen"),
        "{finished:?}"
    );
    assert!(
        finished.len() < 4,
        "the fit finished before the signal: {finished:?}"
    );
    // No temporary folder left beside it.
    let leftovers: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
    // Every finished stage is usable: simulate reads its unit, and its report is kept.
    for (k, st) in finished.iter().enumerate() {
        let unit = out.join(st).join("unit.toml");
        let sim = dir.join(format!("sim-{st}"));
        let o = bin()
            .args(["simulate", "--unit", unit.to_str().unwrap(), "--no-plot"])
            .args(["--out", sim.to_str().unwrap()])
            .output()
            .unwrap();
        assert_eq!(
            o.status.code(),
            Some(0),
            "{}",
            String::from_utf8_lossy(&o.stderr)
        );
        assert!(out.join(st).join("traces.csv").is_file());
        assert_eq!(partial["stage_reports"][k]["stage"], st.as_str());
    }
    // A resume with other options is refused (usage error), the folder untouched.
    let (code, log) = run(&FIT, &out, &["--resume", "--no-polish"]);
    assert_eq!(code, 2, "{log}");
    assert!(log.contains("options differ"), "{log}");
    assert!(out.join("partial.json").is_file());
    // --resume completes it.
    let (code, log) = run(&FIT, &out, &["--resume"]);
    assert_eq!(code, 0, "{log}");
    let m = itaipu_calib_cli::output::verify(&out).unwrap();
    assert!(!out.join("partial.json").exists() && !out.join("resume-unit.toml").exists());
    assert!(m.files.iter().any(|f| f.path == "pss/unit.toml"));
    // The same numbers as the uninterrupted run.
    assert_eq!(
        std::fs::read_to_string(out.join("calibrated.toml")).unwrap(),
        std::fs::read_to_string(reference.join("calibrated.toml")).unwrap()
    );
    let (a, b) = (
        json(&reference.join("report.json")),
        json(&out.join("report.json")),
    );
    let stages = |r: &serde_json::Value| -> Vec<(String, f64, Vec<f64>)> {
        r["stages"]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| {
                (
                    s["stage"].as_str().unwrap().to_string(),
                    s["objective_after"].as_f64().unwrap(),
                    s["parameters"]
                        .as_array()
                        .unwrap()
                        .iter()
                        .map(|p| p["result"].as_f64().unwrap())
                        .collect(),
                )
            })
            .collect()
    };
    assert_eq!(stages(&a), stages(&b));
    assert_eq!(b["resumed_stages"], serde_json::json!(finished));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn sigterm_also_leaves_a_marked_partial_folder_and_a_complete_folder_is_not_resumed() {
    let dir = tmp("sigterm");
    let out = dir.join("fit");
    let (code, log) = interrupted(&out, "-TERM");
    assert_eq!(code, 143, "{log}");
    let partial = json(&out.join("partial.json"));
    assert_eq!(partial["interrupted_by"], "SIGTERM");
    assert!(out.join("gen/unit.toml").is_file());
    // Without --resume or --force the partial folder is not overwritten.
    let (code, _) = run(&FIT, &out, &[]);
    assert_eq!(code, 7);
    let (code, log) = run(&FIT, &out, &["--resume"]);
    assert_eq!(code, 0, "{log}");
    // Resuming a complete folder is a usage error.
    let (code, log) = run(&FIT, &out, &["--resume"]);
    assert_eq!(code, 2, "{log}");
    assert!(log.contains("complete"), "{log}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A command that does not poll the interrupt (diagnose) ends at SIGINT without leaving its
/// temporary folder, and the target is not created.
#[test]
fn an_interrupted_diagnose_leaves_nothing() {
    let dir = tmp("diag");
    let out = dir.join("diag");
    let mut child = bin()
        .args(["diagnose", "--no-plot", "--out", out.to_str().unwrap()])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let pid = child.id().to_string();
    let mut lines = BufReader::new(child.stderr.take().unwrap()).lines();
    // The first progress line (input warnings come before it): the run has started (its
    // temporary folder exists).
    let first = loop {
        let line = lines.next().unwrap().unwrap();
        if !line.starts_with("warning") {
            break line;
        }
    };
    let staged: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(
        staged.iter().any(|n| n.starts_with(".diag.partial-")),
        "{staged:?} ({first})"
    );
    assert!(Command::new("kill")
        .args(["-INT", &pid])
        .status()
        .unwrap()
        .success());
    let rest: Vec<String> = lines.map(|l| l.unwrap()).collect();
    let code = child.wait().unwrap().code();
    assert_eq!(code, Some(130), "{first}\n{}", rest.join("\n"));
    let left: Vec<_> = std::fs::read_dir(&dir).unwrap().collect();
    assert!(left.is_empty(), "{left:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

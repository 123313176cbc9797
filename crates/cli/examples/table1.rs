//! Paper 000's Table 1 for the bundled Itaipu record: the misfit J = Σ(ΔP² + ΔQ²) after each
//! calibration stage, generic models (SEXS, STAB3, HYGOV: `data/itaipu/unit.toml` with
//! `calibration.toml`) beside the user-defined diagrams (`unit_ud.toml` with
//! `calibration_ud.toml`: the AVR, PSS and governor of `avr_ud.toml`, `pss_ud.toml`,
//! `governor_ud.toml`).
//!
//! ```sh
//! cargo run --release -p itaipu-calib-cli --example table1 -- [OUT_DIR]    # default out/table1
//! ```
//!
//! Runs `itaipu-calib fit` on each (the same staging, swarm, seed and local method) into
//! `OUT_DIR/generic` and `OUT_DIR/user-defined`, or reads their `report.json` when
//! `--reuse` is given, and prints the table.

use std::path::{Path, PathBuf};

fn stage_j(report: &Path) -> Result<Vec<(String, f64)>, String> {
    let text = std::fs::read_to_string(report).map_err(|e| format!("{}: {e}", report.display()))?;
    let r: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| format!("{}: {e}", report.display()))?;
    let j = |v: &serde_json::Value| -> f64 {
        v.as_array()
            .map(|a| a.iter().filter_map(|e| e["j_pq"].as_f64()).sum())
            .unwrap_or(f64::NAN)
    };
    let mut out = vec![("start".to_string(), j(&r["start_fitness"]))];
    for s in r["stages"].as_array().into_iter().flatten() {
        out.push((
            s["stage"].as_str().unwrap_or("?").to_string(),
            j(&s["fitness"]),
        ));
    }
    Ok(out)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let reuse = args.iter().any(|a| a == "--reuse");
    let out = args
        .iter()
        .find(|a| !a.starts_with("--"))
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("out/table1"));
    let cases = [
        (
            "generic",
            "data/itaipu/unit.toml",
            "data/itaipu/calibration.toml",
        ),
        (
            "user-defined",
            "data/itaipu/unit_ud.toml",
            "data/itaipu/calibration_ud.toml",
        ),
    ];
    let mut cols = vec![];
    for (name, unit, calib) in cases {
        let dir = out.join(name);
        if !reuse {
            let code = itaipu_calib_cli::run([
                "itaipu-calib",
                "fit",
                "--unit",
                unit,
                "--calib",
                calib,
                "--out",
                dir.to_str().expect("utf-8 path"),
                "--force",
                "--no-plot",
            ]);
            if code != 0 {
                eprintln!("fit of the {name} unit failed (exit {code})");
                std::process::exit(code.into());
            }
        }
        match stage_j(&dir.join("report.json")) {
            Ok(c) => cols.push(c),
            Err(e) => {
                eprintln!("{e}");
                std::process::exit(1);
            }
        }
    }
    fn label(s: &str) -> &str {
        match s {
            "start" => "as given (datasheet)",
            "gen" => "GENSAE generator",
            "avr" => "AVR",
            "pss" => "AVR/PSS",
            "tg" => "AVR/PSS/TG",
            "joint" => "joint pass (all stages)",
            other => other,
        }
    }
    println!(
        "\nTable 1 (paper 000) for the bundled Itaipu record: J = Σ(ΔP² + ΔQ²), system base\n"
    );
    println!(
        "{:<26} {:>12} {:>14}",
        "model setup", "generic", "user-defined"
    );
    let rows: Vec<&String> = cols[0].iter().map(|(s, _)| s).collect();
    for s in rows {
        let g = cols[0].iter().find(|(n, _)| n == s).map(|x| x.1);
        let u = cols[1].iter().find(|(n, _)| n == s).map(|x| x.1);
        let f = |v: Option<f64>| v.map(|v| format!("{v:.4}")).unwrap_or_else(|| "-".into());
        println!("{:<26} {:>12} {:>14}", label(s), f(g), f(u));
    }
}

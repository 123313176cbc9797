//! The onset detector ([`itaipu_dynamics::event::detect_onset`]) measured on the practice sets
//! and the bundled Itaipu record: per case, the detected onset against the answer key's
//! `event.t_event` in samples, false onsets on the ambient cases, misses; and the plausibility
//! layer's `edge_dropout` warning, which must fire on no practice case and on the Itaipu record's
//! erratic end.
//!
//! `cargo run --release -p itaipu-calib --example onset -- [ROOT ...]` (default: the two
//! practice sets beside the checkout, `../shared/practice` and `../shared/practice2`). Each case
//! is loaded as the practice protocol loads it ([`PracticeCase::load`]: the event is built in
//! memory, the onset detected there); only then is the key read, and only to score. A key's
//! `t_event` is the middle of the event's edge (edges last 2.5 sample intervals), so the first
//! disturbed sample lies up to about 1.25 samples before it.

use std::path::{Path, PathBuf};

use itaipu_calib::practice::{case_dirs, PracticeCase};
use itaipu_dynamics::event::Event;

use itaipu_dynamics::plausibility::check_event;

struct Row {
    case: String,
    kind: String,
    err_samples: Option<f64>,
}

fn key_event(root: &Path, case: &str) -> (String, f64) {
    let path = root.join("answers").join(format!("{case}.json"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let v: serde_json::Value =
        serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let ev = &v["event"];
    (
        ev["type"].as_str().unwrap_or("?").to_string(),
        ev["t_event"].as_f64().unwrap_or(f64::NAN),
    )
}

fn dt(ev: &Event) -> f64 {
    let t = &ev.record.time_s;
    (t[t.len() - 1] - t[0]) / (t.len() - 1) as f64
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let here = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let roots: Vec<PathBuf> = if args.is_empty() {
        vec![
            here.join("../../../shared/practice"),
            here.join("../../../shared/practice2"),
        ]
    } else {
        args.iter().map(PathBuf::from).collect()
    };
    let mut rows = vec![];
    let mut edge = vec![];
    println!(
        "{:<5} {:<8} {:>8} {:>9} {:>8}  detector",
        "case", "event", "key s", "onset s", "err smp"
    );
    for root in &roots {
        for dir in case_dirs(root).unwrap_or_else(|e| panic!("{e}")) {
            let case = PracticeCase::load(&dir).unwrap_or_else(|e| panic!("{e}"));
            // The key, read only now, only to score.
            let (kind, t_event) = key_event(root, &case.name);
            let onset = case.event.onset_s();
            let err = onset.map(|t| (t - t_event) / dt(&case.event));
            println!(
                "{:<5} {:<8} {:>8.3} {:>9} {:>8}  {}",
                case.name,
                kind,
                t_event,
                onset.map_or("none".into(), |t| format!("{t:.4}")),
                err.map_or("-".into(), |e| format!("{e:+.2}")),
                case.event.onset.detection.describe()
            );
            edge.extend(
                check_event(&case.event, Some(case.unit.machine_mva))
                    .into_iter()
                    .filter(|f| f.kind == "edge_dropout")
                    .map(|f| format!("{}: {f}", case.name)),
            );
            rows.push(Row {
                case: case.name.clone(),
                kind,
                err_samples: err,
            });
        }
    }
    println!();
    for kind in ["fault", "vstep", "freq"] {
        let of: Vec<&Row> = rows.iter().filter(|r| r.kind == kind).collect();
        let errs: Vec<f64> = of.iter().filter_map(|r| r.err_samples).collect();
        let misses: Vec<&str> = of
            .iter()
            .filter(|r| r.err_samples.is_none())
            .map(|r| r.case.as_str())
            .collect();
        let within2 = errs.iter().filter(|e| e.abs() <= 2.0).count();
        let worst = errs.iter().fold(0.0_f64, |m, e| m.max(e.abs()));
        println!(
            "{kind:<6} {} cases: {} missed {:?}, {} within 2 samples, largest |error| {:.2} samples",
            of.len(),
            misses.len(),
            misses,
            within2,
            worst
        );
    }
    let ambient: Vec<&Row> = rows.iter().filter(|r| r.kind == "ambient").collect();
    let false_onsets: Vec<&str> = ambient
        .iter()
        .filter(|r| r.err_samples.is_some())
        .map(|r| r.case.as_str())
        .collect();
    println!(
        "ambient {} cases: {} false onset(s) {:?}",
        ambient.len(),
        false_onsets.len(),
        false_onsets
    );

    println!(
        "edge_dropout on {} practice case(s){}",
        edge.len(),
        edge.iter().map(|e| format!("\n  {e}")).collect::<String>()
    );

    // The bundled Itaipu record: the event file (explicit init, onset detected) and the
    // COMTRADE recording imported.
    let data = here.join("../../data/itaipu");
    let bundled = Event::from_toml_file(&data.join("event.toml")).expect("bundled Itaipu event");
    println!("\nItaipu, bundled CSV: {}", bundled.onset.describe());
    for f in check_event(&bundled, Some(737.0)) {
        println!("  {f}");
    }
    let opts = itaipu_dynamics::pmu_import::ImportOptions {
        v_base_kv: Some(18.0),
        ..itaipu_dynamics::pmu_import::ImportOptions::new(1000.0, 60.0)
    };
    let (imported, _) =
        itaipu_dynamics::pmu_import::import(&data.join("pmu/itaipu.cfg"), &opts).expect("import");
    println!(
        "Itaipu, COMTRADE import: {}; init window {}",
        imported.onset.describe(),
        imported.init
    );
}

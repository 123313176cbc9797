//! The plausibility layer (issue 13): each implausibility of the bad-input table found, with
//! the file, the line and the fix; the bundled record passes clean.

use std::path::{Path, PathBuf};

use itaipu_dynamics::event::Event;
use itaipu_dynamics::plausibility::{check_event, check_unit, has_errors, Finding, Severity};
use itaipu_dynamics::unit_file::read_unit;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

struct Tmp(PathBuf);
impl Tmp {
    fn new(tag: &str) -> Self {
        let p = std::env::temp_dir().join(format!("itaipu-plaus-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&p);
        std::fs::create_dir_all(&p).unwrap();
        Tmp(p)
    }
}
impl Drop for Tmp {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// The Itaipu record's rows: time, v_re, v_im, p, q.
fn rows() -> Vec<[f64; 5]> {
    let text = std::fs::read_to_string(repo().join("data/itaipu/itaipu_pmu_60sps.csv")).unwrap();
    text.lines()
        .skip(1)
        .map(|l| {
            let v: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
            [v[0], v[1], v[2], v[3], v[4]]
        })
        .collect()
}

/// Writes an event (TOML + CSV) with `rows` and reads it.
fn event(dir: &Path, rows: &[[f64; 5]], system_mva: f64) -> Event {
    let mut csv = String::from("time_s,v_re_pu,v_im_pu,p_pu,q_pu\n");
    for r in rows {
        csv.push_str(&format!(
            "{:?},{:?},{:?},{:?},{:?}\n",
            r[0], r[1], r[2], r[3], r[4]
        ));
    }
    std::fs::write(dir.join("e.csv"), csv).unwrap();
    let toml = format!(
        "name = \"t\"\ncsv = \"e.csv\"\nsystem_mva = {system_mva:?}\nnominal_hz = 60.0\n[init]\nstart_s = {:?}\nend_s = {:?}\n",
        rows[0][0],
        rows[0][0] + 0.95 * (rows[1][0] - rows[0][0]) * 60.0
    );
    std::fs::write(dir.join("e.toml"), toml).unwrap();
    Event::from_toml_file(&dir.join("e.toml")).unwrap()
}

fn find<'a>(f: &'a [Finding], kind: &str) -> &'a Finding {
    f.iter()
        .find(|x| x.kind == kind)
        .unwrap_or_else(|| panic!("no {kind} in {f:#?}"))
}

const ITAIPU_MVA: f64 = 737.0;

/// The findings other than the bundled record's own: its erratic |V| after 4.4 s (the
/// `edge_dropout` warning, see `the_bundled_record_ends_in_a_measurement_dropout`).
fn others(f: Vec<Finding>) -> Vec<Finding> {
    f.into_iter().filter(|x| x.kind != "edge_dropout").collect()
}

#[test]
fn the_bundled_record_and_unit_are_plausible() {
    let e = Event::from_toml_file(&repo().join("data/itaipu/event.toml")).unwrap();
    let f = check_event(&e, Some(ITAIPU_MVA));
    assert!(!has_errors(&f), "{f:#?}");
    assert_eq!(others(f), vec![]);
    let u = read_unit(&repo().join("data/itaipu/unit.toml")).unwrap();
    assert_eq!(check_unit(&u, Path::new("unit.toml")), vec![]);
}

#[test]
fn gaps_are_warnings_and_a_100_s_gap_is_an_error_at_its_line() {
    let t = Tmp::new("gap");
    // One second missing (60 intervals): a warning at the first sample after it.
    let mut r = rows();
    r.drain(100..160);
    let f = check_event(&event(&t.0, &r, 1000.0), Some(ITAIPU_MVA));
    let g = find(&f, "time_gap");
    assert_eq!(g.severity, Severity::Warning);
    assert_eq!(g.line, Some(102), "{g}");
    assert!(g.file.ends_with("e.csv") && g.to_string().contains("fix: "));
    // 100 s: an error.
    let mut r = rows();
    for x in &mut r[150..] {
        x[0] += 100.0;
    }
    let f = check_event(&event(&t.0, &r, 1000.0), Some(ITAIPU_MVA));
    let g = find(&f, "time_gap");
    assert_eq!(g.severity, Severity::Error);
    assert_eq!(g.line, Some(152));
    assert!(g.message.contains("100."), "{}", g.message);
}

#[test]
fn a_single_sample_dropout_is_an_error_not_a_fault() {
    let t = Tmp::new("dropout");
    let mut r = rows();
    r[200][1] = 0.0;
    r[200][2] = 0.0;
    let f = check_event(&event(&t.0, &r, 1000.0), Some(ITAIPU_MVA));
    let d = find(&f, "dropout");
    assert_eq!((d.severity, d.line), (Severity::Error, Some(202)));
    // Its two |V| steps, which Q does not follow either, are not chained to the record's end.
    assert_eq!(find(&f, "edge_dropout").line, Some(266));
    // A dip that lasts (the real fault of the record) is no dropout.
    assert!(others(check_event(&event(&t.0, &rows(), 1000.0), Some(ITAIPU_MVA))).is_empty());
}

/// Blank lines in the CSV (which the reader skips) do not shift the line a finding names, nor
/// the line a run-time failure is traced to.
#[test]
fn lines_are_the_files_lines_with_blank_lines_in_it() {
    let t = Tmp::new("blank");
    let mut r = rows();
    r[200][1] = 0.0;
    r[200][2] = 0.0;
    let e = event(&t.0, &r, 1000.0);
    // Three blank lines after the header, two after the 50th sample (line 52).
    let csv = std::fs::read_to_string(t.0.join("e.csv")).unwrap();
    let mut lines: Vec<&str> = csv.lines().collect();
    lines.splice(52..52, ["", ""]);
    lines.splice(1..1, ["", "", ""]);
    std::fs::write(t.0.join("e.csv"), lines.join("\n") + "\n").unwrap();
    let e2 = Event::from_toml_file(&t.0.join("e.toml")).unwrap();
    assert_eq!(e2.record.time_s, e.record.time_s);
    let d = find(&check_event(&e2, Some(ITAIPU_MVA)), "dropout").clone();
    // Sample 200: line 202 without the blank lines, 207 with them.
    assert_eq!(d.line, Some(207), "{d}");
    let written = std::fs::read_to_string(t.0.join("e.csv")).unwrap();
    assert!(written
        .lines()
        .nth(206)
        .unwrap()
        .starts_with(&format!("{:?},0.0,0.0", r[200][0])));
    // A failure at t = 1.65 s (sample 99) is traced to line 99 + 2 + 5 = 106.
    let at = itaipu_dynamics::plausibility::locate_time(&e2, 1.65);
    assert!(at.contains("line 106 (t = 1.65"), "{at}");
    assert!(written.lines().nth(105).unwrap().starts_with("1.65"));
}

#[test]
fn a_time_column_scaled_absurdly_is_an_error() {
    let t = Tmp::new("timescale");
    for (scale, hint) in [(1e-12, "scaled"), (1000.0, "milliseconds")] {
        let mut r = rows();
        for x in &mut r {
            x[0] *= scale;
        }
        let f = check_event(&event(&t.0, &r, 1000.0), Some(ITAIPU_MVA));
        let d = find(&f, "time_scale");
        assert_eq!(d.severity, Severity::Error);
        assert!(d.fix.contains(hint), "{d}");
    }
}

#[test]
fn flipped_signs_warn_and_p_above_the_rating_is_an_error() {
    let t = Tmp::new("sign");
    let mut r = rows();
    for x in &mut r {
        x[3] = -x[3];
        x[4] = -x[4];
    }
    let f = check_event(&event(&t.0, &r, 1000.0), Some(ITAIPU_MVA));
    let d = find(&f, "absorbing_p");
    assert_eq!(d.severity, Severity::Warning);
    assert!(!has_errors(&f));
    // P and Q on a base 10 × too small: 6 235 MW on a 737 MVA machine.
    let f = check_event(&event(&t.0, &rows(), 10_000.0), Some(ITAIPU_MVA));
    let d = find(&f, "above_rating");
    assert_eq!(d.severity, Severity::Error);
    assert!(d.fix.contains("system_mva"), "{d}");
    // Without the unit the rating is unknown: not flagged.
    assert!(check_event(&event(&t.0, &rows(), 10_000.0), None)
        .iter()
        .all(|x| x.kind != "above_rating"));
}

#[test]
fn an_absurd_sample_and_a_spike_point_at_their_line() {
    let t = Tmp::new("absurd");
    let mut r = rows();
    r[120][3] = 1e300;
    let e = Event::from_toml_file(&{
        let _ = event(&t.0, &rows(), 1000.0);
        let mut csv = String::from("time_s,v_re_pu,v_im_pu,p_pu,q_pu\n");
        for x in &r {
            csv.push_str(&format!(
                "{:?},{:?},{:?},{:?},{:?}\n",
                x[0], x[1], x[2], x[3], x[4]
            ));
        }
        std::fs::write(t.0.join("e.csv"), csv).unwrap();
        t.0.join("e.toml")
    });
    match e {
        // The reader may refuse it first (it looks like MW); then with the line.
        Err(err) => assert!(err.to_string().contains("line 122"), "{err}"),
        Ok(e) => {
            let f = check_event(&e, Some(ITAIPU_MVA));
            let d = find(&f, "absurd_value");
            assert_eq!((d.severity, d.line), (Severity::Error, Some(122)));
        }
    }
    let mut r = rows();
    r[30][4] += 2.0;
    let f = check_event(&event(&t.0, &r, 1000.0), Some(ITAIPU_MVA));
    let d = find(&f, "spike");
    assert_eq!(
        (d.severity, d.line, d.column.as_str()),
        (Severity::Warning, Some(32), "q_pu")
    );
}

#[test]
fn an_angle_column_in_radians_is_found() {
    let t = Tmp::new("radians");
    // |V| and angle with a 0.5 Hz offset from nominal (the angle wraps), the angle in radians
    // under an angle_deg header.
    let mut csv = String::from("time_s,v_pu,angle_deg,p_pu,q_pu\n");
    for x in rows() {
        let a = x[2].atan2(x[1]) + std::f64::consts::TAU * 0.5 * x[0];
        let a = (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
        csv.push_str(&format!(
            "{:?},{:?},{:?},{:?},{:?}\n",
            x[0],
            x[1].hypot(x[2]),
            a,
            x[3],
            x[4]
        ));
    }
    std::fs::write(t.0.join("e.csv"), &csv).unwrap();
    std::fs::write(
        t.0.join("e.toml"),
        "name = \"t\"\ncsv = \"e.csv\"\nsystem_mva = 1000.0\nnominal_hz = 60.0\n",
    )
    .unwrap();
    let e = Event::from_toml_file(&t.0.join("e.toml")).unwrap();
    let f = check_event(&e, Some(ITAIPU_MVA));
    let d = find(&f, "angle_radians");
    assert_eq!(
        (d.severity, d.column.as_str()),
        (Severity::Error, "angle_deg")
    );
    // The same in degrees is fine.
    let deg: String = csv
        .lines()
        .enumerate()
        .map(|(i, l)| {
            if i == 0 {
                return format!("{l}\n");
            }
            let mut v: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
            v[2] = v[2].to_degrees();
            format!("{:?},{:?},{:?},{:?},{:?}\n", v[0], v[1], v[2], v[3], v[4])
        })
        .collect();
    std::fs::write(t.0.join("e.csv"), deg).unwrap();
    let e = Event::from_toml_file(&t.0.join("e.toml")).unwrap();
    assert!(check_event(&e, Some(ITAIPU_MVA))
        .iter()
        .all(|x| x.kind != "angle_radians"));
}

#[test]
fn parameters_far_outside_the_library_ranges_warn() {
    let t = Tmp::new("params");
    let text = std::fs::read_to_string(repo().join("data/itaipu/unit.toml")).unwrap();
    let text = text.replace("h = 4.5 ", "h = 1e308 ");
    std::fs::write(t.0.join("u.toml"), text).unwrap();
    let u = read_unit(&t.0.join("u.toml")).unwrap();
    let f = check_unit(&u, &t.0.join("u.toml"));
    assert_eq!(f.len(), 1, "{f:#?}");
    assert_eq!(
        (f[0].kind, f[0].column.as_str()),
        ("parameter_range", "machine.h")
    );
    assert!(
        f[0].message
            .starts_with("1e308 s lies far outside the library's typical range 3-6"),
        "{}",
        f[0].message
    );
}

/// Issue 25: the bundled record's last samples (its README: "after 4.25 s the voltage
/// magnitude becomes erratic (0.72-1.01 pu) while P and Q stay smooth") are flagged as a
/// measurement drop-out, a warning naming the span; a record that ends in a real fault (Q
/// answers |V|) is not, and the start of a record is checked the same way.
#[test]
fn the_bundled_record_ends_in_a_measurement_dropout() {
    let e = Event::from_toml_file(&repo().join("data/itaipu/event.toml")).unwrap();
    for mva in [Some(ITAIPU_MVA), None] {
        let f = check_event(&e, mva);
        let d = find(&f, "edge_dropout");
        assert_eq!(
            (d.severity, d.column.as_str(), d.line),
            (Severity::Warning, "|V|", Some(266)),
            "{d}"
        );
        assert!((d.time_s.unwrap() - 4.4).abs() < 1e-6, "{d}");
        assert!(d.message.contains("ends in a measurement drop-out"), "{d}");
        assert!(d.message.contains("to 4.65 s (16 samples)"), "{d}");
        assert!(d.fix.contains("before 4.4 s"), "{d}");
        assert_eq!(f.iter().filter(|x| x.kind == "edge_dropout").count(), 1);
    }
    // Cut before the erratic part: nothing.
    let t = Tmp::new("edge");
    let r = rows();
    let f = check_event(&event(&t.0, &r[..255], 1000.0), Some(ITAIPU_MVA));
    assert_eq!(f, vec![]);
    // The same record ending in the fault's first samples: |V| falls, Q answers: no drop-out.
    let f = check_event(&event(&t.0, &r[..63], 1000.0), Some(ITAIPU_MVA));
    assert!(f.iter().all(|x| x.kind != "edge_dropout"), "{f:#?}");
    // |V| alone falling 0.1 pu in the last two samples (P, Q untouched): a drop-out.
    let mut cut = r[..200].to_vec();
    for x in &mut cut[198..] {
        x[1] *= 0.9;
        x[2] *= 0.9;
    }
    let f = check_event(&event(&t.0, &cut, 1000.0), Some(ITAIPU_MVA));
    let d = find(&f, "edge_dropout");
    assert!((d.time_s.unwrap() - cut[198][0]).abs() < 1e-9, "{d}");
    // Reversed in time (the record starts in it): the start's mirror.
    let t_end = r[r.len() - 1][0];
    let mut rev: Vec<[f64; 5]> = r[60..].iter().rev().copied().collect();
    for x in &mut rev {
        x[0] = t_end - x[0];
    }
    let f = check_event(&event(&t.0, &rev, 1000.0), Some(ITAIPU_MVA));
    let d = find(&f, "edge_dropout");
    assert!(
        d.message.contains("starts in a measurement drop-out"),
        "{d}"
    );
    assert_eq!(d.time_s, Some(0.0), "{d}");
    assert!(d.fix.contains("start [playback]"), "{d}");
}

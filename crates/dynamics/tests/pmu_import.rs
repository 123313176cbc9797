//! PMU import: the bundled Itaipu record written as a C37.118-style CSV (kV and A, ISO time
//! stamps) and as COMTRADE (1999 ASCII, 1999 BINARY, 2013 FLOAT32) by code in this test imports
//! back to the same P, Q and |V| within each format's resolution; gaps and dropouts are
//! reported; bad files are errors naming the file and the line or record.

use std::f64::consts::PI;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use itaipu_dynamics::event::Event;
use itaipu_dynamics::pmu_import::{import, write_event_folder, ImportError, ImportOptions};

const V_BASE_KV: f64 = 18.0; // rated line-to-line voltage of an Itaipu unit

fn itaipu() -> Event {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/itaipu/event.toml");
    Event::from_toml_file(&p).unwrap()
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("itaipu-import-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Per sample: |V_an| kV, angle deg, |I| A, angle deg (generator convention, S = 3 V I*).
fn physical(e: &Event) -> Vec<(f64, f64, f64, f64)> {
    let r = &e.record;
    (0..r.len())
        .map(|k| {
            let v = r.v_mag_pu[k] * V_BASE_KV / 3f64.sqrt();
            let th = r.v_ang_rad[k];
            let (p, q) = (r.p_pu[k] * e.system_mva, r.q_pu[k] * e.system_mva); // MVA
                                                                               // I = conj(S / (3 V)) in kA: |I| = |S|/(3|V|), angle θ − atan2(Q, P).
            let i = p.hypot(q) / (3.0 * v) * 1e3;
            let ia = th - q.atan2(p);
            (v, th.to_degrees(), i, ia.to_degrees())
        })
        .collect()
}

fn opts() -> ImportOptions {
    let mut o = ImportOptions::new(1000.0, 60.0);
    o.v_base_kv = Some(V_BASE_KV);
    o.name = Some("itaipu-imported".into());
    o
}

fn stamp(t: f64) -> String {
    // 2015-06-01T12:00:00Z + t, to the microsecond.
    let us = (t * 1e6).round() as i64;
    format!(
        "2015-06-01T12:{:02}:{:02}.{:06}Z",
        us / 60_000_000,
        us / 1_000_000 % 60,
        us % 1_000_000
    )
}

/// Asserts P, Q, |V| and time against the original within the given tolerances.
fn same(a: &Event, b: &Event, tol_p: &[f64], tol_v: &[f64], what: &str) {
    let (ra, rb) = (&a.record, &b.record);
    assert_eq!(ra.len(), rb.len(), "{what}: sample count");
    for k in 0..ra.len() {
        assert!(
            (ra.time_s[k] - rb.time_s[k]).abs() < 1e-6,
            "{what}: time {k}"
        );
        assert!(
            (ra.v_mag_pu[k] - rb.v_mag_pu[k]).abs() <= tol_v[k],
            "{what}: |V| {k}: {} vs {}",
            ra.v_mag_pu[k],
            rb.v_mag_pu[k]
        );
        for (x, y, n) in [(&ra.p_pu, &rb.p_pu, "P"), (&ra.q_pu, &rb.q_pu, "Q")] {
            assert!(
                (x[k] - y[k]).abs() <= tol_p[k],
                "{what}: {n} {k}: {} vs {} (tol {})",
                x[k],
                y[k],
                tol_p[k]
            );
        }
    }
    // The playback angle too (the phasor's frame is kept): compare the wrapped difference.
    for k in 0..ra.len() {
        let d = (ra.v_ang_rad[k] - rb.v_ang_rad[k] + PI).rem_euclid(2.0 * PI) - PI;
        assert!(d.abs() < 1e-3, "{what}: angle {k}: {d}");
    }
}

#[test]
fn a_c37118_csv_in_kv_and_a_imports_back_to_the_itaipu_record() {
    let e = itaipu();
    let ph = physical(&e);
    let dir = tmp("c37");
    let mut s = String::from(
        "Timestamp,STAT,V1.MAG [kV],V1.ANG [deg],I1.MAG [A],I1.ANG [deg],VA.MAG [kV],DFREQ\n",
    );
    for (k, (v, va, i, ia)) in ph.iter().enumerate() {
        writeln!(
            s,
            "{},0x0000,{v},{va},{i},{ia},{v},0",
            stamp(e.record.time_s[k])
        )
        .unwrap();
    }
    let f = dir.join("pmu.csv");
    std::fs::write(&f, s).unwrap();
    let (got, rep) = import(&f, &opts()).unwrap();
    // Text with full f64 precision: only rounding.
    let n = e.record.len();
    same(&e, &got, &vec![1e-12; n], &vec![1e-12; n], "CSV");
    assert_eq!(rep.start.as_deref(), Some("2015-06-01T12:00:00.000000Z"));
    assert!(
        (rep.source_rate_hz - 60.0).abs() < 1e-6,
        "{}",
        rep.source_rate_hz
    );
    assert!(rep.gaps.is_empty() && rep.dropouts.is_empty());
    assert!(
        rep.warnings.iter().any(|w| w.contains("VA.MAG")),
        "{:?}",
        rep.warnings
    );

    // The event folder reads back as an event with the same record.
    let out = dir.join("event");
    write_event_folder(&got, &rep, &out).unwrap();
    let back = Event::from_toml_file(&out.join("event.toml")).unwrap();
    same(&e, &back, &vec![1e-12; n], &vec![1e-12; n], "event folder");
    assert!(std::fs::read_to_string(out.join("import.json"))
        .unwrap()
        .contains("\"samples_kept\": 280"));

    // Resampled to 30 samples/s: every other sample, each the mean of the two within ±1/60 s
    // (the boxcar), so within the record's sample-to-sample change.
    let mut o = opts();
    o.rate_hz = Some(30.0);
    let (half, rep) = import(&f, &o).unwrap();
    assert_eq!(rep.resampled_hz, Some(30.0));
    assert_eq!(half.record.len(), 140);
    assert!((half.record.time_s[1] - 1.0 / 30.0).abs() < 1e-12);
}

#[test]
fn per_unit_rectangular_phasors_with_epoch_time_and_a_current_into_the_machine() {
    let e = itaipu();
    let r = &e.record;
    let dir = tmp("pu");
    let mut s = String::from("soc,fracsec,v_re_pu,v_im_pu,i_re_pu,i_im_pu,freq\n");
    let base = 737.0; // channels in pu on the machine base
    for k in 0..r.len() {
        let (vr, vi) = (
            r.v_mag_pu[k] * r.v_ang_rad[k].cos(),
            r.v_mag_pu[k] * r.v_ang_rad[k].sin(),
        );
        let (p, q) = (r.p_pu[k] * 1000.0 / base, r.q_pu[k] * 1000.0 / base);
        // I = conj(S/V), measured into the machine: −I.
        let m2 = vr * vr + vi * vi;
        let (ir, ii) = ((p * vr + q * vi) / m2, (p * vi - q * vr) / m2);
        let t = 1_433_160_000.0 + r.time_s[k];
        writeln!(
            s,
            "{},{:.9},{vr},{vi},{},{},60.0",
            t.floor() as i64,
            t - t.floor(),
            -ir,
            -ii
        )
        .unwrap();
    }
    let f = dir.join("pu.csv");
    std::fs::write(&f, s).unwrap();
    let mut o = ImportOptions::new(1000.0, 60.0);
    o.pu_base_mva = Some(base);
    o.current_into_machine = true;
    let (got, rep) = import(&f, &o).unwrap();
    let n = r.len();
    same(&e, &got, &vec![1e-9; n], &vec![1e-12; n], "pu CSV");
    assert_eq!(got.record.freq_hz.as_ref().unwrap()[0], 60.0);
    assert_eq!(rep.start.as_deref(), Some("2015-06-01T12:00:00.000000Z"));
}

/// Writes a COMTRADE pair. `codes` gives (sample number, values) per record; `fmt` ASCII,
/// BINARY or FLOAT32. Channels: V1 MAG kV, V1 ANG deg, I1 MAG A, I1 ANG deg, with scale `a`.
fn comtrade(dir: &Path, rev: u32, fmt: &str, a: [f64; 4], rows: &[(u32, [f64; 4])]) -> PathBuf {
    let mut c = String::new();
    writeln!(c, "ITAIPU,PMU-U1,{rev}").unwrap();
    writeln!(c, "5,4A,1D").unwrap();
    for (k, (id, uu)) in [
        ("V1 MAG", "kV"),
        ("V1 ANG", "deg"),
        ("I1 MAG", "A"),
        ("I1 ANG", "deg"),
    ]
    .iter()
    .enumerate()
    {
        writeln!(c, "{},{id},,,{uu},{:e},0,0,-32767,32767,1,1,P", k + 1, a[k]).unwrap();
    }
    writeln!(c, "1,TRIP,,,0").unwrap();
    writeln!(c, "60").unwrap();
    writeln!(c, "1").unwrap();
    writeln!(c, "60,{}", rows.last().unwrap().0).unwrap();
    writeln!(c, "01/06/2015,12:00:00.000000").unwrap();
    writeln!(c, "01/06/2015,12:00:01.000000").unwrap();
    writeln!(c, "{fmt}").unwrap();
    writeln!(c, "1").unwrap();
    if rev == 2013 {
        writeln!(c, "0,0\nF,0").unwrap();
    }
    let cfg = dir.join("rec.cfg");
    std::fs::write(&cfg, c).unwrap();
    let mut dat: Vec<u8> = vec![];
    for (n, x) in rows {
        let ts = ((*n - 1) as f64 * 1e6 / 60.0).round() as u32;
        match fmt {
            "ASCII" => {
                let f: Vec<String> = x
                    .iter()
                    .map(|v| {
                        if v.is_nan() {
                            String::new()
                        } else {
                            format!("{v}")
                        }
                    })
                    .collect();
                dat.extend(format!("{n},{ts},{},0\n", f.join(",")).bytes());
            }
            "BINARY" => {
                dat.extend(n.to_le_bytes());
                dat.extend(ts.to_le_bytes());
                for v in x {
                    let code = if v.is_nan() { i16::MIN } else { *v as i16 };
                    dat.extend(code.to_le_bytes());
                }
                dat.extend(0u16.to_le_bytes());
            }
            _ => {
                dat.extend(n.to_le_bytes());
                dat.extend(ts.to_le_bytes());
                for v in x {
                    dat.extend((*v as f32).to_le_bytes());
                }
                dat.extend(0u16.to_le_bytes());
            }
        }
    }
    std::fs::write(dir.join("rec.dat"), dat).unwrap();
    cfg
}

/// Bound on the P, Q error (system pu) from rounding V, I and the angles by half a step each
/// (S = 3 V I: first order in each, plus the second order), and on |V| (pu).
fn tolerances(
    ph: &[(f64, f64, f64, f64)],
    step: &dyn Fn(usize, f64) -> f64,
) -> (Vec<f64>, Vec<f64>) {
    let mut tp = vec![];
    let mut tv = vec![];
    for (v, va, i, ia) in ph {
        let (dv, di) = (step(0, *v) / 2.0, step(2, *i) / 2.0 * 1e-3);
        let dth = (step(1, *va) + step(3, *ia)).to_radians() / 2.0;
        let (v, i) = (*v, *i * 1e-3);
        let ds = 3.0 * ((v + dv) * (i + di) * (1.0 + dth) - v * i + v * i * dth);
        tp.push(ds / 1000.0 * 1.0001 + 1e-12);
        tv.push(dv * 3f64.sqrt() / V_BASE_KV * 1.0001 + 1e-12);
    }
    (tp, tv)
}

#[test]
fn comtrade_ascii_binary_and_float32_import_back_within_their_resolution() {
    let e = itaipu();
    let ph = physical(&e);
    // Scales: 16-bit codes over the channels' ranges.
    let a = [
        12.0 / 32767.0,
        180.0 / 32767.0,
        40_000.0 / 32767.0,
        180.0 / 32767.0,
    ];
    let wrap = |d: f64| (d + 180.0).rem_euclid(360.0) - 180.0;
    let coded: Vec<(u32, [f64; 4])> = ph
        .iter()
        .enumerate()
        .map(|(k, (v, va, i, ia))| {
            let x = [*v, wrap(*va), *i, wrap(*ia)];
            (k as u32 + 1, std::array::from_fn(|j| (x[j] / a[j]).round()))
        })
        .collect();
    let quantum = |j: usize, _: f64| a[j];
    let (tp, tv) = tolerances(&ph, &quantum);
    for (rev, fmt) in [(1999, "ASCII"), (1999, "BINARY")] {
        let dir = tmp(&format!("ct-{fmt}"));
        let cfg = comtrade(&dir, rev, fmt, a, &coded);
        let (got, rep) = import(&cfg, &opts()).unwrap();
        assert_eq!(rep.format, format!("COMTRADE {rev} {fmt}"));
        assert_eq!(rep.start.as_deref(), Some("2015-06-01T12:00:00.000000Z"));
        same(&e, &got, &tp, &tv, fmt);
        // The bound is not loose: the worst error uses a fair part of it.
        let worst = (0..e.record.len())
            .map(|k| (e.record.p_pu[k] - got.record.p_pu[k]).abs() / tp[k])
            .fold(0.0, f64::max);
        assert!(
            worst > 0.05,
            "{fmt}: worst P error only {worst} of the bound"
        );
    }
    // FLOAT32 (2013): values as 32-bit floats, scale 1.
    let floats: Vec<(u32, [f64; 4])> = ph
        .iter()
        .enumerate()
        .map(|(k, (v, va, i, ia))| (k as u32 + 1, [*v, wrap(*va), *i, wrap(*ia)]))
        .collect();
    let dir = tmp("ct-float");
    let cfg = comtrade(&dir, 2013, "FLOAT32", [1.0; 4], &floats);
    let f32_step = |_: usize, x: f64| x.abs().max(1e-30) * f32::EPSILON as f64;
    let (tp, tv) = tolerances(&ph, &f32_step);
    let (got, _) = import(&cfg, &opts()).unwrap();
    same(&e, &got, &tp, &tv, "FLOAT32");
}

#[test]
fn gaps_and_dropouts_are_reported_and_the_bad_samples_left_out() {
    let e = itaipu();
    let ph = physical(&e);
    let a = [
        12.0 / 32767.0,
        180.0 / 32767.0,
        40_000.0 / 32767.0,
        180.0 / 32767.0,
    ];
    let wrap = |d: f64| (d + 180.0).rem_euclid(360.0) - 180.0;
    let mut rows: Vec<(u32, [f64; 4])> = ph
        .iter()
        .enumerate()
        .map(|(k, (v, va, i, ia))| {
            (
                k as u32 + 1,
                [v / a[0], wrap(*va) / a[1], i / a[2], wrap(*ia) / a[3]].map(f64::round),
            )
        })
        .collect();
    rows.drain(100..103); // samples 101-103 never arrived: a gap
    rows[150].1[0] = f64::NAN; // a missing-data code in |V|: a dropout
    for fmt in ["ASCII", "BINARY"] {
        let dir = tmp(&format!("gap-{fmt}"));
        let cfg = comtrade(&dir, 1999, fmt, a, &rows);
        let (got, rep) = import(&cfg, &opts()).unwrap();
        assert_eq!(rep.samples_read, 277, "{fmt}");
        assert_eq!((rep.samples_kept, got.record.len()), (276, 276), "{fmt}");
        assert_eq!(rep.gaps.len(), 1, "{fmt}: {rep}");
        assert_eq!(rep.gaps[0].missing, 3, "{fmt}");
        assert!(
            (rep.gaps[0].from_s - 99.0 / 60.0).abs() < 1e-9
                && (rep.gaps[0].to_s - 103.0 / 60.0).abs() < 1e-9,
            "{fmt}: {rep}"
        );
        assert_eq!(rep.dropouts.len(), 1, "{fmt}");
        assert!(rep.dropouts[0].reason.contains("V1 MAG"), "{fmt}: {rep}");
        let at = if fmt == "ASCII" {
            "line 151"
        } else {
            "record 151"
        };
        assert!(
            rep.dropouts[0].at.starts_with(at),
            "{fmt}: {}",
            rep.dropouts[0].at
        );
        // Resampled, the gap is filled on the uniform grid (and said so).
        let mut o = opts();
        o.rate_hz = Some(60.0);
        let (uni, rep) = import(&cfg, &o).unwrap();
        assert_eq!(uni.record.len(), 280, "{fmt}");
        assert!(
            rep.warnings
                .iter()
                .any(|w| w.contains("filled by interpolation")),
            "{rep}"
        );
    }
    // STAT data-error bits in a CSV make dropouts.
    let dir = tmp("stat");
    let mut s = String::from("timestamp,stat,v_mag_kv,v_ang_deg,i_mag_a,i_ang_deg\n");
    for (k, (v, va, i, ia)) in ph.iter().enumerate().take(40) {
        let stat = if k == 20 {
            "0xC000"
        } else if k == 21 {
            "0x2000"
        } else {
            "0"
        };
        writeln!(s, "{},{stat},{v},{va},{i},{ia}", stamp(e.record.time_s[k])).unwrap();
    }
    std::fs::write(dir.join("s.csv"), s).unwrap();
    let (got, rep) = import(&dir.join("s.csv"), &opts()).unwrap();
    assert_eq!(got.record.len(), 39);
    assert_eq!(rep.dropouts[0].at, "line 22");
    assert!(
        rep.dropouts[0].reason.contains("do not")
            || rep.dropouts[0].reason.contains("not to be used"),
        "{rep}"
    );
    assert!(rep.warnings.iter().any(|w| w.contains("bit 13")), "{rep}");
    assert!(rep.gaps.is_empty(), "a dropout is not also a gap: {rep}");
}

fn err(path: &Path, o: &ImportOptions) -> ImportError {
    match import(path, o) {
        Ok(_) => panic!("{} accepted", path.display()),
        Err(e) => e,
    }
}

#[test]
fn bad_files_are_errors_naming_the_file_and_the_line_or_record() {
    let dir = tmp("bad");
    let head = "timestamp,v_mag_kv,v_ang_deg,i_mag_a,i_ang_deg\n";
    let row = |t: f64| format!("{},10.4,1.0,20000,-3.0\n", stamp(t));
    let rows: String = (0..10).map(|k| row(k as f64 / 60.0)).collect();
    let cases: Vec<(&str, String, &str, &str)> = vec![
        (
            "text in a number column",
            format!("{head}{}{}", rows, row(0.5).replace("10.4", "ten")),
            "data",
            "line 12, column v_mag_kv: 'ten' is not a number",
        ),
        (
            "no time column",
            head.replace("timestamp", "when") + &rows,
            "data",
            "line 1: no time column",
        ),
        (
            "bad time stamp",
            format!("{head}{}2015-06-01T25:00:00Z,1,1,1,1\n", rows),
            "data",
            "line 12, column timestamp",
        ),
        (
            "time going back",
            format!("{head}{}{}", rows, row(0.05)),
            "data",
            "line 12: time",
        ),
        (
            "no unit",
            head.replace("v_mag_kv", "v_mag") + &rows,
            "data",
            "'v_mag' (v_mag): no unit",
        ),
        (
            "a wrong unit",
            head.replace("i_mag_a", "i_mag_kv") + &rows,
            "data",
            "unit kV does not fit",
        ),
        (
            "no current",
            "timestamp,v_mag_kv,v_ang_deg\n".to_string()
                + &(0..5)
                    .map(|k| format!("{},10,0\n", stamp(k as f64)))
                    .collect::<String>(),
            "data",
            "the current phasor needs",
        ),
        (
            "wrong field count",
            format!("{head}{}2015-06-01T12:00:01Z,1,1\n", rows),
            "data",
            "line 12: 3 fields",
        ),
        (
            "kV read as pu (no base)",
            format!("{head}{rows}"),
            "options",
            "v_base_kv: missing",
        ),
    ];
    for (what, text, kind, mention) in cases {
        let f = dir.join("bad.csv");
        std::fs::write(&f, text).unwrap();
        let mut o = opts();
        if what.starts_with("kV read") {
            o.v_base_kv = None;
        }
        let e = err(&f, &o);
        let msg = e.to_string();
        assert_eq!(e.kind(), kind, "{what}: {msg}");
        assert!(msg.starts_with(&f.display().to_string()), "{what}: {msg}");
        assert!(
            msg.contains(mention),
            "{what}: '{msg}' should contain '{mention}'"
        );
    }

    // COMTRADE: a bad .cfg line, an ASCII .dat line, a truncated binary record.
    let a = [1e-3; 4];
    let rows: Vec<(u32, [f64; 4])> = (1..=20)
        .map(|n| (n, [10400.0, 0.0, 20000.0, -3000.0]))
        .collect();
    let cfg = comtrade(&dir, 1999, "ASCII", a, &rows);
    let text = std::fs::read_to_string(&cfg).unwrap();
    std::fs::write(
        &cfg,
        text.replace("3,I1 MAG,,,A,1e-3,0,0,-32767,32767,1,1,P", "3,I1 MAG,,,A"),
    )
    .unwrap();
    let e = err(&cfg, &opts());
    assert!(
        e.to_string().starts_with(&format!(
            "{} line 5: an analog channel line has 13 fields",
            cfg.display()
        )),
        "{e}"
    );
    std::fs::write(&cfg, &text).unwrap();
    let dat = cfg.with_extension("dat");
    let d = std::fs::read_to_string(&dat).unwrap();
    let mut lines: Vec<&str> = d.lines().collect();
    lines[6] = "7,100000,10400,0";
    std::fs::write(&dat, lines.join("\n")).unwrap();
    let e = err(&cfg, &opts());
    assert!(
        e.to_string()
            .starts_with(&format!("{} line 7: 4 fields", dat.display())),
        "{e}"
    );
    let cfg = comtrade(&dir, 1999, "BINARY", a, &rows);
    let mut b = std::fs::read(cfg.with_extension("dat")).unwrap();
    b.truncate(b.len() - 3);
    std::fs::write(cfg.with_extension("dat"), b).unwrap();
    let e = err(&cfg, &opts());
    assert!(
        e.to_string().contains("rec.dat record 20: ") && e.to_string().contains("truncated"),
        "{e}"
    );
    // A missing .dat names the file.
    std::fs::remove_file(cfg.with_extension("dat")).unwrap();
    let e = err(&cfg, &opts());
    assert_eq!(e.kind(), "io");
    assert!(e.to_string().contains("rec.dat"), "{e}");
}

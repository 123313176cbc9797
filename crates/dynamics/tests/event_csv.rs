//! Event CSV: reading valid records (both voltage forms, angle unwrapping), the write/read
//! round trip and `%.17g` formatting, and every CSV error with its kind and message.

#![allow(clippy::needless_range_loop)] // parallel per-sample arrays read best with an index

use crate::event_support;

use std::f64::consts::{PI, TAU};
use std::fs;

use event_support::*;
use itaipu_dynamics::event::*;

// ---- reading valid data -------------------------------------------------------------------

#[test]
fn parses_itaipu_like_record_with_exact_header_and_unwraps() {
    let (t, mag, ang, p, q) = itaipu_like();
    // Sanity: the wrapped angle really crosses -180° (else this test proves nothing).
    let raw: Vec<f64> = ang.iter().map(|a| a.sin().atan2(a.cos())).collect();
    assert!(raw.windows(2).any(|w| (w[1] - w[0]).abs() > PI));
    let dir = TempDir::new("itaipu");
    let csv = dir.write("itaipu_pmu_60sps.csv", &rect_csv(&t, &mag, &ang, &p, &q));
    let rec = read_csv(&csv, 60.0).unwrap();
    assert_eq!(rec.len(), 280);
    assert_eq!(rec.time_s[0], 0.0);
    assert!((rec.end_s() - 4.65).abs() < 1e-12);
    assert!((rec.v_mag_pu[0] - 0.986).abs() < 1e-15);
    assert_eq!(rec.v_ang_rad[0], 0.0);
    assert!((rec.p_pu[0] - 0.6235).abs() < 1e-15);
    assert!((rec.q_pu[0] - 0.0225).abs() < 1e-15);
    assert!(rec.freq_hz.is_none() && rec.efd_pu.is_none() && rec.ifd_pu.is_none());
    for i in 0..rec.len() {
        assert!((rec.v_ang_rad[i] - ang[i]).abs() < 1e-12, "sample {i}");
    }
    // The drift is large (well beyond -180°).
    assert!(rec.v_ang_rad.last().unwrap().to_degrees() < -300.0);

    // As an event with the example windows; the operating point sees 60.01 Hz.
    let toml = dir.write(
        "itaipu.toml",
        &toml_text(
            "itaipu_pmu_60sps.csv",
            "[playback]\nstart_s = 0.0\nend_s = 4.65\n[init]\nstart_s = 0.0\nend_s = 0.95\n[fit]\nstart_s = 1.0\nend_s = 4.65\n",
        ),
    );
    let ev = Event::from_toml_file(&toml).unwrap();
    assert_eq!(ev.record.len(), 280);
    assert_eq!(ev.init, Window::new(0.0, 0.95));
    assert_eq!(ev.init_range(), 0..58);
    assert_eq!(ev.fit_range(), 60..280);
    let op = ev.operating_point();
    assert!((op.freq_hz - 60.01).abs() < 1e-9, "{}", op.freq_hz);
    assert!(op.v_ang_rad.abs() < 1e-9);
    assert!((op.v_mag_pu - 0.986).abs() < 1e-12);
    assert!((op.p_pu - 0.6235).abs() < 1e-12);
    assert_eq!(op.n_samples, 58);
}

#[test]
fn unwraps_synthetic_record_0p4_hz_off_nominal() {
    // 0.4 Hz above and below nominal for 10 s: the wrapped angle crosses ±180° four times.
    for df in [0.4, -0.4] {
        let n = 600;
        let t: Vec<f64> = (0..n).map(|i| i as f64 / 60.0).collect();
        let theta0 = 170f64.to_radians();
        let ang: Vec<f64> = t.iter().map(|t| theta0 + TAU * df * t).collect();
        let wraps = ang
            .iter()
            .map(|a| a.sin().atan2(a.cos()))
            .collect::<Vec<_>>()
            .windows(2)
            .filter(|w| (w[1] - w[0]).abs() > PI)
            .count();
        assert!(wraps >= 3, "test data must wrap several times, got {wraps}");
        let dir = TempDir::new("unwrap");
        let p = dir.write(
            "u.csv",
            &rect_csv(&t, &vec![1.02; n], &ang, &vec![0.5; n], &vec![0.1; n]),
        );
        let rec = read_csv(&p, 60.0).unwrap();
        for i in 0..n {
            assert!(
                (rec.v_ang_rad[i] - ang[i]).abs() < 1e-9,
                "df {df} sample {i}: {} vs {}",
                rec.v_ang_rad[i],
                ang[i]
            );
        }
        // Frequency recovered from the unwrapped slope over the whole record.
        let ev = Event::from_toml_file(
            &dir.write("u.toml", &toml_text("u.csv", "[init]\nend_s = 9.9\n")),
        )
        .unwrap();
        assert!((ev.operating_point().freq_hz - (60.0 + df)).abs() < 1e-9);
    }
}

#[test]
fn unwrap_angles_basic() {
    let raw = [3.0, -3.0, 3.1, -3.1, -2.0];
    let u = unwrap_angles(&raw);
    let expect = [3.0, -3.0 + TAU, 3.1, -3.1 + TAU, -2.0 + TAU];
    for (a, b) in u.iter().zip(expect) {
        assert!((a - b).abs() < 1e-12, "{u:?}");
    }
    // Continuous input is returned bit for bit.
    let smooth: Vec<f64> = (0..50).map(|i| -7.0 + 0.3 * i as f64).collect();
    assert_eq!(unwrap_angles(&smooth), smooth);
    assert!(unwrap_angles(&[]).is_empty());
}

#[test]
fn polar_form_equals_rectangular_form() {
    let n = 300;
    let t: Vec<f64> = (0..n).map(|i| 0.25 + i as f64 / 50.0).collect();
    let mut lcg = Lcg::new(7);
    let mag: Vec<f64> = (0..n).map(|_| 1.0 + 0.05 * lcg.uniform()).collect();
    let ang: Vec<f64> = t.iter().map(|t| 2.5 - TAU * 0.3 * t).collect();
    let p: Vec<f64> = (0..n).map(|_| 0.7 + 0.1 * lcg.uniform()).collect();
    let q: Vec<f64> = (0..n).map(|_| -0.1 + 0.1 * lcg.uniform()).collect();
    let dir = TempDir::new("polar");
    let rect = dir.write("rect.csv", &rect_csv(&t, &mag, &ang, &p, &q));

    // Polar file: other column order, padded headers and fields, angle wrapped to ±180°.
    let mut s = String::from(" q_pu , angle_deg,time_s,  v_pu ,p_pu\n");
    for i in 0..n {
        let wrapped = ang[i].sin().atan2(ang[i].cos()).to_degrees();
        s += &format!(
            "{} , {},{},  {} ,{}\n",
            g(q[i]),
            g(wrapped),
            g(t[i]),
            g(mag[i]),
            g(p[i])
        );
    }
    let polar = dir.write("polar.csv", &s);
    // Polar file with the angle already unwrapped in degrees (< -360°).
    let mut s2 = String::from("time_s,v_pu,angle_deg,p_pu,q_pu\n");
    for i in 0..n {
        s2 += &format!(
            "{},{},{},{},{}\n",
            g(t[i]),
            g(mag[i]),
            g(ang[i].to_degrees()),
            g(p[i]),
            g(q[i])
        );
    }
    let polar2 = dir.write("polar2.csv", &s2);

    let a = read_csv(&rect, 60.0).unwrap();
    for b in [
        read_csv(&polar, 60.0).unwrap(),
        read_csv(&polar2, 60.0).unwrap(),
    ] {
        assert_eq!(a.time_s, b.time_s);
        assert_eq!(a.p_pu, b.p_pu);
        assert_eq!(a.q_pu, b.q_pu);
        for i in 0..n {
            assert!((a.v_mag_pu[i] - b.v_mag_pu[i]).abs() < 1e-14, "mag {i}");
            assert!((a.v_ang_rad[i] - b.v_ang_rad[i]).abs() < 1e-12, "ang {i}");
            assert!((a.v_ang_rad[i] - ang[i]).abs() < 1e-12, "truth {i}");
        }
    }
    assert!(a.v_ang_rad.last().unwrap().to_degrees() < -360.0);
}

#[test]
fn optional_columns_blank_lines_and_bom_are_accepted() {
    let text = "\u{feff}time_s,v_re_pu,v_im_pu,p_pu,q_pu,ifd_pu,freq_hz,efd_pu\n\
                0,1,0,0.5,0.1,1.5,60.02,2.0\n\n\
                0.1,1,0,0.5,0.1,1.6,60.01,2.1\r\n\
                0.2,1,0,0.5,0.1,1.7,59.99,2.2\n";
    let dir = TempDir::new("optional");
    let p = dir.write("o.csv", text);
    let rec = read_csv(&p, 60.0).unwrap();
    assert_eq!(rec.len(), 3);
    assert_eq!(rec.freq_hz, Some(vec![60.02, 60.01, 59.99]));
    assert_eq!(rec.efd_pu, Some(vec![2.0, 2.1, 2.2]));
    assert_eq!(rec.ifd_pu, Some(vec![1.5, 1.6, 1.7]));
}

// ---- write / read round trip --------------------------------------------------------------

#[test]
fn time_stamps_on_a_reporting_grid_are_its_instants() {
    // 60 samples/s written with 11 decimals (the bundled Itaipu CSV) or to the microsecond (a
    // C37.118 export): the event's time stamps are the exact multiples of 1/60 s, whatever the
    // path; every path to the record then plays back the same instants.
    for digits in [11usize, 6] {
        let n = 120;
        let t: Vec<f64> = (0..n)
            .map(|k| format!("{:.*}", digits, k as f64 / 60.0).parse().unwrap())
            .collect();
        assert!(t.iter().enumerate().any(|(k, x)| *x != k as f64 / 60.0));
        let rec = Record {
            time_s: t,
            v_mag_pu: vec![1.0; n],
            v_ang_rad: vec![0.0; n],
            p_pu: vec![0.5; n],
            q_pu: vec![0.1; n],
            freq_hz: None,
            efd_pu: None,
            ifd_pu: None,
        };
        let ev = Event::from_record("grid", rec, 500.0, 60.0, None, None).unwrap();
        for (k, x) in ev.record.time_s.iter().enumerate() {
            assert_eq!(*x, k as f64 / 60.0, "{digits} digits, sample {k}");
        }
    }
}

#[test]
fn write_csv_round_trips() {
    let n = 100;
    let mut lcg = Lcg::new(99);
    let t: Vec<f64> = (0..n)
        // A jitter of tens of microseconds: an irregular time base, kept as it is (a jitter
        // within a microsecond is the rounding of written time stamps, snapped to the grid:
        // `time_stamps_on_a_reporting_grid_are_its_instants`).
        .map(|i| 10.0 + i as f64 * 0.02 + 5e-5 * lcg.uniform())
        .collect();
    let rec = Record {
        v_mag_pu: (0..n).map(|_| 1.0 + 0.1 * lcg.uniform()).collect(),
        v_ang_rad: t.iter().map(|t| 1.0 + TAU * 0.7 * (t - 10.0)).collect(),
        p_pu: (0..n).map(|_| 0.5 + 0.3 * lcg.uniform()).collect(),
        q_pu: (0..n).map(|_| 1e-9 * lcg.uniform()).collect(),
        freq_hz: Some((0..n).map(|_| 60.7 + 0.01 * lcg.uniform()).collect()),
        efd_pu: Some((0..n).map(|_| 2.0 + lcg.uniform()).collect()),
        // Plausible per-unit field currents (a median above 20 pu is refused as amperes).
        ifd_pu: Some((0..n).map(|_| 1.5 + lcg.uniform() * 1e-3).collect()),
        time_s: t,
    };
    let ev = Event::from_record("rt", rec.clone(), 500.0, 60.0, None, None).unwrap();
    assert_eq!(ev.record, rec, "from_record must not alter a valid record");
    let dir = TempDir::new("roundtrip");
    let path = dir.0.join("out.csv");
    ev.write_csv(&path).unwrap();
    let text = fs::read_to_string(&path).unwrap();
    assert_eq!(
        text.lines().next().unwrap(),
        "time_s,v_mag_pu,v_ang_rad,p_pu,q_pu,freq_hz,efd_pu,ifd_pu"
    );
    let back = read_csv(&path, 60.0).unwrap();
    // Every channel is reproduced bit for bit (17 significant digits; the voltage as the record
    // holds it): the event read back is the event written.
    assert_eq!(back, rec);
    assert_eq!(back.time_s, rec.time_s);
    assert_eq!(back.p_pu, rec.p_pu);
    assert_eq!(back.q_pu, rec.q_pu);
    assert_eq!(back.freq_hz, rec.freq_hz);
    assert_eq!(back.efd_pu, rec.efd_pu);
    assert_eq!(back.ifd_pu, rec.ifd_pu);
}

#[test]
fn format_g17_matches_c_printf() {
    // Expected strings are C's printf("%.17g").
    assert_eq!(format_g17(4.65), "4.6500000000000004");
    assert_eq!(format_g17(0.1), "0.10000000000000001");
    assert_eq!(format_g17(1e-7), "9.9999999999999995e-08");
    assert_eq!(format_g17(-623.5), "-623.5");
    assert_eq!(format_g17(1e20), "1e+20");
    assert_eq!(format_g17(1e16), "10000000000000000");
    assert_eq!(format_g17(0.0001), "0.0001");
    assert_eq!(format_g17(1e-5), "1.0000000000000001e-05");
    assert_eq!(format_g17(0.0), "0");
    let mut lcg = Lcg::new(3);
    for _ in 0..2000 {
        let x = lcg.uniform() * 10f64.powi((lcg.uniform() * 300.0) as i32);
        assert_eq!(format_g17(x).parse::<f64>().unwrap(), x);
    }
}

// ---- CSV errors ---------------------------------------------------------------------------

#[test]
fn error_missing_column() {
    let (_d, p, e) = csv_err(
        "miss",
        "time_s,v_re_pu,v_im_pu,p_pu\n0,1,0,0.5\n0.1,1,0,0.5\n0.2,1,0,0.5\n",
    );
    assert_err(&e, "missing_column", &[&ps(&p), "line 1", "'q_pu'"]);

    let (_d, p, e) = csv_err(
        "miss2",
        "time_s,v_re_pu,p_pu,q_pu\n0,1,0.5,0\n0.1,1,0.5,0\n0.2,1,0.5,0\n",
    );
    assert_err(
        &e,
        "missing_column",
        &[&ps(&p), "'v_im_pu'", "v_pu and angle_deg"],
    );

    let (_d, p, e) = csv_err("miss3", "time_s,p_pu,q_pu\n0,0.5,0\n0.1,0.5,0\n0.2,0.5,0\n");
    assert_err(&e, "missing_column", &[&ps(&p), "'v_re_pu'"]);

    let (_d, p, e) = csv_err(
        "miss4",
        "time_s,angle_deg,p_pu,q_pu\n0,1,0.5,0\n0.1,1,0.5,0\n0.2,1,0.5,0\n",
    );
    assert_err(&e, "missing_column", &[&ps(&p), "'v_pu'"]);
}

#[test]
fn error_both_voltage_forms() {
    let (_d, p, e) = csv_err(
        "both",
        "time_s,v_re_pu,v_im_pu,v_pu,angle_deg,p_pu,q_pu\n0,1,0,1,0,0.5,0\n",
    );
    assert_err(&e, "conflicting_columns", &[&ps(&p), "exactly one"]);
}

#[test]
fn error_unknown_column() {
    let (_d, p, e) = csv_err("unk", "time_s,v_re_pu,v_im_pu,p_mw,q_pu\n0,1,0,500,0\n");
    assert_err(
        &e,
        "unknown_column",
        &[
            &ps(&p),
            "line 1",
            "'p_mw'",
            "time_s, v_re_pu, v_im_pu, v_pu, angle_deg, v_mag_pu, v_ang_rad, p_pu, q_pu, freq_hz, efd_pu, ifd_pu",
        ],
    );
}

#[test]
fn error_duplicate_column() {
    let (_d, p, e) = csv_err(
        "dup",
        "time_s,v_re_pu,v_im_pu,p_pu,q_pu, p_pu\n0,1,0,0.5,0,0.5\n",
    );
    assert_err(&e, "duplicate_column", &[&ps(&p), "line 1", "'p_pu'"]);
}

#[test]
fn error_nan_field() {
    // Only one bad value, on line 17.
    let mut rows: Vec<String> = simple_csv(20).lines().map(String::from).collect();
    rows[16] = rows[16].replacen(",0.59999999999999998,", ",NaN,", 1);
    let (_d, p, e) = csv_err("nan17", &(rows.join("\n") + "\n"));
    assert_err(
        &e,
        "bad_number",
        &[
            &ps(&p),
            "line 17, column p_pu: 'NaN' is not a finite number",
        ],
    );

    let mut rows: Vec<String> = simple_csv(20).lines().map(String::from).collect();
    rows[3] = rows[3].replacen(",0.02", ",inf", 1);
    let (_d, p, e) = csv_err("inf", &(rows.join("\n") + "\n"));
    assert_err(&e, "bad_number", &[&ps(&p), "line 4, column q_pu", "'inf'"]);

    let mut rows: Vec<String> = simple_csv(20).lines().map(String::from).collect();
    rows[5] = rows[5].replacen("0.", "zero.", 1);
    let (_d, p, e) = csv_err("text", &(rows.join("\n") + "\n"));
    assert_err(
        &e,
        "bad_number",
        &[&ps(&p), "line 6, column time_s", "'zero."],
    );
}

#[test]
fn error_empty_field() {
    let text = "time_s,v_re_pu,v_im_pu,p_pu,q_pu\n0,1,0,0.5,0\n0.1,1, ,0.5,0\n0.2,1,0,0.5,0\n";
    let (_d, p, e) = csv_err("empty", text);
    assert_err(
        &e,
        "bad_number",
        &[&ps(&p), "line 3, column v_im_pu", "empty field"],
    );
}

#[test]
fn error_wrong_field_count() {
    let text = "time_s,v_re_pu,v_im_pu,p_pu,q_pu\n0,1,0,0.5,0\n0.1,1,0,0.5\n0.2,1,0,0.5,0\n";
    let (_d, p, e) = csv_err("count", text);
    assert_err(
        &e,
        "csv_structure",
        &[&ps(&p), "line 3", "expected 5 fields", "found 4"],
    );
    let text = "time_s,v_re_pu,v_im_pu,p_pu,q_pu\n0,1,0,0.5,0\n0.1,1,0,0.5,0\n0.2,1,0,0.5,0,7\n";
    let (_d, p, e) = csv_err("count2", text);
    assert_err(&e, "csv_structure", &[&ps(&p), "line 4", "found 6"]);
}

#[test]
fn error_empty_file() {
    let (_d, p, e) = csv_err("emptyfile", "");
    assert_err(&e, "csv_structure", &[&ps(&p), "empty"]);
}

#[test]
fn error_non_monotonic_time() {
    let text = "time_s,v_re_pu,v_im_pu,p_pu,q_pu\n0,1,0,0.5,0\n0.1,1,0,0.5,0\n0.2,1,0,0.5,0\n0.15,1,0,0.5,0\n";
    let (_d, p, e) = csv_err("mono", text);
    assert_err(
        &e,
        "non_monotonic_time",
        &[&ps(&p), "line 5", "0.15", "0.2", "line 4"],
    );
}

#[test]
fn error_duplicate_time() {
    let text = "time_s,v_re_pu,v_im_pu,p_pu,q_pu\n0,1,0,0.5,0\n0.1,1,0,0.5,0\n0.1,1,0,0.5,0\n0.2,1,0,0.5,0\n";
    let (_d, p, e) = csv_err("duptime", text);
    assert_err(
        &e,
        "non_monotonic_time",
        &[&ps(&p), "line 4", "time 0.1 s", "time 0.1 s (line 3)"],
    );
}

#[test]
fn error_too_few_samples() {
    // Whole file.
    let text = "time_s,v_re_pu,v_im_pu,p_pu,q_pu\n0,1,0,0.5,0\n0.1,1,0,0.5,0\n";
    let (_d, p, e) = csv_err("few", text);
    assert_err(
        &e,
        "too_few_samples",
        &[&ps(&p), "holds 2 sample(s)", "at least 3"],
    );
    // Header only.
    let (_d, p, e) = csv_err("few0", "time_s,v_re_pu,v_im_pu,p_pu,q_pu\n");
    assert_err(&e, "too_few_samples", &[&ps(&p), "holds 0"]);
    // Playback window holding 2 samples of a longer record.
    let dir = TempDir::new("fewpb");
    dir.write("d.csv", &simple_csv(60));
    let toml = dir.write(
        "e.toml",
        &toml_text("d.csv", "[playback]\nstart_s = 0.5\nend_s = 0.52\n"),
    );
    let e = Event::from_toml_file(&toml).unwrap_err();
    assert_err(
        &e,
        "too_few_samples",
        &[&ps(&toml), "playback window", "holds 2"],
    );
    // Init window holding 2 samples.
    let toml = dir.write(
        "i.toml",
        &toml_text("d.csv", "[init]\nstart_s = 0.1\nend_s = 0.12\n"),
    );
    let e = Event::from_toml_file(&toml).unwrap_err();
    assert_err(
        &e,
        "too_few_samples",
        &[&ps(&toml), "init window", "holds 2"],
    );
}

#[test]
fn error_kv_instead_of_pu() {
    let n = 30;
    let t: Vec<f64> = (0..n).map(|i| i as f64 / 60.0).collect();
    let text = rect_csv(
        &t,
        &vec![13.8; n],
        &vec![0.1; n],
        &vec![0.5; n],
        &vec![0.0; n],
    );
    let (_d, p, e) = csv_err("kv", &text);
    assert_err(&e, "units", &[&ps(&p), "v_re_pu/v_im_pu", "kV", "per unit"]);
    // Volts in polar form.
    let mut s = String::from("time_s,v_pu,angle_deg,p_pu,q_pu\n");
    for ti in &t {
        s += &format!("{ti},13800,5,0.5,0\n");
    }
    let (_d, p, e) = csv_err("volts", &s);
    assert_err(&e, "units", &[&ps(&p), "column v_pu", "volts"]);
    // Too small (e.g. a wrong base).
    let text = rect_csv(
        &t,
        &vec![0.0138; n],
        &vec![0.1; n],
        &vec![0.5; n],
        &vec![0.0; n],
    );
    let (_d, p, e) = csv_err("small", &text);
    assert_err(&e, "units", &[&ps(&p), "per unit"]);
    // A record with a deep but short dip is fine (median, not minimum).
    let mut mag = vec![1.0; n];
    mag[10] = 0.2;
    mag[11] = 0.2;
    let dir = TempDir::new("dip");
    let ok = dir.write(
        "dip.csv",
        &rect_csv(&t, &mag, &vec![0.1; n], &vec![0.5; n], &vec![0.0; n]),
    );
    assert!(read_csv(&ok, 60.0).is_ok());
}

#[test]
fn error_mw_instead_of_pu() {
    let n = 30;
    let t: Vec<f64> = (0..n).map(|i| i as f64 / 60.0).collect();
    let mut p = vec![0.6235; n];
    p[7] = 623.5;
    let text = rect_csv(&t, &vec![1.0; n], &vec![0.0; n], &p, &vec![0.02; n]);
    let (_d, path, e) = csv_err("mw", &text);
    assert_err(
        &e,
        "units",
        &[
            &ps(&path),
            "line 9, column p_pu",
            "MW",
            "per unit",
            "system_mva",
        ],
    );
    let mut q = vec![0.02; n];
    q[0] = -22.5;
    let text = rect_csv(&t, &vec![1.0; n], &vec![0.0; n], &vec![0.6; n], &q);
    let (_d, path, e) = csv_err("mvar", &text);
    assert_err(&e, "units", &[&ps(&path), "line 2, column q_pu", "Mvar"]);
    // 19.9 pu is accepted (limit is 20).
    let text = rect_csv(
        &t,
        &vec![1.0; n],
        &vec![0.0; n],
        &vec![19.9; n],
        &vec![0.0; n],
    );
    let dir = TempDir::new("mwok");
    assert!(read_csv(&dir.write("ok.csv", &text), 60.0).is_ok());
}

#[test]
fn error_bad_freq() {
    let mut s = String::from("time_s,v_re_pu,v_im_pu,p_pu,q_pu,freq_hz\n");
    for i in 0..10 {
        let f = if i < 4 { 60.0 } else { 0.01 }; // deviation instead of absolute
        s += &format!("{},1,0,0.5,0,{f}\n", i as f64 * 0.1);
    }
    let (_d, p, e) = csv_err("freq", &s);
    assert_err(
        &e,
        "units",
        &[&ps(&p), "line 6, column freq_hz", "deviation", "per unit"],
    );
    // Per unit frequency (1.0) with nominal 50 Hz.
    let mut s = String::from("time_s,v_re_pu,v_im_pu,p_pu,q_pu,freq_hz\n");
    for i in 0..10 {
        s += &format!("{},1,0,0.5,0,1.0\n", i as f64 * 0.1);
    }
    let dir = TempDir::new("freqpu");
    let p = dir.write("f.csv", &s);
    let e = read_csv(&p, 50.0).unwrap_err();
    assert_err(&e, "units", &[&ps(&p), "line 2", "outside 45..55 Hz"]);
    // Just inside the ±10 % band (54 … 66 Hz at 60 Hz nominal) is accepted.
    let mut s = String::from("time_s,v_re_pu,v_im_pu,p_pu,q_pu,freq_hz\n");
    for i in 0..10 {
        s += &format!("{},1,0,0.5,0,54.01\n", i as f64 * 0.1);
    }
    assert!(read_csv(&dir.write("ok.csv", &s), 60.0).is_ok());
}

#[test]
fn error_missing_csv_file() {
    let dir = TempDir::new("nocsv");
    let toml = dir.write("e.toml", &toml_text("missing.csv", ""));
    let e = Event::from_toml_file(&toml).unwrap_err();
    let csv = dir.0.join("missing.csv");
    assert_err(
        &e,
        "io",
        &[
            &ps(&csv),
            &format!("cannot open the CSV file named in {}", ps(&toml)),
        ],
    );
    assert_eq!(e.path(), csv.as_path());
    let e = read_csv(&csv, 60.0).unwrap_err();
    assert_err(&e, "io", &[&ps(&csv)]);
    // A missing TOML file.
    let missing = dir.0.join("nope.toml");
    let e = Event::from_toml_file(&missing).unwrap_err();
    assert_err(&e, "io", &[&ps(&missing), "event file"]);
}

//! Helpers shared by the event integration tests (`event_csv.rs`, `event_toml.rs`,
//! `event_window.rs`, `event_memory.rs`): temporary folders, seeded test data, CSV and TOML
//! text builders and error assertions.

// Each test file uses only some of the helpers.
#![allow(dead_code)]
#![allow(clippy::needless_range_loop)] // parallel per-sample arrays read best with an index

use std::f64::consts::TAU;
use std::fs;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use itaipu_dynamics::event::{format_g17, read_csv, EventError, Record};
use itaipu_dynamics::rng::SplitMix64;

/// A fresh, uniquely named directory under the system temp dir, removed on drop.
pub struct TempDir(pub PathBuf);

impl TempDir {
    pub fn new(tag: &str) -> TempDir {
        static COUNTER: AtomicUsize = AtomicUsize::new(0);
        let n = COUNTER.fetch_add(1, Ordering::SeqCst);
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.subsec_nanos())
            .unwrap_or(0);
        let dir = std::env::temp_dir().join(format!(
            "itaipu-event-test-{}-{tag}-{n}-{nanos}",
            std::process::id()
        ));
        fs::create_dir_all(&dir).unwrap();
        TempDir(dir)
    }

    pub fn write(&self, name: &str, text: &str) -> PathBuf {
        let p = self.0.join(name);
        if let Some(parent) = p.parent() {
            fs::create_dir_all(parent).unwrap();
        }
        fs::write(&p, text).unwrap();
        p
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = fs::remove_dir_all(&self.0);
    }
}

/// Seeded test data in [-1, 1): the workspace's one random source.
pub struct Lcg(SplitMix64);

impl Lcg {
    pub fn new(seed: u64) -> Self {
        Lcg(SplitMix64::new(seed))
    }
    pub fn uniform(&mut self) -> f64 {
        self.0.uniform_in(-1.0, 1.0)
    }
}

pub fn g(x: f64) -> String {
    format_g17(x)
}

/// CSV text in canonical re/im form from per-sample values.
pub fn rect_csv(t: &[f64], mag: &[f64], ang: &[f64], p: &[f64], q: &[f64]) -> String {
    let mut s = String::from("time_s,v_re_pu,v_im_pu,p_pu,q_pu\n");
    for i in 0..t.len() {
        s += &format!(
            "{},{},{},{},{}\n",
            g(t[i]),
            g(mag[i] * ang[i].cos()),
            g(mag[i] * ang[i].sin()),
            g(p[i]),
            g(q[i])
        );
    }
    s
}

/// A simple valid CSV with `n` samples at 60 samples/s.
pub fn simple_csv(n: usize) -> String {
    let t: Vec<f64> = (0..n).map(|i| i as f64 / 60.0).collect();
    let mag = vec![1.0; n];
    let ang: Vec<f64> = t.iter().map(|t| 0.1 + 0.05 * t).collect();
    rect_csv(&t, &mag, &ang, &vec![0.6; n], &vec![0.02; n])
}

pub fn toml_text(csv: &str, extra: &str) -> String {
    format!(
        "name = \"test-event\"\ndescription = \"unit test\"\ncsv = \"{csv}\"\nsystem_mva = 1000.0\nnominal_hz = 60.0\n{extra}"
    )
}

/// Asserts the kind and that the message contains every piece in `needles`.
pub fn assert_err(e: &EventError, kind: &str, needles: &[&str]) {
    let msg = e.to_string();
    assert_eq!(e.kind(), kind, "wrong kind; message: {msg}");
    for n in needles {
        assert!(msg.contains(n), "message lacks {n:?}: {msg}");
    }
}

pub fn csv_err(tag: &str, text: &str) -> (TempDir, PathBuf, EventError) {
    let dir = TempDir::new(tag);
    let p = dir.write("data.csv", text);
    let e = read_csv(&p, 60.0).expect_err("expected an error");
    (dir, p, e)
}

pub fn ps(p: &Path) -> String {
    p.display().to_string()
}

/// Per-sample columns: time, |V|, angle (rad), P, Q.
pub type Columns = (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>);

/// An Itaipu-like record, synthesised: 280 samples at 60/s (t = 0 … 4.65 s), |V| = 0.986,
/// P = 0.6235, Q = 0.0225 at 60.01 Hz before a dip at 1.02–1.10 s, then the frequency falls
/// linearly to 59.6 Hz, so the angle drifts by several hundred degrees and wraps at -180°.
pub fn itaipu_like() -> Columns {
    let n = 280;
    let dt = 1.0 / 60.0;
    let mut t = Vec::new();
    let mut mag = Vec::new();
    let mut ang = Vec::new();
    let mut p = Vec::new();
    let mut q = Vec::new();
    let mut theta: f64 = 0.0;
    for i in 0..n {
        let ti = i as f64 * dt;
        let f = if ti < 1.1 {
            60.01
        } else {
            (60.01 - 0.4 * (ti - 1.1) / 1.0).max(59.6)
        };
        if i > 0 {
            theta += TAU * (f - 60.0) * dt;
        }
        let dip = (1.02..=1.10).contains(&ti);
        t.push(ti);
        mag.push(if dip { 0.856 } else { 0.986 });
        ang.push(theta);
        p.push(if dip {
            0.37
        } else {
            0.6235 + 0.2 * (ti - 1.1).max(0.0).sin()
        });
        q.push(if dip { 0.39 } else { 0.0225 });
    }
    (t, mag, ang, p, q)
}

/// A valid in-memory record of `n` samples at 60/s: |V| = 1 pu, angle 0.2 rad, P = 0.5 pu,
/// Q = 0.1 pu, no optional channels.
pub fn mem_record(n: usize) -> Record {
    let t: Vec<f64> = (0..n).map(|i| i as f64 / 60.0).collect();
    Record {
        v_mag_pu: vec![1.0; n],
        v_ang_rad: vec![0.2; n],
        p_pu: vec![0.5; n],
        q_pu: vec![0.1; n],
        freq_hz: None,
        efd_pu: None,
        ifd_pu: None,
        time_s: t,
    }
}

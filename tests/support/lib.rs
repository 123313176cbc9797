//! Shared helpers for the end-to-end tests in `tests/`.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// A fresh folder under the system temp dir, removed on drop.
pub struct TempDir(PathBuf);

impl TempDir {
    pub fn new(tag: &str) -> Self {
        static N: AtomicUsize = AtomicUsize::new(0);
        let p = std::env::temp_dir().join(format!(
            "itaipu-e2e-{tag}-{}-{}",
            std::process::id(),
            N.fetch_add(1, Ordering::SeqCst)
        ));
        let _ = std::fs::remove_dir_all(&p);
        std::fs::create_dir_all(&p).unwrap();
        Self(p)
    }
    pub fn path(&self) -> &Path {
        &self.0
    }
    /// Writes `text` to `name` inside the folder and returns its path.
    pub fn write(&self, name: &str, text: &str) -> PathBuf {
        let p = self.0.join(name);
        if let Some(d) = p.parent() {
            std::fs::create_dir_all(d).unwrap();
        }
        std::fs::write(&p, text).unwrap();
        p
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// The repository root (where `data/` lives).
pub fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// `data/<rel>` in the repository.
pub fn data(rel: &str) -> PathBuf {
    repo_root().join("data").join(rel)
}

/// Runs the CLI in-process with `args` (without the program name) and returns its exit code.
pub fn cli(args: &[&str]) -> u8 {
    let mut all = vec!["itaipu-calib"];
    all.extend_from_slice(args);
    itaipu_calib_cli::run(all)
}

/// Runs `cmd --event EVENT --unit UNIT --out OUT` followed by `extra`: the usual shape of a call
/// (clap takes the options in any order).
pub fn cli_on(
    cmd: &str,
    event: impl AsRef<Path>,
    unit: impl AsRef<Path>,
    out: impl AsRef<Path>,
    extra: &[&str],
) -> u8 {
    let s = |p: &Path| p.to_str().expect("a UTF-8 path").to_string();
    let (e, u, o) = (s(event.as_ref()), s(unit.as_ref()), s(out.as_ref()));
    let mut args = vec![cmd, "--event", &e, "--unit", &u, "--out", &o];
    args.extend_from_slice(extra);
    cli(&args)
}

/// The names of the entries of `dir`, sorted.
pub fn file_names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// Swarm and L-BFGS settings of a quick fit stage: the command's path, not the optimum, is
/// under test.
pub const FIT_BUDGET: [&str; 6] = [
    "--particles",
    "6",
    "--pso-iterations",
    "3",
    "--lbfgs-iterations",
    "3",
];

/// Swarm and L-BFGS settings of a quick diagnosis (a second or so per cause).
pub const DIAGNOSE_BUDGET: [&str; 6] = [
    "--particles",
    "8",
    "--pso-iterations",
    "6",
    "--lbfgs-iterations",
    "5",
];

/// `synth --duration 10 --skew-ms SKEW_MS --out OUT`: a 10 s synthetic fault dip from the
/// generic unit with the power channels delayed; returns the exit code.
pub fn synth_skewed_dip(out: &Path, skew_ms: &str) -> u8 {
    let o = out.to_str().expect("a UTF-8 path");
    cli(&[
        "synth",
        "--duration",
        "10",
        "--skew-ms",
        skew_ms,
        "--out",
        o,
    ])
}

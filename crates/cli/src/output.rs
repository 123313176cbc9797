//! Output folders that are never half-written.
//!
//! Every command writes into a temporary folder beside its target (`.<name>.partial-<pid>`,
//! created before any computation, which is the writability check), and only when every file
//! is written goes `manifest.json` in (last: files with sizes and SHA-256, the command, the
//! version, the seed) and the folder is renamed into place, replacing an earlier folder
//! whole under `--force`. A failed or killed run leaves the target as it was. An interrupted
//! `fit` renames its folder into place with `partial.json` instead of the manifest (see
//! `fit_cmd`): a folder is complete if and only if it holds `manifest.json`.

use std::cell::RefCell;
use std::io::Read;
use std::path::{Path, PathBuf};

use serde::Serialize;
use sha2::{Digest, Sha256};

use crate::CliError;

/// Name of the manifest, written last.
pub const MANIFEST: &str = "manifest.json";
/// Name of the marker of a partial (interrupted) result.
pub const PARTIAL: &str = "partial.json";

thread_local! {
    /// The command line of the run on this thread (for the manifest).
    static COMMAND: RefCell<Vec<String>> = const { RefCell::new(Vec::new()) };
}

/// Records the command line of the current run (called by [`crate::run`]).
pub(crate) fn set_command(args: Vec<String>) {
    COMMAND.with(|c| *c.borrow_mut() = args);
}

/// The command line of the current run.
pub fn command() -> Vec<String> {
    COMMAND.with(|c| c.borrow().clone())
}

/// One file of a manifest.
#[derive(Debug, Clone, Serialize, serde::Deserialize, PartialEq)]
pub struct FileEntry {
    /// Path relative to the folder, `/`-separated.
    pub path: String,
    pub bytes: u64,
    pub sha256: String,
}

/// `manifest.json`.
#[derive(Debug, Clone, Serialize, serde::Deserialize, PartialEq)]
pub struct Manifest {
    pub tool: String,
    pub version: String,
    pub command: Vec<String>,
    pub seed: Option<u64>,
    /// Every file of the folder except the manifest itself, sorted by path.
    pub files: Vec<FileEntry>,
}

/// SHA-256 of a file, lower-case hex.
pub fn sha256_file(p: &Path) -> std::io::Result<String> {
    let mut f = std::fs::File::open(p)?;
    let mut h = Sha256::new();
    let mut buf = vec![0u8; 1 << 16];
    loop {
        let n = f.read(&mut buf)?;
        if n == 0 {
            break;
        }
        h.update(&buf[..n]);
    }
    Ok(h.finalize().iter().map(|b| format!("{b:02x}")).collect())
}

/// Every file under `dir` (relative, `/`-separated, sorted) with size and hash.
pub fn list_files(dir: &Path) -> std::io::Result<Vec<FileEntry>> {
    fn walk(root: &Path, d: &Path, out: &mut Vec<FileEntry>) -> std::io::Result<()> {
        for e in std::fs::read_dir(d)? {
            let e = e?;
            let p = e.path();
            if e.file_type()?.is_dir() {
                walk(root, &p, out)?;
            } else {
                let rel = p
                    .strip_prefix(root)
                    .unwrap_or(&p)
                    .components()
                    .map(|c| c.as_os_str().to_string_lossy().into_owned())
                    .collect::<Vec<_>>()
                    .join("/");
                out.push(FileEntry {
                    path: rel,
                    bytes: e.metadata()?.len(),
                    sha256: sha256_file(&p)?,
                });
            }
        }
        Ok(())
    }
    let mut v = vec![];
    walk(dir, dir, &mut v)?;
    v.sort_by(|a, b| a.path.cmp(&b.path));
    Ok(v)
}

/// Checks a folder against its manifest: every listed file present with its size and hash,
/// and no other file. `Err` names the first difference.
pub fn verify(dir: &Path) -> Result<Manifest, String> {
    let text = std::fs::read_to_string(dir.join(MANIFEST))
        .map_err(|e| format!("{}: {e}", dir.join(MANIFEST).display()))?;
    let m: Manifest = serde_json::from_str(&text).map_err(|e| format!("{MANIFEST}: {e}"))?;
    let mut now = list_files(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    now.retain(|f| f.path != MANIFEST);
    if now != m.files {
        let listed: Vec<&str> = m.files.iter().map(|f| f.path.as_str()).collect();
        let diff = now
            .iter()
            .find(|f| !m.files.contains(f))
            .map(|f| format!("{} differs from or is missing in the manifest", f.path))
            .or_else(|| {
                m.files
                    .iter()
                    .find(|f| !now.contains(f))
                    .map(|f| format!("{} is listed but missing or changed", f.path))
            })
            .unwrap_or_else(|| format!("files differ from {listed:?}"));
        return Err(diff);
    }
    Ok(m)
}

/// Temporary folders of the runs in this process, removed when SIGINT or SIGTERM ends a
/// command that does not stop by itself at a signal (all but `fit`, which polls a flag).
static LIVE: std::sync::Mutex<Vec<PathBuf>> = std::sync::Mutex::new(Vec::new());

/// Makes SIGINT and SIGTERM remove the temporary folders of this process and exit with
/// 128 + the signal (130, 143), so that an interrupted `simulate`, `diagnose` or `synth` leaves
/// nothing behind. Installed once, by the commands that do not poll an interrupt flag.
pub(crate) fn remove_partial_on_signal() {
    #[cfg(unix)]
    {
        static ONCE: std::sync::Once = std::sync::Once::new();
        ONCE.call_once(|| {
            use signal_hook::consts::{SIGINT, SIGTERM};
            let Ok(mut signals) = signal_hook::iterator::Signals::new([SIGINT, SIGTERM]) else {
                return;
            };
            std::thread::spawn(move || {
                if let Some(sig) = signals.forever().next() {
                    // The lock is kept to the exit: a folder being renamed into place is
                    // finished first, and none is started after.
                    let dirs = LIVE.lock().unwrap_or_else(|p| p.into_inner());
                    for d in dirs.iter() {
                        let _ = std::fs::remove_dir_all(d);
                    }
                    eprintln!("error: interrupted by signal {sig}; nothing written");
                    std::process::exit(128 + sig);
                }
            });
        });
    }
}

/// An output folder being written: a temporary folder beside the target, renamed into place
/// by [`Staging::commit`] (or [`Staging::keep_partial`]); removed if dropped otherwise.
pub struct Staging {
    target: PathBuf,
    tmp: PathBuf,
    done: bool,
}

impl Staging {
    /// Creates the temporary folder beside `target` (and `target`'s parent folders) and
    /// probes that a file can be written in it: exit 7 otherwise, before any computation.
    pub fn begin(target: &Path) -> Result<Self, CliError> {
        let name = target
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .ok_or_else(|| CliError::new(7, format!("{}: not a folder name", target.display())))?;
        let parent = match target.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        std::fs::create_dir_all(&parent)
            .map_err(|e| CliError::new(7, format!("cannot create {}: {e}", parent.display())))?;
        let tmp = parent.join(format!(".{name}.partial-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&tmp);
        std::fs::create_dir(&tmp).map_err(|e| {
            CliError::new(
                7,
                format!(
                    "{} is not writable: cannot create {}: {e}",
                    parent.display(),
                    tmp.display()
                ),
            )
        })?;
        if let Ok(mut v) = LIVE.lock() {
            v.push(tmp.clone());
        }
        let st = Self {
            target: target.to_path_buf(),
            tmp,
            done: false,
        };
        let probe = st.tmp.join(".probe");
        std::fs::write(&probe, b"itaipu-calib")
            .and_then(|_| std::fs::remove_file(&probe))
            .map_err(|e| CliError::new(7, format!("{} is not writable: {e}", st.tmp.display())))?;
        Ok(st)
    }

    /// The temporary folder to write into.
    pub fn path(&self) -> &Path {
        &self.tmp
    }

    /// Where the folder goes when complete.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Writes the manifest (last) and renames the folder into place.
    pub fn commit(mut self, seed: Option<u64>) -> Result<PathBuf, CliError> {
        let files = list_files(&self.tmp)
            .map_err(|e| CliError::new(7, format!("cannot list {}: {e}", self.tmp.display())))?;
        let m = Manifest {
            tool: "itaipu-calib".into(),
            version: env!("CARGO_PKG_VERSION").into(),
            command: command(),
            seed,
            files,
        };
        let text = serde_json::to_string_pretty(&m).map_err(|e| CliError::new(7, e.to_string()))?;
        write_synced(&self.tmp.join(MANIFEST), text.as_bytes())?;
        self.rename_into_place()?;
        self.done = true;
        Ok(self.target.clone())
    }

    /// Renames the folder into place as it is (a partial result: the caller has written its
    /// marker).
    pub fn keep_partial(mut self) -> Result<PathBuf, CliError> {
        self.rename_into_place()?;
        self.done = true;
        Ok(self.target.clone())
    }

    fn rename_into_place(&self) -> Result<(), CliError> {
        let err = |e: std::io::Error, what: &str| {
            CliError::new(7, format!("cannot {what} {}: {e}", self.target.display()))
        };
        // Held until the folder is in place and the old one gone: a signal arriving meanwhile
        // waits for it (see `remove_partial_on_signal`), so that it never removes the new
        // folder after the old one was moved aside, nor leaves the old one beside it.
        let mut live = LIVE.lock().unwrap_or_else(|p| p.into_inner());
        live.retain(|d| d != &self.tmp);
        if self.target.exists() {
            // Replace whole: move the old folder aside, the new one in, then delete the old.
            let old = self.tmp.with_file_name(format!(
                "{}.old",
                self.tmp.file_name().unwrap_or_default().to_string_lossy()
            ));
            let _ = std::fs::remove_dir_all(&old);
            std::fs::rename(&self.target, &old).map_err(|e| err(e, "move aside"))?;
            if let Err(e) = std::fs::rename(&self.tmp, &self.target) {
                let _ = std::fs::rename(&old, &self.target);
                return Err(err(e, "rename into"));
            }
            let _ = std::fs::remove_dir_all(&old);
        } else {
            std::fs::rename(&self.tmp, &self.target).map_err(|e| err(e, "rename into"))?;
        }
        Ok(())
    }
}

impl Drop for Staging {
    fn drop(&mut self) {
        if let Ok(mut v) = LIVE.lock() {
            v.retain(|d| d != &self.tmp);
        }
        if !self.done {
            let _ = std::fs::remove_dir_all(&self.tmp);
        }
    }
}

/// Writes a file and flushes it to disk (exit 7 on failure, naming the file).
pub fn write_synced(p: &Path, bytes: &[u8]) -> Result<(), CliError> {
    use std::io::Write;
    let res = std::fs::File::create(p).and_then(|mut f| {
        f.write_all(bytes)?;
        f.sync_all()
    });
    res.map_err(|e| CliError::new(7, format!("cannot write {}: {e}", p.display())))
}

/// Copies a folder recursively.
pub fn copy_dir(from: &Path, to: &Path) -> std::io::Result<()> {
    std::fs::create_dir_all(to)?;
    for e in std::fs::read_dir(from)? {
        let e = e?;
        let dst = to.join(e.file_name());
        if e.file_type()?.is_dir() {
            copy_dir(&e.path(), &dst)?;
        } else {
            std::fs::copy(e.path(), &dst)?;
        }
    }
    Ok(())
}

/// Refuses an explicit `--out` that is not a folder, a non-empty folder without `force`, and
/// with `force` a non-empty folder that is not an output of this tool (exit 7). Called before a
/// long run, so that it fails before the work, not after.
pub fn check_out(out: Option<&Path>, force: bool) -> Result<(), CliError> {
    let Some(d) = out else {
        return Ok(());
    };
    if d.exists() && !d.is_dir() {
        return Err(CliError::new(
            7,
            format!("{} exists and is not a folder", d.display()),
        ));
    }
    let nonempty = d.is_dir()
        && std::fs::read_dir(d)
            .map(|mut r| r.next().is_some())
            .unwrap_or(false);
    if nonempty && !force {
        return Err(CliError::new(
            7,
            format!(
                "{} exists and is not empty; refusing to overwrite (use --force, or another --out)",
                d.display()
            ),
        ));
    }
    if nonempty && !looks_like_output(d) {
        return Err(CliError::new(
            7,
            format!(
                "{} is not an output folder of itaipu-calib (none of {}); --force replaces a folder whole, so it only replaces one of ours: give another --out, or empty the folder first",
                d.display(),
                OUTPUT_MARKERS.join(", ")
            ),
        ));
    }
    if nonempty {
        let foreign = foreign_files(d);
        if !foreign.is_empty() {
            let shown: Vec<&str> = foreign.iter().take(5).map(String::as_str).collect();
            return Err(CliError::new(
                7,
                format!(
                    "{} holds {} file(s) that its manifest.json does not list ({}{}): --force replaces the folder whole and would delete them; move them out first, or give another --out",
                    d.display(),
                    foreign.len(),
                    shown.join(", "),
                    if foreign.len() > 5 { ", ..." } else { "" }
                ),
            ));
        }
    }
    Ok(())
}

/// Files of a complete output folder that its manifest does not list (put there after the
/// run); empty when there is no readable manifest.
fn foreign_files(dir: &Path) -> Vec<String> {
    let Ok(text) = std::fs::read_to_string(dir.join(MANIFEST)) else {
        return vec![];
    };
    let Ok(m) = serde_json::from_str::<Manifest>(&text) else {
        return vec![];
    };
    let Ok(now) = list_files(dir) else {
        return vec![];
    };
    now.into_iter()
        .map(|f| f.path)
        .filter(|p| p != MANIFEST && !m.files.iter().any(|f| &f.path == p))
        .collect()
}

/// Files at the top of a folder that mark it as an output of this tool (the manifest, the
/// partial marker, and the main result of each command, as written before manifests existed).
pub const OUTPUT_MARKERS: &[&str] = &[
    MANIFEST,
    PARTIAL,
    "report.json",
    "traces.csv",
    "diagnosis.json",
    "truth.json",
];

/// Whether `--force` may replace `dir` whole: it holds one of [`OUTPUT_MARKERS`]. A folder of
/// the user's own (say the one holding the event files) is never deleted by a mistyped `--out`.
pub fn looks_like_output(dir: &Path) -> bool {
    OUTPUT_MARKERS.iter().any(|m| dir.join(m).is_file())
}

/// Chooses the output folder and starts writing it ([`Staging`]: a temporary folder
/// beside it, renamed into place when complete). With an explicit `--out`, an existing
/// non-empty folder is refused unless `force` ([`check_out`]), and then replaced whole; by
/// default `out/<name>` or the first free `out/<name>-N`. Call it before the computation: it
/// is the writability check.
pub fn prepare_out(out: Option<&Path>, name: &str, force: bool) -> Result<Staging, CliError> {
    check_out(out, force)?;
    let dir = match out {
        Some(d) => d.to_path_buf(),
        None => {
            let base = PathBuf::from("out").join(name);
            let mut d = base.clone();
            let mut k = 2;
            while d.exists() {
                d = PathBuf::from(format!("{}-{k}", base.display()));
                k += 1;
            }
            d
        }
    };
    Staging::begin(&dir)
}

//! Output folders that are never half-written, for every front end (the command line, Python,
//! a fleet's jobs).
//!
//! Every run writes into a temporary folder beside its target (`.<name>.partial-<pid>`,
//! created before any computation, which is the writability check), and only when every file
//! is written goes `manifest.json` in (last: files with sizes and SHA-256, the command, the
//! version, the seed) and the folder is renamed into place, replacing an earlier folder
//! whole when the caller allows it. A failed or killed run leaves the target as it was. An
//! interrupted fit renames its folder into place with `partial.json` instead of the manifest: a
//! folder is complete if and only if it holds `manifest.json`.
//!
//! **Work left by a killed run.** A temporary folder whose process no longer runs (killed
//! outright, SIGKILL or a power cut) is looked at by the next run that writes beside it
//! ([`Staging::begin`], [`stale`]): one that holds finished work ([`Stale::holds_work`]: a
//! `partial.json` listing a finished stage, or a complete folder whose rename was cut short) is
//! never removed by another command: it is kept and named, `fit --resume` goes on from it and
//! removes it once its stages are in the finished folder, and only `fit --discard-interrupted`
//! deletes it ([`discard_stale`]). One without finished work is removed and named. A target
//! moved aside for its replacement (`.<name>.partial-<pid>.old`) when the process died before
//! the replacement went in is put back (or the complete replacement put in).

use std::io::Read;
use std::path::{Path, PathBuf};

use serde::Serialize;
use sha2::{Digest, Sha256};

use crate::Error;

/// An output error (class [`crate::error::ErrorClass::Output`]).
fn out_err(msg: String) -> Error {
    Error::Output(msg)
}

/// Name of the manifest, written last.
pub const MANIFEST: &str = "manifest.json";
/// Name of the marker of a partial (interrupted) result.
pub const PARTIAL: &str = "partial.json";

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

/// Temporary folders of the runs in this process, for a front end's signal handler
/// ([`remove_live`]).
static LIVE: std::sync::Mutex<Vec<PathBuf>> = std::sync::Mutex::new(Vec::new());

/// Removes every temporary folder of this process and returns with the registry locked, so that
/// no folder is renamed into place after it (call it from a signal handler right before the
/// process exits: the guard is held to the exit). A folder being renamed into place is
/// finished first.
pub fn remove_live() -> std::sync::MutexGuard<'static, Vec<PathBuf>> {
    let dirs = LIVE.lock().unwrap_or_else(|p| p.into_inner());
    for d in dirs.iter() {
        let _ = std::fs::remove_dir_all(d);
    }
    dirs
}

/// Temporary folders that are resumable as they stand (`partial.json` kept up to date in
/// them: [`Staging::mark_resumable`]), with their targets.
static RESUMABLE: std::sync::Mutex<Vec<(PathBuf, PathBuf)>> = std::sync::Mutex::new(Vec::new());

/// For a signal handler right before the process exits: renames every resumable temporary
/// folder of this process into place as it stands (replacing its target) and removes the
/// others. Returns the registry locked (hold it to the exit: nothing is renamed or removed
/// after) and the folders kept.
pub fn finish_on_signal() -> (std::sync::MutexGuard<'static, Vec<PathBuf>>, Vec<PathBuf>) {
    let dirs = LIVE.lock().unwrap_or_else(|p| p.into_inner());
    let keep = RESUMABLE.lock().unwrap_or_else(|p| p.into_inner()).clone();
    let mut kept = vec![];
    for d in dirs.iter() {
        match keep.iter().find(|(tmp, _)| tmp == d) {
            Some((tmp, target)) => {
                if target.exists() {
                    let _ = std::fs::remove_dir_all(target);
                }
                if std::fs::rename(tmp, target).is_ok() {
                    kept.push(target.clone());
                }
            }
            None => {
                let _ = std::fs::remove_dir_all(d);
            }
        }
    }
    (dirs, kept)
}

/// Whether process `pid` is running (on Linux, from `/proc`; elsewhere it is assumed to run, so
/// that nothing of a live process is ever removed).
fn process_alive(pid: u32) -> bool {
    let proc_root = Path::new("/proc");
    if !proc_root.join("self").exists() {
        return true;
    }
    pid == std::process::id() || proc_root.join(pid.to_string()).exists()
}

/// The finished stages `partial.json` in `dir` lists (an interrupted fit's), in order; empty
/// without a readable `partial.json`.
pub fn finished_stages(dir: &Path) -> Vec<String> {
    std::fs::read_to_string(dir.join(PARTIAL))
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .and_then(|v| {
            v["finished_stages"].as_array().map(|a| {
                a.iter()
                    .filter_map(|x| x.as_str().map(String::from))
                    .collect()
            })
        })
        .unwrap_or_default()
}

/// A temporary folder beside a target left by a process that no longer runs ([`stale`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Stale {
    pub path: PathBuf,
    /// The finished stages its `partial.json` lists (an interrupted fit's work).
    pub finished: Vec<String>,
    /// It holds a `manifest.json` that verifies and no `partial.json`: a complete result whose
    /// rename into place was cut short.
    pub complete: bool,
    /// A target moved aside for its replacement (`.old`).
    pub moved_aside: bool,
}

impl Stale {
    /// Whether it holds work another command must not delete: a finished stage, or a complete
    /// result.
    pub fn holds_work(&self) -> bool {
        !self.finished.is_empty() || self.complete
    }

    /// How the front ends name it: the folder and what it holds.
    pub fn describe(&self) -> String {
        if self.complete {
            format!(
                "{} (a complete result of a run killed before it renamed the folder into place)",
                self.path.display()
            )
        } else {
            format!(
                "{} (finished stage(s) {} of a fit killed outright)",
                self.path.display(),
                self.finished.join(", ")
            )
        }
    }
}

/// The temporary folders beside `target` (`.<name>.partial-<pid>` and their `.old`) left by
/// processes that no longer run (an interrupted or killed run of an earlier process), sorted by
/// path, with what each holds.
pub fn stale(target: &Path) -> Vec<Stale> {
    let (Some(name), Some(parent)) = (target.file_name(), target.parent()) else {
        return vec![];
    };
    let parent = if parent.as_os_str().is_empty() {
        Path::new(".")
    } else {
        parent
    };
    let prefix = format!(".{}.partial-", name.to_string_lossy());
    let Ok(entries) = std::fs::read_dir(parent) else {
        return vec![];
    };
    let mut out: Vec<Stale> = entries
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let n = e.file_name().to_string_lossy().into_owned();
            let pid = n.strip_prefix(&prefix)?;
            let (pid, moved_aside) = match pid.strip_suffix(".old") {
                Some(p) => (p, true),
                None => (pid, false),
            };
            let pid: u32 = pid.parse().ok()?;
            if process_alive(pid) || !e.path().is_dir() {
                return None;
            }
            let path = e.path();
            Some(Stale {
                finished: finished_stages(&path),
                complete: !path.join(PARTIAL).exists() && verify(&path).is_ok(),
                moved_aside,
                path,
            })
        })
        .collect();
    out.sort_by(|a, b| a.path.cmp(&b.path));
    out
}

/// The paths of [`stale`].
pub fn stale_partials(target: &Path) -> Vec<PathBuf> {
    stale(target).into_iter().map(|s| s.path).collect()
}

/// Deletes every temporary folder of ended processes beside `target`, finished work and all
/// (`fit --discard-interrupted`: the user's explicit consent). Returns what it deleted.
pub fn discard_stale(target: &Path) -> Vec<Stale> {
    stale(target)
        .into_iter()
        .filter(|s| std::fs::remove_dir_all(&s.path).is_ok())
        .collect()
}

/// Puts back what a process that died inside [`Staging::commit`]'s rename left: `target`
/// missing, its earlier folder moved aside (`.old`) and the replacement beside it. The complete
/// replacement goes in (and the old folder, unless it holds finished work, goes); an incomplete
/// one stays where it is and the old folder goes back. Returns what was done, one line each.
fn recover_rename(target: &Path) -> Vec<String> {
    let mut done = vec![];
    for s in stale(target).into_iter().filter(|s| s.moved_aside) {
        if target.exists() {
            continue;
        }
        let replacement = s.path.with_file_name(
            s.path
                .file_name()
                .unwrap_or_default()
                .to_string_lossy()
                .trim_end_matches(".old"),
        );
        let complete = !replacement.join(PARTIAL).exists() && verify(&replacement).is_ok();
        if complete && std::fs::rename(&replacement, target).is_ok() {
            done.push(format!(
                "{}: the complete result of a run killed while renaming it into place, put in",
                target.display()
            ));
            if s.finished.is_empty() && std::fs::remove_dir_all(&s.path).is_ok() {
                done.push(format!(
                    "{}: the folder it replaced, removed",
                    s.path.display()
                ));
            }
        } else if std::fs::rename(&s.path, target).is_ok() {
            done.push(format!(
                "{}: put back from {} (a run was killed while replacing it)",
                target.display(),
                s.path.display()
            ));
        }
    }
    done
}

/// An output folder being written: a temporary folder beside the target, renamed into place
/// by [`Staging::commit`] (or [`Staging::keep_partial`]); removed if dropped otherwise.
pub struct Staging {
    target: PathBuf,
    tmp: PathBuf,
    done: bool,
    /// Temporary folders of ended processes removed by [`Staging::begin`] (for the front end to
    /// say so): they held no finished work.
    pub removed_stale: Vec<PathBuf>,
    /// Temporary folders of ended processes that hold finished work ([`Stale::holds_work`]),
    /// kept (for the front end to name them).
    pub kept_stale: Vec<Stale>,
    /// What [`Staging::begin`] put back of a rename a killed process left half done.
    pub recovered: Vec<String>,
}

impl Staging {
    /// Creates the temporary folder beside `target` (and `target`'s parent folders) and
    /// probes that a file can be written in it: an output error otherwise, before any
    /// computation. First a rename a killed process left half done is completed or undone,
    /// then the temporary folders beside it left by ended processes are removed when they hold
    /// no finished work ([`Staging::removed_stale`]) and kept otherwise
    /// ([`Staging::kept_stale`]; see the module documentation).
    pub fn begin(target: &Path) -> Result<Self, Error> {
        let name = target
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .ok_or_else(|| out_err(format!("{}: not a folder name", target.display())))?;
        let parent = match target.parent() {
            Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
            _ => PathBuf::from("."),
        };
        std::fs::create_dir_all(&parent)
            .map_err(|e| out_err(format!("cannot create {}: {e}", parent.display())))?;
        let recovered = recover_rename(target);
        let (kept_stale, empty): (Vec<Stale>, Vec<Stale>) =
            stale(target).into_iter().partition(Stale::holds_work);
        let removed_stale: Vec<PathBuf> = empty
            .into_iter()
            .map(|s| s.path)
            .filter(|d| std::fs::remove_dir_all(d).is_ok())
            .collect();
        let tmp = parent.join(format!(".{name}.partial-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&tmp);
        std::fs::create_dir(&tmp).map_err(|e| {
            out_err(format!(
                "{} is not writable: cannot create {}: {e}",
                parent.display(),
                tmp.display()
            ))
        })?;
        if let Ok(mut v) = LIVE.lock() {
            v.push(tmp.clone());
        }
        let st = Self {
            target: target.to_path_buf(),
            tmp,
            done: false,
            removed_stale,
            kept_stale,
            recovered,
        };
        let probe = st.tmp.join(".probe");
        std::fs::write(&probe, b"itaipu-calib")
            .and_then(|_| std::fs::remove_file(&probe))
            .map_err(|e| out_err(format!("{} is not writable: {e}", st.tmp.display())))?;
        Ok(st)
    }

    /// Marks the folder resumable as it stands: the caller keeps a `partial.json` in it up to
    /// date, so that a signal handler may rename it into place ([`finish_on_signal`]).
    pub fn mark_resumable(&self) {
        if let Ok(mut v) = RESUMABLE.lock() {
            v.push((self.tmp.clone(), self.target.clone()));
        }
    }

    /// The temporary folder to write into.
    pub fn path(&self) -> &Path {
        &self.tmp
    }

    /// Where the folder goes when complete.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Writes the manifest (last: `command` is what made the folder, the command line or the
    /// Python call) and renames the folder into place. A `partial.json` kept up to date in the
    /// folder (a fit's) is not listed and is removed only after the manifest is written, so
    /// that a process killed at any moment leaves a folder that is resumable or complete.
    pub fn commit(mut self, seed: Option<u64>, command: Vec<String>) -> Result<PathBuf, Error> {
        let mut files = list_files(&self.tmp)
            .map_err(|e| out_err(format!("cannot list {}: {e}", self.tmp.display())))?;
        files.retain(|f| f.path != PARTIAL);
        let m = Manifest {
            tool: "itaipu-calib".into(),
            version: env!("CARGO_PKG_VERSION").into(),
            command,
            seed,
            files,
        };
        let text = serde_json::to_string_pretty(&m).map_err(|e| out_err(e.to_string()))?;
        write_synced(&self.tmp.join(MANIFEST), text.as_bytes())?;
        let partial = self.tmp.join(PARTIAL);
        if partial.exists() {
            std::fs::remove_file(&partial)
                .map_err(|e| out_err(format!("cannot remove {}: {e}", partial.display())))?;
        }
        self.rename_into_place()?;
        self.done = true;
        Ok(self.target.clone())
    }

    /// Renames the folder into place as it is (a partial result: the caller has written its
    /// marker).
    pub fn keep_partial(mut self) -> Result<PathBuf, Error> {
        self.rename_into_place()?;
        self.done = true;
        Ok(self.target.clone())
    }

    fn rename_into_place(&self) -> Result<(), Error> {
        let err = |e: std::io::Error, what: &str| {
            out_err(format!("cannot {what} {}: {e}", self.target.display()))
        };
        // Held until the folder is in place and the old one gone: a signal arriving meanwhile
        // waits for it (see `remove_partial_on_signal`), so that it never removes the new
        // folder after the old one was moved aside, nor leaves the old one beside it.
        let mut live = LIVE.lock().unwrap_or_else(|p| p.into_inner());
        live.retain(|d| d != &self.tmp);
        if let Ok(mut v) = RESUMABLE.lock() {
            v.retain(|(d, _)| d != &self.tmp);
        }
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
        if let Ok(mut v) = RESUMABLE.lock() {
            v.retain(|(d, _)| d != &self.tmp);
        }
        if !self.done {
            let _ = std::fs::remove_dir_all(&self.tmp);
        }
    }
}

/// Writes a file whole or not at all: into a temporary file beside it, flushed, then renamed
/// over it (a process killed meanwhile leaves the earlier file as it was). For the files a
/// resume reads (`partial.json`).
pub fn write_atomic(p: &Path, bytes: &[u8]) -> Result<(), Error> {
    let tmp = p.with_file_name(format!(
        ".{}.writing",
        p.file_name().unwrap_or_default().to_string_lossy()
    ));
    write_synced(&tmp, bytes)?;
    std::fs::rename(&tmp, p).map_err(|e| out_err(format!("cannot write {}: {e}", p.display())))
}

/// Writes a file and flushes it to disk (an output error naming the file on failure).
pub fn write_synced(p: &Path, bytes: &[u8]) -> Result<(), Error> {
    use std::io::Write;
    let res = std::fs::File::create(p).and_then(|mut f| {
        f.write_all(bytes)?;
        f.sync_all()
    });
    res.map_err(|e| out_err(format!("cannot write {}: {e}", p.display())))
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

/// Refuses an explicit output folder that is not a folder, a non-empty folder without `force`,
/// and with `force` a non-empty folder that is not an output of this tool (an output error).
/// Called before a long run, so that it fails before the work, not after.
pub fn check_out(out: Option<&Path>, force: bool) -> Result<(), Error> {
    let Some(d) = out else {
        return Ok(());
    };
    if d.exists() && !d.is_dir() {
        return Err(out_err(format!(
            "{} exists and is not a folder",
            d.display()
        )));
    }
    let nonempty = d.is_dir()
        && std::fs::read_dir(d)
            .map(|mut r| r.next().is_some())
            .unwrap_or(false);
    if nonempty && !force {
        return Err(out_err(format!(
            "{} exists and is not empty; refusing to overwrite (use --force, or another --out)",
            d.display()
        )));
    }
    if nonempty && !looks_like_output(d) {
        return Err(out_err(format!(
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
            return Err(out_err(format!(
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
pub fn prepare_out(out: Option<&Path>, name: &str, force: bool) -> Result<Staging, Error> {
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

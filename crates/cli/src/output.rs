//! Output folders: the library's ([`itaipu_calib::output`]: staging beside the target, the
//! manifest written last, stale temporary folders of ended processes removed), plus what only
//! the command line has: the command line recorded for the manifest, and the signal handler of
//! the commands that do not stop by themselves at a signal.

use std::cell::RefCell;

pub use itaipu_calib::output::{
    check_out, copy_dir, list_files, looks_like_output, sha256_file, stale, stale_partials, verify,
    FileEntry, Manifest, Staging, Stale, MANIFEST, OUTPUT_MARKERS, PARTIAL,
};

use crate::CliError;

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

/// Writes a file and flushes it to disk (exit 7 on failure, naming the file).
pub fn write_synced(p: &std::path::Path, bytes: &[u8]) -> Result<(), CliError> {
    Ok(itaipu_calib::output::write_synced(p, bytes)?)
}

/// [`itaipu_calib::output::prepare_out`], saying what it did with the temporary folders of
/// ended runs: removed (no finished work in them), kept (finished work: named, with how to go
/// on), or a half-done rename put right.
pub fn prepare_out(
    out: Option<&std::path::Path>,
    name: &str,
    force: bool,
) -> Result<Staging, CliError> {
    let st = itaipu_calib::output::prepare_out(out, name, force)?;
    for r in &st.recovered {
        eprintln!("note: {r}");
    }
    for d in &st.removed_stale {
        eprintln!(
            "note: removed {}, the temporary folder of an earlier run whose process has ended (killed before it could finish; it held no finished work)",
            d.display()
        );
    }
    for k in &st.kept_stale {
        eprintln!("note: kept {}", stale_advice(k, st.target()));
    }
    Ok(st)
}

/// What to do with a kept temporary folder of an ended run (`s`, beside `target`).
pub fn stale_advice(s: &Stale, target: &std::path::Path) -> String {
    format!(
        "{}: `itaipu-calib fit --resume --out {}` (with the interrupted fit's other options) goes on from it; `fit --discard-interrupted --out {}` deletes it",
        s.describe(),
        target.display(),
        target.display()
    )
}

/// Writes the manifest with this run's command line and renames the folder into place.
pub fn commit(st: Staging, seed: Option<u64>) -> Result<std::path::PathBuf, CliError> {
    Ok(st.commit(seed, command())?)
}

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
                    // The registry stays locked to the exit: a folder being renamed into place
                    // is finished first, and none is started after.
                    let _held = itaipu_calib::output::remove_live();
                    eprintln!("error: interrupted by signal {sig}; nothing written");
                    std::process::exit(128 + sig);
                }
            });
        });
    }
}

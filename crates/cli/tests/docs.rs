//! Every code example of the README and of `docs/` (the lab notebook aside: its commands need
//! the practice sets and hours) is run or checked here, so that the documentation cannot drift
//! from the tool:
//!
//! * shell blocks: every `itaipu-calib` command (also as `cargo run -p itaipu-calib-cli --`) is
//!   parsed by the command line's own definition and its input files must exist; the quick
//!   commands (`simulate`, `import`, `synth`, `dyr`, `models`, `diagram`) run, in order, in a
//!   scratch folder beside the repository's `data/`, and must end with the exit code their line
//!   states (`# ... exit N`; 0 otherwise). With the slow checks (`ITAIPU_SLOW_TESTS=1` or the
//!   `slow-tests` feature) every command runs, `fit` and `diagnose` too. Other commands are checked
//!   for what they name: a `cargo` package or example, a script;
//! * TOML blocks parse, and read as what their marker says (`<!-- check: calibration -->`, `event
//!   DIR` (its CSV from DIR), `unit`, `file PATH`: the block is that file, byte for byte);
//! * Rust blocks are files compiled with a crate (`<!-- check: file PATH -->`, PATH included by a
//!   `#[path]` module: `crates/calib/src/docs_examples.rs`);
//! * relative links point at files that exist, and `#anchors` at headings that exist.
//!
//! Python blocks are run by `tests/python/test_docs.py` against the installed wheel.
#![cfg(unix)]

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .canonicalize()
        .expect("the repository's root")
}

fn slow() -> bool {
    cfg!(feature = "slow-tests") || std::env::var_os("ITAIPU_SLOW_TESTS").is_some()
}

/// The documentation's files: the README and `docs/*.md` (not the lab notebook).
fn doc_files() -> Vec<PathBuf> {
    let root = repo();
    let mut files = vec![root.join("README.md")];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root.join("docs"))
        .expect("docs/")
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "md"))
        .collect();
    docs.sort();
    files.extend(docs);
    files
}

/// A fenced code block.
#[derive(Debug, Clone)]
struct Block {
    file: PathBuf,
    /// 1-based line of the opening fence.
    line: usize,
    lang: String,
    /// What the `<!-- check: ... -->` line just before the fence says.
    check: Option<String>,
    text: String,
}

impl Block {
    fn at(&self) -> String {
        format!("{}:{}", self.file.display(), self.line)
    }
}

fn blocks(file: &Path) -> Vec<Block> {
    let text = std::fs::read_to_string(file).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let mut out = vec![];
    let mut k = 0;
    while k < lines.len() {
        let Some(info) = lines[k].strip_prefix("```") else {
            k += 1;
            continue;
        };
        let lang = info.split_whitespace().next().unwrap_or("").to_string();
        let check = lines[..k]
            .iter()
            .rev()
            .find(|l| !l.trim().is_empty())
            .and_then(|l| l.trim().strip_prefix("<!-- check:"))
            .and_then(|l| l.strip_suffix("-->"))
            .map(|l| l.trim().to_string());
        let start = k;
        k += 1;
        let mut body = String::new();
        while k < lines.len() && !lines[k].starts_with("```") {
            body.push_str(lines[k]);
            body.push('\n');
            k += 1;
        }
        out.push(Block {
            file: file.to_path_buf(),
            line: start + 1,
            lang,
            check,
            text: body,
        });
        k += 1;
    }
    out
}

fn all_blocks() -> Vec<Block> {
    doc_files().iter().flat_map(|f| blocks(f)).collect()
}

#[test]
fn every_code_block_names_a_language_the_tests_know() {
    let known = ["sh", "toml", "python", "rust", "csv", "diff"];
    for b in all_blocks() {
        assert!(
            known.contains(&b.lang.as_str()),
            "{}: a code block in '{}' (known: {known:?}): every example is run or checked",
            b.at(),
            b.lang
        );
    }
}

/// A `diff` block shows a change to the file named on its first line (` path`): the file holds
/// the change's result, its context and added lines in the diff's order (removed lines are not
/// looked for: the file may have moved on past them).
#[test]
fn diff_blocks_show_changes_the_named_files_hold() {
    let root = repo();
    let mut checked = 0;
    for b in all_blocks().into_iter().filter(|b| b.lang == "diff") {
        let mut lines = b.text.lines();
        let path = lines.next().unwrap_or("").trim();
        let file = std::fs::read_to_string(root.join(path))
            .unwrap_or_else(|e| panic!("{}: the diff names {path}: {e}", b.at()));
        let file_lines: Vec<&str> = file.lines().map(str::trim_end).collect();
        let mut at = 0;
        for l in lines {
            if l.starts_with('-') {
                continue;
            }
            let want = l.get(1..).unwrap_or("").trim_end();
            let Some(k) = file_lines[at..].iter().position(|f| *f == want) else {
                panic!(
                    "{}: {path} does not hold '{want}' where the diff shows it",
                    b.at()
                );
            };
            at += k + 1;
        }
        checked += 1;
    }
    assert!(checked >= 1, "no diff block checked");
}

// -------------------------------------------------------------------------------------------
// TOML
// -------------------------------------------------------------------------------------------

#[test]
fn toml_blocks_parse_and_read_as_marked() {
    let root = repo();
    let mut checked = 0;
    for b in all_blocks().into_iter().filter(|b| b.lang == "toml") {
        let table: toml::Table = match toml::from_str(&b.text) {
            Ok(t) => t,
            Err(e) => panic!("{}: not TOML: {e}", b.at()),
        };
        let check = b.check.clone().unwrap_or_default();
        let mut words = check.split_whitespace();
        let dir = scratch(&format!("toml-{}", b.line));
        match words.next() {
            None | Some("toml") => {}
            Some("calibration") => {
                if let Err(e) = itaipu_calib::spec::CalibSpec::parse(&b.text, &b.file) {
                    panic!("{}: {e}", b.at());
                }
            }
            Some("event") => {
                let from = root.join(words.next().expect("event DIR"));
                let csv = table["csv"].as_str().expect("csv").to_string();
                std::fs::copy(from.join(&csv), dir.join(&csv)).unwrap();
                std::fs::write(dir.join("event.toml"), &b.text).unwrap();
                if let Err(e) =
                    itaipu_dynamics::event::Event::from_toml_file(&dir.join("event.toml"))
                {
                    panic!("{}: {e}", b.at());
                }
            }
            Some("unit") => {
                std::fs::write(dir.join("unit.toml"), &b.text).unwrap();
                if let Err(e) = itaipu_dynamics::unit_file::read_unit(&dir.join("unit.toml")) {
                    panic!("{}: {e}", b.at());
                }
            }
            Some("file") => {
                let path = root.join(words.next().expect("file PATH"));
                let file = std::fs::read_to_string(&path).unwrap_or_default();
                assert!(
                    file == b.text,
                    "{}: the block is not {} as it is",
                    b.at(),
                    path.display()
                );
            }
            Some(other) => panic!("{}: unknown check '{other}'", b.at()),
        }
        let _ = std::fs::remove_dir_all(&dir);
        checked += 1;
    }
    assert!(checked >= 8, "only {checked} TOML blocks found");
}

// -------------------------------------------------------------------------------------------
// Rust
// -------------------------------------------------------------------------------------------

#[test]
fn rust_blocks_are_files_compiled_with_a_crate() {
    let root = repo();
    let sources = rust_sources(&root.join("crates"));
    let mut n = 0;
    for b in all_blocks().into_iter().filter(|b| b.lang == "rust") {
        let check = b.check.clone().unwrap_or_default();
        let rel = check
            .strip_prefix("file ")
            .unwrap_or_else(|| panic!("{}: a Rust example names its compiled file", b.at()));
        let file = std::fs::read_to_string(root.join(rel)).unwrap_or_default();
        assert!(
            file == b.text,
            "{}: the block is not {rel} as it is",
            b.at()
        );
        let included = sources.iter().any(|s| {
            std::fs::read_to_string(s)
                .unwrap()
                .lines()
                .any(|l| l.contains("#[path") && l.contains(rel))
        });
        assert!(included, "{}: {rel} is compiled by no crate", b.at());
        n += 1;
    }
    assert!(n >= 1, "the cause example of docs/extending.md");
}

fn rust_sources(dir: &Path) -> Vec<PathBuf> {
    let mut out = vec![];
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() && !p.ends_with("target") {
            out.extend(rust_sources(&p));
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
    out
}

// -------------------------------------------------------------------------------------------
// Links
// -------------------------------------------------------------------------------------------

/// Chapters other engineers are writing: a link to them may point ahead of the file.
const PENDING: &[&str] = &[];

/// GitHub's anchor of a heading.
fn slug(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || *c == ' ' || *c == '-' || *c == '_')
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

fn anchors(file: &Path) -> BTreeSet<String> {
    let text = std::fs::read_to_string(file).unwrap_or_default();
    let mut in_code = false;
    let mut out = BTreeSet::new();
    for l in text.lines() {
        if l.starts_with("```") {
            in_code = !in_code;
        } else if !in_code && l.starts_with('#') {
            out.insert(slug(l.trim_start_matches('#').replace('`', "").as_str()));
        }
    }
    out
}

#[test]
fn relative_links_point_at_files_and_headings_that_exist() {
    let root = repo();
    let files: Vec<PathBuf> = doc_files()
        .into_iter()
        .chain(
            std::fs::read_dir(root.join("docs/lab"))
                .unwrap()
                .map(|e| e.unwrap().path()),
        )
        .collect();
    for f in files {
        let text = std::fs::read_to_string(&f).unwrap();
        let mut rest = text.as_str();
        while let Some(i) = rest.find("](") {
            rest = &rest[i + 2..];
            let Some(end) = rest.find(')') else { break };
            let target = &rest[..end];
            if target.contains("://") || target.starts_with("mailto:") {
                continue;
            }
            let (path, anchor) = target.split_once('#').unwrap_or((target, ""));
            let dest = if path.is_empty() {
                f.clone()
            } else {
                f.parent().unwrap().join(path)
            };
            let rel = dest
                .canonicalize()
                .ok()
                .and_then(|d| d.strip_prefix(&root).ok().map(|p| p.to_path_buf()));
            if !dest.exists() {
                let pending = PENDING.iter().any(|p| root.join(p) == dest);
                assert!(pending, "{}: link to {target}: no such file", f.display());
                continue;
            }
            if !anchor.is_empty() {
                assert!(
                    anchors(&dest).contains(anchor),
                    "{}: link to {target}: no heading '#{anchor}' in {}",
                    f.display(),
                    rel.unwrap_or(dest.clone()).display()
                );
            }
        }
    }
}

// -------------------------------------------------------------------------------------------
// Shell
// -------------------------------------------------------------------------------------------

/// One shell command line of a block: its words (before any pipe or redirection), and the exit
/// code its comment states.
#[derive(Debug, Clone)]
struct Line {
    at: String,
    words: Vec<String>,
    exit: u8,
}

/// The command lines of a shell block: continuation lines joined, comments cut, environment
/// assignments in front dropped.
fn command_lines(b: &Block) -> Vec<Line> {
    let mut out = vec![];
    let mut pending = String::new();
    for (k, raw) in b.text.lines().enumerate() {
        if let Some(head) = raw.strip_suffix('\\') {
            pending.push_str(head);
            pending.push(' ');
            continue;
        }
        let line = format!("{pending}{raw}");
        pending.clear();
        let (code, comment) = match line.find(" #") {
            Some(i) => (line[..i].to_string(), line[i..].to_string()),
            None if line.trim_start().starts_with('#') => (String::new(), line.clone()),
            None => (line.clone(), String::new()),
        };
        let exit = comment
            .split("exit ")
            .nth(1)
            .and_then(|s| s.split(|c: char| !c.is_ascii_digit()).next())
            .and_then(|s| s.parse().ok())
            .unwrap_or(0);
        let mut words = shell_words(&code);
        if let Some(i) = words.iter().position(|w| w == "|" || w == ">") {
            words.truncate(i);
        }
        while words.first().is_some_and(|w| {
            w.contains('=')
                && w.split('=')
                    .next()
                    .unwrap()
                    .chars()
                    .all(|c| c.is_ascii_uppercase() || c == '_')
        }) {
            words.remove(0);
        }
        if !words.is_empty() {
            out.push(Line {
                at: format!("{}:{}", b.file.display(), b.line + 1 + k),
                words,
                exit,
            });
        }
    }
    out
}

/// Words as a POSIX shell splits them (single and double quotes; no expansion).
fn shell_words(s: &str) -> Vec<String> {
    let mut out = vec![];
    let mut cur = String::new();
    let mut quote: Option<char> = None;
    let mut any = false;
    for c in s.chars() {
        match (quote, c) {
            (Some(q), c) if c == q => quote = None,
            (Some(_), c) => cur.push(c),
            (None, '\'' | '"') => {
                quote = Some(c);
                any = true;
            }
            (None, c) if c.is_whitespace() => {
                if any || !cur.is_empty() {
                    out.push(std::mem::take(&mut cur));
                    any = false;
                }
            }
            (None, c) => cur.push(c),
        }
    }
    if any || !cur.is_empty() {
        out.push(cur);
    }
    out
}

/// What a documented command is.
#[derive(Debug)]
enum Kind {
    /// An `itaipu-calib` command with these arguments.
    Tool(Vec<String>),
    /// A command the tests do not run (a build, an installation, a viewer): checked for what
    /// it names.
    Other,
}

fn classify(line: &Line) -> Kind {
    let w = &line.words;
    let root = repo();
    let head = w[0].as_str();
    if head == "itaipu-calib" || head.ends_with("/itaipu-calib") {
        return Kind::Tool(w[1..].to_vec());
    }
    match head {
        "cargo" => {
            let package = w.iter().position(|x| x == "-p").map(|i| w[i + 1].clone());
            if let Some(p) = &package {
                let dir = match p.as_str() {
                    "itaipu-calib-cli" => "crates/cli",
                    "itaipu-calib" => "crates/calib",
                    "itaipu-dynamics" => "crates/dynamics",
                    "itaipu-calib-py" => "crates/py",
                    other => panic!("{}: no package {other}", line.at),
                };
                if let Some(i) = w.iter().position(|x| x == "--example") {
                    let ex = root
                        .join(dir)
                        .join("examples")
                        .join(format!("{}.rs", w[i + 1]));
                    assert!(ex.is_file(), "{}: no example {}", line.at, ex.display());
                }
                if let Some(i) = w.iter().position(|x| x == "--test") {
                    let manifest = std::fs::read_to_string(root.join(dir).join("Cargo.toml"));
                    let target = format!("name = \"{}\"", w[i + 1]);
                    assert!(
                        manifest.unwrap().contains(&target),
                        "{}: {p} has no test target {}",
                        line.at,
                        w[i + 1]
                    );
                }
                if let Some(i) = w.iter().position(|x| x == "--bench") {
                    let t = root
                        .join(dir)
                        .join("benches")
                        .join(format!("{}.rs", w[i + 1]));
                    assert!(t.is_file(), "{}: no bench {}", line.at, t.display());
                }
                if w[1] == "run" && p == "itaipu-calib-cli" && w.iter().all(|x| x != "--example") {
                    let dash = w
                        .iter()
                        .position(|x| x == "--")
                        .expect("cargo run ... -- ARGS");
                    return Kind::Tool(w[dash + 1..].to_vec());
                }
            }
            Kind::Other
        }
        "bash" => {
            assert!(
                root.join(&w[1]).is_file(),
                "{}: no script {}",
                line.at,
                w[1]
            );
            Kind::Other
        }
        "export" | "python3" | "target/venv/bin/pip" | "pip" | "xdg-open" => Kind::Other,
        other => panic!(
            "{}: a command the documentation's tests do not know: {other}",
            line.at
        ),
    }
}

/// The input files a command names (relative paths outside `out/`): they must exist.
fn inputs(args: &[String]) -> Vec<String> {
    args.iter()
        .filter(|a| !a.starts_with('-') && a.contains('/') && !a.starts_with("out/"))
        .filter(|a| !a.contains(':') && !a.contains('='))
        .cloned()
        .collect()
}

/// The commands of every shell block, file by file.
fn shell_lines() -> Vec<(PathBuf, Vec<Line>)> {
    doc_files()
        .into_iter()
        .map(|f| {
            let lines = blocks(&f)
                .iter()
                .filter(|b| b.lang == "sh")
                .flat_map(command_lines)
                .collect();
            (f, lines)
        })
        .collect()
}

#[test]
fn every_documented_command_parses_and_names_existing_inputs() {
    let root = repo();
    let mut n = 0;
    for (_, lines) in shell_lines() {
        for line in lines {
            let Kind::Tool(args) = classify(&line) else {
                continue;
            };
            let mut argv = vec!["itaipu-calib".to_string()];
            argv.extend(args.iter().cloned());
            if let Err(e) = itaipu_calib_cli::command().try_get_matches_from(&argv) {
                panic!("{}: `{}` does not parse: {e}", line.at, argv.join(" "));
            }
            for p in inputs(&args) {
                assert!(root.join(&p).exists(), "{}: no such input {p}", line.at);
            }
            n += 1;
        }
    }
    assert!(n >= 20, "only {n} commands found");
}

/// Commands quick enough for every test run (a playback or two).
const QUICK: [&str; 6] = ["simulate", "import", "synth", "dyr", "models", "diagram"];

/// A folder to run a file's commands in: `data` is the repository's.
fn scratch(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("itaipu-docs-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn documented_commands_end_as_documented() {
    let root = repo();
    let mut ran = 0;
    for (file, lines) in shell_lines() {
        let name = file.file_stem().unwrap().to_string_lossy().to_string();
        let dir = scratch(&format!("sh-{name}"));
        std::os::unix::fs::symlink(root.join("data"), dir.join("data")).unwrap();
        for line in lines {
            let Kind::Tool(args) = classify(&line) else {
                continue;
            };
            let quick = args.first().is_some_and(|c| QUICK.contains(&c.as_str()));
            // Its inputs written by earlier commands of the file are there (not when a slow
            // command before it was skipped).
            let ready = args
                .iter()
                .enumerate()
                .filter(|(i, a)| a.starts_with("out/") && (*i == 0 || args[i - 1] != "--out"))
                .all(|(_, a)| dir.join(a).exists());
            if !(slow() || (quick && ready)) {
                continue;
            }
            let out = Command::new(env!("CARGO_BIN_EXE_itaipu-calib"))
                .args(&args)
                .current_dir(&dir)
                .output()
                .expect("the binary runs");
            let code = out.status.code().unwrap_or(255) as u8;
            assert_eq!(
                code,
                line.exit,
                "{}: `itaipu-calib {}` ended with exit {code}, the documentation says {}:\n{}",
                line.at,
                args.join(" "),
                line.exit,
                String::from_utf8_lossy(&out.stderr)
            );
            ran += 1;
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
    assert!(ran >= 8, "only {ran} commands ran");
}

#[test]
fn the_line_splitter_reads_comments_exits_and_pipes() {
    let b = Block {
        file: PathBuf::from("x.md"),
        line: 1,
        lang: "sh".into(),
        check: None,
        text: "itaipu-calib dyr write a.toml --out 'b c.dyr'   # refused: exit 4\n\
               X_Y=1 cargo test -p itaipu-calib \\\n  --lib options\n\
               itaipu-calib diagram d.toml | dot -Tsvg > d.svg\n"
            .into(),
    };
    let l = command_lines(&b);
    assert_eq!(l.len(), 3);
    assert_eq!(
        l[0].words,
        ["itaipu-calib", "dyr", "write", "a.toml", "--out", "b c.dyr"]
    );
    assert_eq!(l[0].exit, 4);
    assert_eq!(l[1].words[..3], ["cargo", "test", "-p"]);
    assert_eq!(l[1].exit, 0);
    assert_eq!(l[2].words, ["itaipu-calib", "diagram", "d.toml"]);
    assert_eq!(
        slug("The played-back voltage's noise"),
        "the-played-back-voltages-noise"
    );
    assert_eq!(
        slug("PSS/E `.dyr` in and out".replace('`', "").as_str()),
        "psse-dyr-in-and-out"
    );
}

//! The library's comments say what and why, never when: no comment in `crates/*/src` names a
//! practice case (`p01`-`p22`, `q01`-`q44`) or a piece of the development's history (`stop 45`,
//! `issue 28`, a date, a commit hash). Those belong to the lab notebook (`docs/lab/`), which
//! the code does not cite. Precise on purpose: a time stamp shown as an example of a format
//! (`2021-03-04T05:06:07Z`), a hexadecimal constant or the word "stop" followed by anything but
//! a number pass.

use std::path::{Path, PathBuf};

/// The repository's root.
fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .canonicalize()
        .expect("the repository's root")
}

/// Every `.rs` file under `crates/*/src`.
fn library_sources() -> Vec<PathBuf> {
    let crates = repo_root().join("crates");
    let mut out = vec![];
    for c in std::fs::read_dir(&crates).unwrap() {
        let src = c.unwrap().path().join("src");
        if src.is_dir() {
            walk(&src, &mut out);
        }
    }
    out.sort();
    out
}

fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            walk(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The comment on a line of Rust (after a `//` that is not inside a string literal), if any.
fn comment(line: &str) -> Option<&str> {
    let mut in_string = false;
    let mut prev = ' ';
    let bytes: Vec<char> = line.chars().collect();
    let mut byte = 0;
    for (i, &c) in bytes.iter().enumerate() {
        if c == '"' && prev != '\\' && !(prev == '\'' && bytes.get(i + 1) == Some(&'\'')) {
            in_string = !in_string;
        }
        if !in_string && c == '/' && bytes.get(i + 1) == Some(&'/') {
            return Some(&line[byte + 2..]);
        }
        prev = c;
        byte += c.len_utf8();
    }
    None
}

/// Words: runs of ASCII letters and digits.
fn words(text: &str) -> Vec<&str> {
    text.split(|c: char| !c.is_ascii_alphanumeric())
        .filter(|w| !w.is_empty())
        .collect()
}

fn number(w: &str) -> bool {
    !w.is_empty() && w.chars().all(|c| c.is_ascii_digit())
}

/// A practice case's name: `p01`-`p22` or `q01`-`q44`.
fn practice_case(w: &str) -> bool {
    let (head, n) = w.split_at(1.min(w.len()));
    if n.len() != 2 || !number(n) {
        return false;
    }
    let n: u32 = n.parse().unwrap();
    match head {
        "p" => (1..=22).contains(&n),
        "q" => (1..=44).contains(&n),
        _ => false,
    }
}

/// A commit hash: 7 to 40 lower-case hexadecimal digits with at least one letter and one digit.
fn commit_hash(w: &str) -> bool {
    (7..=40).contains(&w.len())
        && w.chars()
            .all(|c| c.is_ascii_digit() || ('a'..='f').contains(&c))
        && w.chars().any(|c| c.is_ascii_digit())
        && w.chars().any(|c| c.is_ascii_alphabetic())
}

/// A calendar date `YYYY-MM-DD` not followed by `T` (an ISO 8601 time stamp shown as an
/// example of a format).
fn date(text: &str) -> Option<&str> {
    let b = text.as_bytes();
    (0..b.len().saturating_sub(9)).find_map(|i| {
        let s = &b[i..i + 10];
        let digits = |r: std::ops::Range<usize>| r.into_iter().all(|k| s[k].is_ascii_digit());
        let boundary = i == 0 || !b[i - 1].is_ascii_alphanumeric();
        let date = digits(0..4) && s[4] == b'-' && digits(5..7) && s[7] == b'-' && digits(8..10);
        let after = b.get(i + 10).copied();
        let stamp = matches!(after, Some(b'T') | Some(b't'));
        let more = after.is_some_and(|c| c.is_ascii_alphanumeric());
        (boundary && date && !stamp && !more && &s[0..2] == b"20").then(|| &text[i..i + 10])
    })
}

/// What a comment names that it should not, if anything.
fn offence(text: &str) -> Option<String> {
    let w = words(text);
    for (k, word) in w.iter().enumerate() {
        if practice_case(word) {
            return Some(format!("practice case '{word}'"));
        }
        let next = w.get(k + 1).copied().unwrap_or("");
        let lower = word.to_ascii_lowercase();
        if (lower == "stop" || lower == "stops") && number(next) {
            return Some(format!("history '{word} {next}'"));
        }
        if (lower == "issue" || lower == "issues") && number(next) {
            return Some(format!("history '{word} {next}'"));
        }
        if commit_hash(word) {
            return Some(format!("commit hash '{word}'"));
        }
    }
    date(text).map(|d| format!("date '{d}'"))
}

#[test]
fn library_comments_name_no_practice_case_and_no_history() {
    let mut hits = vec![];
    for path in library_sources() {
        let text = std::fs::read_to_string(&path).unwrap();
        for (k, line) in text.lines().enumerate() {
            if let Some(why) = comment(line).and_then(offence) {
                let shown = path.strip_prefix(repo_root()).unwrap_or(&path);
                hits.push(format!("{}:{}: {why}", shown.display(), k + 1));
            }
        }
    }
    assert!(
        hits.is_empty(),
        "{} comment(s) name a practice case or the development's history (say what and why; \
         measurements go to docs/lab/):\n{}",
        hits.len(),
        hits.join("\n")
    );
}

#[test]
fn the_scanner_flags_what_it_should_and_nothing_else() {
    for bad in [
        "measured on p09 and q13",
        "since stop 45 the rule",
        "(issue 28, the profile)",
        "as at 9326ba7",
        "measured 2026-11-28",
    ] {
        assert!(offence(bad).is_some(), "{bad}");
    }
    for good in [
        "an ISO 8601 stamp (`2021-03-04T05:06:07.016667Z`)",
        "the swarm's stop reason",
        "stops at 1e-6",
        "p value below 0.05 (p < 1e-6)",
        "q45 and p23 are out of the sets' range",
        "SplitMix64 seed 1234567",
        "0x9e3779b97f4a7c15",
        "deadbeef and facade",
        "an issue the user must fix",
    ] {
        assert!(offence(good).is_none(), "{good}: {:?}", offence(good));
    }
    assert_eq!(comment(r#"let s = "http://x"; // a p09"#), Some(" a p09"));
    assert_eq!(comment(r#"let s = "a // b";"#), None);
    assert_eq!(comment("let c = '\"'; // q13"), Some(" q13"));
}

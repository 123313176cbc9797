//! The option reference, `docs/options.md`: every command's options as the command line
//! defines them (clap), with the Python spelling and default of each option both front ends
//! take from the library's declaration ([`itaipu_calib::options`]). A test fails when the file
//! is not what [`options_reference`] renders; `ITAIPU_WRITE_DOCS=1` makes it write the file.

use clap::{Arg, ArgAction};
use itaipu_calib::options::{Command as Cmd, DefaultValue, OptionDecl, OPTIONS};
use itaipu_calib::request::Style;

/// How to rewrite the reference after an option changed.
pub const REGENERATE: &str =
    "ITAIPU_WRITE_DOCS=1 cargo test --release -p itaipu-calib-cli --lib options_doc";

/// The option reference as Markdown.
pub fn options_reference() -> String {
    let mut out = String::new();
    out.push_str("# Option reference\n\n");
    out.push_str(&format!(
        "<!-- Generated: do not edit. Rendered from the option declaration \
         (crates/calib/src/options.rs) and the command line's definition (crates/cli); \
         `{REGENERATE}` rewrites this file, and that test fails when it is not current. -->\n\n"
    ));
    out.push_str(
        "Every option of every command. An option with a Python spelling is taken by both front \
         ends, with the same default and the same checks (the Python function of the same name: \
         `itaipu_calib.simulate`, `fit`, `diagnose`, `synth`; `itaipu_calib.options()` returns \
         these declarations). Arguments only Python has (the events and unit as objects, \
         `fit=`, `return_truth`, ...) are in each function's docstring. Exit codes: see \
         `itaipu-calib --help`.\n",
    );
    let root = crate::command();
    for sub in root.get_subcommands() {
        render_command(&mut out, sub, &[]);
    }
    out
}

/// The section of subcommand `cmd` (and of its own subcommands, `parents` naming the path).
fn render_command(out: &mut String, cmd: &clap::Command, parents: &[&str]) {
    let mut path: Vec<&str> = parents.to_vec();
    path.push(cmd.get_name());
    let declared = declared_command(&path);
    let args: Vec<&Arg> = cmd
        .get_arguments()
        .filter(|a| !matches!(a.get_action(), ArgAction::Help | ArgAction::Version))
        .filter(|a| !a.is_hide_set())
        .collect();
    out.push_str(&format!("\n## `itaipu-calib {}`\n\n", path.join(" ")));
    if let Some(about) = cmd.get_about() {
        out.push_str(&one_line(&about.to_string()));
        out.push('\n');
    }
    if !args.is_empty() {
        out.push_str("\n| command line | Python | default | what it does |\n|---|---|---|---|\n");
        for a in args {
            out.push_str(&row(a, declared));
        }
    }
    for sub in cmd.get_subcommands() {
        render_command(out, sub, &path);
    }
}

/// The declared command behind a subcommand path (`["fit"]`), if both front ends have it.
fn declared_command(path: &[&str]) -> Option<Cmd> {
    match path {
        [one] => Cmd::ALL.into_iter().find(|c| c.name() == *one),
        _ => None,
    }
}

/// The declaration of the command line's option `long` of `cmd`.
fn declaration(cmd: Cmd, long: &str) -> Option<&'static OptionDecl> {
    OPTIONS
        .iter()
        .find(|o| o.command == cmd && o.cli == Some(long))
}

/// One table row.
fn row(a: &Arg, cmd: Option<Cmd>) -> String {
    let decl = match (cmd, a.get_long()) {
        (Some(c), Some(long)) => declaration(c, long),
        _ => None,
    };
    let python = match decl {
        Some(OptionDecl {
            python: Some(p),
            default,
            ..
        }) => match default {
            DefaultValue::Switch(Some(on)) => format!("`{p}={}`", py_bool(!on)),
            DefaultValue::Switch(None) => format!("`{p}=False`"),
            _ => format!("`{p}`"),
        },
        _ => "—".to_string(),
    };
    let default = match decl {
        Some(d) => d.default_text().unwrap_or_else(|| "off".into()),
        None => clap_default(a),
    };
    let help = match decl {
        Some(d) => d.help(Style::Cli),
        None => a
            .get_long_help()
            .or(a.get_help())
            .map(|h| h.to_string())
            .unwrap_or_default(),
    };
    format!(
        "| {} | {python} | {} | {} |\n",
        cell(&spelling(a)),
        cell(&default),
        cell(&one_line(&help))
    )
}

fn py_bool(b: bool) -> &'static str {
    if b {
        "True"
    } else {
        "False"
    }
}

/// `--name <VALUE>` (or `FILE` for a positional argument).
fn spelling(a: &Arg) -> String {
    let value = a
        .get_value_names()
        .map(|v| {
            v.iter()
                .map(|s| s.to_string())
                .collect::<Vec<_>>()
                .join(" ")
        })
        .unwrap_or_else(|| a.get_id().as_str().to_uppercase());
    let takes_value = matches!(a.get_action(), ArgAction::Set | ArgAction::Append);
    let values: Vec<String> = a
        .get_possible_values()
        .iter()
        .filter(|v| !v.is_hide_set())
        .map(|v| v.get_name().to_string())
        .collect();
    let value = if !values.is_empty() && values.len() <= 6 {
        values.join("|")
    } else {
        value
    };
    match a.get_long() {
        Some(long) if takes_value => format!("`--{long} <{value}>`"),
        Some(long) => format!("`--{long}`"),
        None => format!("`{value}`"),
    }
}

/// The default clap shows, or a dash.
fn clap_default(a: &Arg) -> String {
    let d: Vec<String> = a
        .get_default_values()
        .iter()
        .map(|v| v.to_string_lossy().into_owned())
        .collect();
    if d.is_empty() {
        if matches!(a.get_action(), ArgAction::SetTrue) {
            "off".into()
        } else {
            "—".into()
        }
    } else {
        d.join(",")
    }
}

/// Whitespace (clap's wrapped doc comments) folded into single spaces.
fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// A Markdown table cell: pipes escaped.
fn cell(s: &str) -> String {
    s.replace('|', "\\|")
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    fn reference_path() -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../docs/options.md")
    }

    /// docs/options.md is what the declarations render; `ITAIPU_WRITE_DOCS=1` rewrites it.
    #[test]
    fn docs_options_md_is_current() {
        let want = options_reference();
        let path = reference_path();
        if std::env::var_os("ITAIPU_WRITE_DOCS").is_some() {
            std::fs::write(&path, &want).expect("docs/options.md written");
            return;
        }
        let have = std::fs::read_to_string(&path).unwrap_or_default();
        assert!(
            have == want,
            "docs/options.md is not current: run `{REGENERATE}`"
        );
    }

    /// Every declared option with a command-line spelling is an option of that command, with
    /// the declared default and the declared help: clap reads the declaration, not a copy.
    #[test]
    fn the_command_line_takes_every_declared_option_as_declared() {
        let root = crate::command();
        for o in OPTIONS.iter().filter(|o| o.cli.is_some()) {
            let long = o.cli.unwrap();
            let sub = root
                .find_subcommand(o.command.name())
                .unwrap_or_else(|| panic!("no subcommand {}", o.command.name()));
            let arg = sub
                .get_arguments()
                .find(|a| a.get_long() == Some(long))
                .unwrap_or_else(|| panic!("{} has no --{long}", o.command.name()));
            let clap_default: Vec<String> = arg
                .get_default_values()
                .iter()
                .map(|v| v.to_string_lossy().into_owned())
                .collect();
            match o.default {
                DefaultValue::Text(_) | DefaultValue::Real(_) | DefaultValue::Int(_) => {
                    assert_eq!(
                        clap_default,
                        [o.default_text().unwrap()],
                        "--{long} of {}",
                        o.command.name()
                    )
                }
                _ => assert!(clap_default.is_empty(), "--{long} has a default of its own"),
            }
            let help = arg.get_help().map(|h| h.to_string()).unwrap_or_default();
            assert!(
                help.starts_with(&o.help(Style::Cli)),
                "--{long} of {}: help not from the declaration",
                o.command.name()
            );
        }
    }

    #[test]
    fn cells_escape_pipes() {
        assert_eq!(cell("|V|"), "\\|V\\|");
    }
}

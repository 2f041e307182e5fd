//! Every `pcrnet` command the README, `docs/` and the crate READMEs show
//! still exists with the flags they give it: each `pcrnet SUBCOMMAND
//! --flag ...` in a code span or block is checked against `pcrnet
//! SUBCOMMAND --help`. (Running each as written would need the ModelNet
//! data and hours of training; the commands that run on a fresh machine
//! are run by CI itself: `cargo xtask demo`, the tests of this crate.)

use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The Markdown files a user reads.
fn documents() -> Vec<PathBuf> {
    let root = root();
    let mut files = vec![
        root.join("README.md"),
        root.join("CONTRIBUTING.md"),
        root.join("core/README.md"),
    ];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root.join("docs"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    docs.sort();
    files.extend(docs);
    files
}

/// The shell code in a Markdown text: fenced shell blocks line by line
/// (comments cut off) and inline `code` spans.
fn code_spans(text: &str) -> Vec<String> {
    let mut spans = Vec::new();
    // Inside a fence: whether it holds shell commands (not Rust or C).
    let mut fence: Option<bool> = None;
    for line in text.lines() {
        if let Some(lang) = line.trim_start().strip_prefix("```") {
            fence = match fence {
                Some(_) => None,
                None => Some(matches!(
                    lang.trim(),
                    "" | "sh" | "bash" | "shell" | "console"
                )),
            };
            continue;
        }
        if let Some(shell) = fence {
            if shell {
                spans.push(line.split(" #").next().unwrap_or("").to_owned());
            }
        } else {
            spans.extend(line.split('`').skip(1).step_by(2).map(str::to_owned));
        }
    }
    spans
}

/// Each `pcrnet SUBCOMMAND` in `code` with the `--flags` that follow it.
fn commands(code: &str) -> Vec<(String, Vec<String>)> {
    let words: Vec<&str> = code.split_whitespace().collect();
    let mut found = Vec::new();
    for (i, pair) in words.windows(2).enumerate() {
        let sub = pair[1];
        if pair[0] != "pcrnet" || !sub.chars().all(|c| c.is_ascii_lowercase()) {
            continue;
        }
        let flags = words[i + 2..]
            .iter()
            .take_while(|w| **w != "pcrnet" && !w.starts_with('|') && !w.starts_with(';'))
            .filter(|w| w.starts_with("--") && w.len() > 2)
            .map(|w| w.split(['=', ',', ')', '.']).next().unwrap_or(w).to_owned())
            .collect();
        found.push((sub.to_owned(), flags));
    }
    found
}

fn help(sub: &str) -> Option<String> {
    let out = Command::new(env!("CARGO_BIN_EXE_pcrnet"))
        .args([sub, "--help"])
        .output()
        .unwrap();
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).into_owned())
}

#[test]
fn documented_commands_and_flags_exist() {
    let mut checked = 0;
    let mut wrong = Vec::new();
    let mut helps = std::collections::HashMap::new();
    for file in documents() {
        let text = std::fs::read_to_string(&file).unwrap();
        let name = file
            .strip_prefix(root())
            .unwrap_or(Path::new("?"))
            .display()
            .to_string();
        for code in code_spans(&text) {
            for (sub, flags) in commands(&code) {
                let help = helps.entry(sub.clone()).or_insert_with(|| help(&sub));
                let Some(help) = help else {
                    wrong.push(format!("{name}: `pcrnet {sub}`: no such command ({code})"));
                    continue;
                };
                for flag in flags {
                    let known = help
                        .split(|c: char| !(c.is_ascii_alphanumeric() || c == '-'))
                        .any(|w| w == flag);
                    if !known {
                        wrong.push(format!("{name}: `pcrnet {sub}` has no {flag} ({code})"));
                    }
                }
                checked += 1;
            }
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
    // The scan sees the documents' commands (the README alone shows four).
    assert!(checked >= 30, "only {checked} commands found");
}

#[test]
fn a_wrong_flag_would_be_caught() {
    let cmds = commands("pcrnet register A B --no-such-flag --json -");
    assert_eq!(
        cmds,
        [(
            "register".to_owned(),
            vec!["--no-such-flag".to_owned(), "--json".to_owned()]
        )]
    );
    let text = help("register").unwrap();
    assert!(text.contains("--json") && !text.contains("--no-such-flag"));
    assert!(help("no-such-command").is_none());
}

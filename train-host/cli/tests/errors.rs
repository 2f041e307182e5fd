//! The `pcrnet` binary as a user's shell runs it: bad flag values, user
//! errors and a closed output pipe give a clear exit, never a panic; each
//! error names its flag or file once.

mod common;

use std::path::PathBuf;
use std::process::Stdio;

use common::{models, pcrnet};

#[test]
fn a_closed_output_pipe_ends_quietly() {
    let m = models();
    let runs: [Vec<PathBuf>; 2] = [
        vec![
            "register".into(),
            m.join("embedded-default-template.xyz"),
            m.join("embedded-default-source.xyz"),
            "--method".into(),
            "icp".into(),
        ],
        vec!["inspect".into(), m.join("embedded-default-int8.pcrn")],
    ];
    for args in runs {
        let mut child = pcrnet()
            .args(&args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // The reader goes away before anything is written (`| head -0`).
        drop(child.stdout.take());
        let out = child.wait_with_output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
        assert_eq!(out.status.code(), Some(0), "{args:?}: {stderr}");
    }
}

#[test]
fn bad_flag_values_are_errors_naming_the_flag() {
    for (args, flag) in [
        (
            vec![
                "pairs",
                "--generated",
                "3",
                "--max-deg=-10",
                "--out",
                "/dev/null",
            ],
            "--max-deg",
        ),
        (
            vec![
                "pairs",
                "--generated",
                "3",
                "--max-deg",
                "nan",
                "--out",
                "/dev/null",
            ],
            "--max-deg",
        ),
        (
            vec![
                "pairs",
                "--generated",
                "3",
                "--max-t",
                "nan",
                "--out",
                "/dev/null",
            ],
            "--max-t",
        ),
        (
            vec![
                "train",
                "--generated",
                "3",
                "--max-t",
                "nan",
                "--out",
                "/dev/null",
            ],
            "--max-t",
        ),
    ] {
        let out = pcrnet().args(&args).output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {stderr}");
        assert!(
            stderr.contains(flag) && !stderr.contains("panicked"),
            "{args:?}: {stderr}"
        );
        // One chain of messages, no backtrace even when one is asked for.
        assert!(!stderr.contains("stack backtrace"), "{stderr}");
    }
}

/// Issue 10, items 12 and 13, as a kind: every user error is one chain of
/// messages in the user's terms (the flag or file it concerns, what to do),
/// no backtrace even with RUST_BACKTRACE=1, no part said twice.
#[test]
fn user_errors_name_the_flag_or_file_once() {
    let m = models();
    let s = |p: &str| m.join(p).display().to_string();
    let (src, tpl) = (
        s("embedded-default-source.xyz"),
        s("embedded-default-template.xyz"),
    );
    let (int8, f32) = (
        s("embedded-default-int8.pcrn"),
        s("embedded-default-f32.pcrn"),
    );
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            vec![
                "register".into(),
                src.clone(),
                "--method".into(),
                "pointnetlk".into(),
                "--model".into(),
                int8.clone(),
            ],
            "--method pointnetlk needs the f32 blob",
        ),
        (
            vec![
                "register".into(),
                src.clone(),
                "--model".into(),
                src.clone(),
            ],
            "not a model blob",
        ),
        (
            vec![
                "register".into(),
                tpl.clone(),
                src.clone(),
                "--model".into(),
                f32.clone(),
                "--hypotheses".into(),
                "0".into(),
            ],
            "--hypotheses must be at least 1",
        ),
        (
            vec![
                "register".into(),
                tpl.clone(),
                src.clone(),
                "--model".into(),
                int8.clone(),
                "--template-points".into(),
                "70000".into(),
            ],
            "--template-points must be between 1 and 65535",
        ),
        (
            vec![
                "register".into(),
                src.clone(),
                "--model".into(),
                int8.clone(),
                "--template-points".into(),
                "1024".into(),
            ],
            "--template-points applies to a TEMPLATE file",
        ),
        (
            vec![
                "register".into(),
                src.clone(),
                "--model".into(),
                int8.clone(),
                "--icp-distance=nan".into(),
            ],
            "--icp-distance NaN",
        ),
        (
            vec![
                "register".into(),
                src.clone(),
                "--method".into(),
                "icp".into(),
            ],
            "give TEMPLATE SOURCE",
        ),
        (
            vec![
                "pairs".into(),
                "--generated".into(),
                "2".into(),
                "--noise".into(),
                "abc".into(),
                "--out".into(),
                "/nonexistent/p.json".into(),
            ],
            "--noise \"abc\"",
        ),
        (
            vec!["inspect".into(), "/nonexistent.pcrn".into()],
            "/nonexistent.pcrn",
        ),
        // More starting poses than the template has turns (+ 1), with the
        // blob's own template and with a template file bound in its place.
        (
            vec![
                "register".into(),
                src.clone(),
                "--model".into(),
                int8.clone(),
                "--hypotheses".into(),
                "99".into(),
            ],
            "--hypotheses 99: the template has 9 turns, so the device tries 1 to 10",
        ),
        (
            vec![
                "register".into(),
                tpl.clone(),
                src.clone(),
                "--model".into(),
                int8.clone(),
                "--hypotheses".into(),
                "11".into(),
            ],
            "--hypotheses 11: the template has 9 turns",
        ),
        // A negative value after a space reaches the flag's own check.
        (
            vec![
                "register".into(),
                src.clone(),
                "--model".into(),
                int8.clone(),
                "--max-residual".into(),
                "-1".into(),
            ],
            "--max-residual -1 must be finite and at least 0",
        ),
        // Refused once, before any pair is read.
        (
            vec![
                "eval".into(),
                "--pairs".into(),
                "/nonexistent/pairs.json".into(),
                "--method".into(),
                "device".into(),
            ],
            "--method device needs a model",
        ),
    ];
    for (args, expected) in cases {
        let out = pcrnet()
            .args(&args)
            .env("RUST_BACKTRACE", "1")
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {stderr}");
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
        assert!(!stderr.contains("backtrace") && !stderr.contains("panicked"));
        let line = stderr.lines().find(|l| l.starts_with("error: ")).unwrap();
        let parts: Vec<&str> = line.split(": ").filter(|p| p.len() > 12).collect();
        for (i, p) in parts.iter().enumerate() {
            assert!(!parts[i + 1..].contains(p), "said twice: {line}");
        }
    }
}

//! `pcrnet register` names the clouds' roles: `--template T --source S`
//! is the positional `T S` in any order of the flags, `--source S` alone is
//! the positional `S` (the blob's own template), and a mix of the two forms
//! or a template without a source is an error naming the flag.

mod common;

use common::{models, pcrnet};

/// The JSON result of `pcrnet register ARGS --json -`, or the error text.
fn register(args: &[&str]) -> Result<serde_json::Value, String> {
    let out = pcrnet()
        .arg("register")
        .args(args)
        .args(["--json", "-"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!stderr.contains("panicked"), "{stderr}");
    if out.status.success() {
        Ok(serde_json::from_slice(&out.stdout).unwrap())
    } else {
        Err(stderr)
    }
}

#[test]
fn named_roles_match_the_positional_order() {
    let m = models();
    let template = m.join("embedded-default-template.xyz");
    let source = m.join("embedded-default-source.xyz");
    let (t, s) = (template.to_str().unwrap(), source.to_str().unwrap());
    let positional = register(&[t, s]).unwrap();
    let named = register(&["--source", s, "--template", t]).unwrap();
    assert_eq!(positional["matrix"], named["matrix"]);
    assert!(positional["matrix"].is_array(), "{positional}");
    // The other way round is a different registration: the roles matter.
    let swapped = register(&[s, t]).unwrap();
    assert_ne!(positional["matrix"], swapped["matrix"]);

    let own = register(&[s]).unwrap();
    assert_eq!(own["matrix"], register(&["--source", s]).unwrap()["matrix"]);

    for bad in [
        vec!["--template", t],
        vec![t, "--source", s],
        vec![t, s, "--template", t],
    ] {
        let error = register(&bad).unwrap_err();
        assert!(
            error.contains("--source") || error.contains("--template"),
            "{bad:?}: {error}"
        );
    }
}

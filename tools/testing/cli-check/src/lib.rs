// SPDX-License-Identifier: GPL-2.0
//! The command-line contract of every rcan tool, checked by running the
//! built program as a user does: `--help` and `--version` exit 0 and print
//! to standard output; a usage error exits 2 with `error: ` on standard
//! error, before any device or socket is touched. Each tool's
//! `tests/cli.rs` calls [`check`] with its binary.

use std::process::Command;

/// Exit code, standard output and standard error of `bin args`.
pub fn run(bin: &str, args: &[&str]) -> (i32, String, String) {
    let out = Command::new(bin)
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("run {bin}: {e}"));
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Checks the contract for the program `bin` named `name` at `version`:
/// `--help` prints a usage line starting `Usage: name`, `--version` prints
/// `name version`, an unknown option exits 2 with a usage line, and so
/// does each of `usage_errors` (argument lists the tool must refuse).
pub fn check(bin: &str, name: &str, version: &str, usage_errors: &[&[&str]]) {
    let (code, out, err) = run(bin, &["--help"]);
    assert_eq!(code, 0, "--help: {err}");
    assert!(out.contains(&format!("Usage: {name}")), "--help: {out}");
    let (code, out, err) = run(bin, &["--version"]);
    assert_eq!(code, 0, "--version: {err}");
    assert_eq!(out.trim(), format!("{name} {version}"));
    let (code, _, err) = run(bin, &["--bogus"]);
    assert_eq!(code, 2, "--bogus: {err}");
    assert!(err.contains(&format!("Usage: {name}")), "--bogus: {err}");
    for args in usage_errors {
        let (code, _, err) = run(bin, args);
        assert_eq!(code, 2, "{args:?}: {err}");
        assert!(err.starts_with("error: "), "{args:?}: {err}");
    }
}

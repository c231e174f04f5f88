// SPDX-License-Identifier: GPL-2.0
//! The command line as a user meets it (see `rcan-cli-check`): every
//! refusal happens before any module is loaded or CPU pinned, so this runs
//! on the host, unprivileged.

/// Refused on the host, each before anything is loaded.
const USAGE_ERRORS: &[&[&str]] = &[
    &["can0"],
    &["--part", "nosuch"],
    &["--stack", "neither"],
    &["--rounds"],
    &["--rounds", "x"],
    &["--bcm-jobs", "1537"],
    &["--table-masks", "256"],
    &["--table-unwanted-id", "55a"],
    &["--msg-sizes", "8301"],
    &["--rounds", "0"],
    &["--no-load"],
];

#[test]
fn help_version_and_usage_errors() {
    let bin = env!("CARGO_BIN_EXE_rcan-bench");
    rcan_cli_check::check(bin, "rcan-bench", env!("CARGO_PKG_VERSION"), USAGE_ERRORS);
    // Errors in values too carry the usage line.
    for args in USAGE_ERRORS {
        let (_, _, err) = rcan_cli_check::run(bin, args);
        assert!(err.contains("Usage: rcan-bench"), "{args:?}: {err}");
    }
}

/// `rcan-bench-sja` (the SJA1000 part bench.sh runs) likewise.
#[test]
fn sja_help_version_and_usage_errors() {
    let bin = env!("CARGO_BIN_EXE_rcan-bench-sja");
    rcan_cli_check::check(
        bin,
        "rcan-bench-sja",
        env!("CARGO_PKG_VERSION"),
        &[
            &["can0"],
            &["--frames"],
            &["--frames", "x"],
            &["--rounds", "0"],
        ],
    );
}

/// `rcan-bench-ctu` (the CTU CAN FD section of `bench.sh --part fd`)
/// likewise.
#[test]
fn ctu_help_version_and_usage_errors() {
    let bin = env!("CARGO_BIN_EXE_rcan-bench-ctu");
    rcan_cli_check::check(
        bin,
        "rcan-bench-ctu",
        env!("CARGO_PKG_VERSION"),
        &[
            &["can0"],
            &["--frames"],
            &["--frames", "0"],
            &["--rounds", "0"],
        ],
    );
}

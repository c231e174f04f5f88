// SPDX-License-Identifier: GPL-2.0
//! The command lines as a user meets them (see `rcan-cli-check`).

#[test]
fn canzlogd_help_version_and_usage_errors() {
    rcan_cli_check::check(
        env!("CARGO_BIN_EXE_canzlogd"),
        "canzlogd",
        env!("CARGO_PKG_VERSION"),
        &[
            &[],
            &["--flush-ms", "0", "can0"],
            &["--level", "10", "can0"],
            &["--max-age", "x", "can0"],
        ],
    );
}

#[test]
fn cantcpd_help_version_and_usage_errors() {
    rcan_cli_check::check(
        env!("CARGO_BIN_EXE_cantcpd"),
        "cantcpd",
        env!("CARGO_PKG_VERSION"),
        &[&["--listen", "nowhere"], &["--queue", "0"], &["extra"]],
    );
}

#[test]
fn powerd_help_version_and_usage_errors() {
    rcan_cli_check::check(
        env!("CARGO_BIN_EXE_powerd"),
        "powerd",
        env!("CARGO_PKG_VERSION"),
        &[
            &[],
            &["can0"],
            &["--id", "20000000", "can0"],
            &["--id", "123", "--data", "1", "can0"],
            &["--id", "123", "--signal", "NOPE", "can0"],
        ],
    );
}

#[test]
fn logd_help_version_and_usage_errors() {
    rcan_cli_check::check(
        env!("CARGO_BIN_EXE_logd"),
        "logd",
        env!("CARGO_PKG_VERSION"),
        &[&[], &["5"], &["128:1"], &["--max-len", "0", "5:1"]],
    );
}

// SPDX-License-Identifier: GPL-2.0
//! The command line as a user meets it (see `rcan-cli-check`).

#[test]
fn canarb_demo_help_version_and_usage_errors() {
    rcan_cli_check::check(
        env!("CARGO_BIN_EXE_canarb-demo"),
        "canarb-demo",
        env!("CARGO_PKG_VERSION"),
        &[&["can0", "can1"]],
    );
}

#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-2.0
# The main command (make demo): boot the test kernel, load pf_can,
# CANPROTO_CAN, CAN_RAW and canloop, bring can0 up and run the thesis-API
# sample, which sends a standard, an extended and a remote frame and prints
# them as they come back; then Debian's candump/cansend, unchanged, on the
# same device.
set -euo pipefail
. "$(dirname "$0")/lib.sh"
cd "$RCAN_ROOT"
script=$(mktemp -p "$RCAN_ROOT/out" demo.XXXXXX.sh 2>/dev/null ||
	{ mkdir -p "$RCAN_ROOT/out" && mktemp -p "$RCAN_ROOT/out" demo.XXXXXX.sh; })
trap 'rm -f "$script"' EXIT
cat > "$script" <<'EOS'
set -e
insmod net/can/rcan_pf.ko
insmod net/can/rcan_can.ko
insmod net/can/rcan_raw.ko
insmod drivers/net/can/rcan_loop.ko
ip link set can0 up
echo "--- modules loaded, can0 up; running samples/rcan canarb-demo"
target/release/canarb-demo can0
echo "--- can-utils on rcan's CAN_RAW: candump while cansend sends three frames"
candump -n 3 -ta can0 &
dump=$!
sleep 1
cansend can0 123#DEADBEEF
cansend can0 12345678#0102
cansend can0 321#R
wait $dump
echo "--- ip -s link show can0"
ip -s link show can0
EOS
bash "$RCAN_ROOT/tools/testing/rcan/vm-run.sh" --timeout 300 -- bash "$script"

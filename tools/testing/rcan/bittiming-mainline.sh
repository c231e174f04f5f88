#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-2.0
#
# Records what mainline's CAN device layer computes, for the expected
# values of rcan-core's bit-timing tests (net/can/core/tests/bittiming.rs).
# Run inside the VM, with the mainline stack and QEMU's Kvaser cards:
#
#   . tools/testing/rcan/lib.sh
#   RCAN_KBUILD=$(RCAN_KERNEL=release bash tools/testing/rcan/build-kernel.sh)
#   RCAN_KBUILD=$RCAN_KBUILD bash tools/testing/rcan/vm-run.sh --timeout 1800 \
#       --qemu-extra "$RCAN_QEMU_CAN" -- bash tools/testing/rcan/bittiming-mainline.sh
#
# It loads mainline's can-dev, sja1000 and kvaser_pci (CAN clock 8 MHz:
# kvaser_pci.c's KVASER_PCI_CAN_CLOCK = 16 MHz / 2), and for each case runs
# the commands a user types, `ip link set can0 type can ...` and
# `ip -details link show can0`, printing one block per case:
#
#   CASE <ip arguments>
#   RC <exit status of ip link set>
#   MSG <what ip printed on stderr (the kernel's extack message)>
#   BT <bitrate> <sample-point> <tq> <prop-seg> <phase-seg1> <phase-seg2> <sjw> <brp>
#   BTR <BTR0> <BTR1>      (from mainline sja1000's "setting BTR0=.. BTR1=.." log line)
set -u
K=${RCAN_KBUILD:?RCAN_KBUILD must name the kernel build directory}
for m in net/can/can.ko drivers/net/can/dev/can-dev.ko \
	drivers/net/can/sja1000/sja1000.ko drivers/net/can/sja1000/kvaser_pci.ko; do
	insmod "$K/$m" || { echo "FAIL insmod $m"; exit 1; }
done
sleep 1
ip link show can0 >/dev/null || { echo "FAIL no can0"; exit 1; }
echo "IPVERSION $(ip -V)"
ip -details link show can0

run() {
	echo "CASE $*"
	dmesg -c >/dev/null
	local err rc
	err=$(ip link set can0 type can "$@" 2>&1 >/dev/null)
	rc=$?
	echo "RC $rc"
	[ -n "$err" ] && echo "MSG $(echo "$err" | tr '\n' ' ')"
	if [ "$rc" = 0 ]; then
		ip -details link show can0 | awk '
			/bitrate/ && /sample-point/ { for (i = 1; i <= NF; i++) { if ($i == "bitrate") b = $(i+1); if ($i == "sample-point") s = $(i+1) } }
			/ tq / { for (i = 1; i <= NF; i++) { if ($i == "tq") tq = $(i+1); if ($i == "prop-seg") p = $(i+1); if ($i == "phase-seg1") p1 = $(i+1); if ($i == "phase-seg2") p2 = $(i+1); if ($i == "sjw") j = $(i+1); if ($i == "brp") r = $(i+1) } }
			END { print "BT", b, s, tq, p, p1, p2, j, r }'
		dmesg | sed -n 's/.*setting BTR0=\(0x[0-9a-f]*\) BTR1=\(0x[0-9a-f]*\).*/BTR \1 \2/p' | tail -n 1
	fi
}

for b in 10000 20000 50000 100000 125000 250000 500000 800000 1000000; do
	run bitrate $b
	for sp in 0.5 0.6 0.75 0.8 0.875 0.9 0.95; do
		run bitrate $b sample-point $sp
	done
done
# Rates that need the nearest rate (bitrate error), odd rates, extremes.
for b in 33333 47619 83333 95000 300000 333333 666666 2000000 5000 2000 1000; do
	run bitrate $b
done
# Triple sampling (BTR1 bit 7) and its ctrlmode, then off again.
run bitrate 125000 triple-sampling on
run bitrate 125000 triple-sampling off
# Sample point 100 % and above: refused by can_validate.
run bitrate 500000 sample-point 1.0
# Bit timing given directly (tq in ns, segments, sjw).
run tq 125 prop-seg 6 phase-seg1 7 phase-seg2 2 sjw 1
run tq 125 prop-seg 6 phase-seg1 7 phase-seg2 2
run tq 250 prop-seg 8 phase-seg1 7 phase-seg2 4 sjw 4
run tq 100 prop-seg 6 phase-seg1 7 phase-seg2 2 sjw 1
run tq 130 prop-seg 6 phase-seg1 7 phase-seg2 2 sjw 1
run tq 125 prop-seg 10 phase-seg1 7 phase-seg2 2 sjw 1
run tq 125 prop-seg 0 phase-seg1 0 phase-seg2 2 sjw 1
run tq 125 prop-seg 6 phase-seg1 7 phase-seg2 9 sjw 1
run tq 125 prop-seg 6 phase-seg1 7 phase-seg2 2 sjw 5
run tq 125 prop-seg 6 phase-seg1 2 phase-seg2 4 sjw 3
run tq 125 prop-seg 6 phase-seg1 7 phase-seg2 2 sjw 3
run tq 10000 prop-seg 6 phase-seg1 7 phase-seg2 2 sjw 1
run tq 50 prop-seg 6 phase-seg1 7 phase-seg2 2 sjw 1
run tq 8000 prop-seg 6 phase-seg1 7 phase-seg2 2 sjw 1
run tq 9000 prop-seg 6 phase-seg1 7 phase-seg2 2 sjw 1
# Control modes: supported by sja1000, and CAN FD which it lacks.
run bitrate 500000 loopback on listen-only on one-shot on berr-reporting on presume-ack on cc-len8-dlc on
run loopback off listen-only off one-shot off berr-reporting off presume-ack off cc-len8-dlc off
run fd on
run restart-ms 100
run restart-ms 0
# A manual restart while down.
run restart
# Up: then settings are refused, restart is refused when not bus-off.
echo "CASE up"
ip link set can0 up; echo "RC $?"
run bitrate 250000
run loopback on
run restart-ms 100
run restart
ip link set can0 down
# restart-ms set, then manual restart while up.
run restart-ms 100
ip link set can0 up
run restart
ip link set can0 down
# Up without a bit timing: can1 never had one.
echo "CASE up-without-bittiming"
dmesg -c >/dev/null
err=$(ip link set can1 up 2>&1); echo "RC $?"; echo "MSG $err"
echo "DMESG $(dmesg | grep -i 'bit-timing' | tail -n 1)"
ip -details link show can1 | head -n 5
echo "DONE"

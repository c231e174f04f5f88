# SPDX-License-Identifier: GPL-2.0
# Sourced by prof-bindclose.sh and prof-frame.sh (guest side, from the
# tree's top): loads one CAN stack with can0 up, for a profile.
#   stack_load STACK: "mainline" (RCAN_KBUILD's can, can-raw, vcan echo=1),
#   "ours" (this tree's modules) or "ours:DIR" (the modules of another
#   build, laid out as in the tree); unloads whatever was loaded first.
#   Returns non-zero if a module does not load.
stack_unload() {
	ip link del can0 2>/dev/null
	for m in rcan_loop rcan_raw rcan_can rcan_pf can_raw vcan can_dev can; do
		rmmod $m 2>/dev/null
	done
}
stack_load() {
	local kb d m
	stack_unload
	case $1 in
	mainline)
		kb=$RCAN_KBUILD
		insmod $kb/net/can/can.ko && insmod $kb/net/can/can-raw.ko || return 1
		modinfo -F depends $kb/drivers/net/can/vcan.ko | grep -q "can.dev" &&
			insmod $kb/drivers/net/can/dev/can-dev.ko
		insmod $kb/drivers/net/can/vcan.ko echo=1 && ip link add dev can0 type vcan || return 1
		;;
	ours | ours:*)
		d=.
		[ "$1" = ours ] || d=${1#ours:}
		for m in net/can/rcan_pf net/can/rcan_can net/can/rcan_raw drivers/net/can/rcan_loop; do
			insmod $d/$m.ko || return 1
		done
		;;
	*) echo "unknown stack $1" >&2; return 1 ;;
	esac
	ip link set can0 up
}

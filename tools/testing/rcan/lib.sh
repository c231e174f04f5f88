# SPDX-License-Identifier: GPL-2.0
# Shared settings for the rcan test scripts. Sourced, not run.

RCAN_ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/../../.." && pwd)
RCAN_CACHE=${RCAN_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/rcan}
RCAN_KERNEL=${RCAN_KERNEL:-release}
RCAN_BINDGEN_VERSION=0.73.0
# Debian's linux-source-6.12; overridable for the front-door tests, which
# extract a small tarball of their own (the default is part of the cache key).
KERNEL_TARBALL=${KERNEL_TARBALL:-/usr/src/linux-source-6.12.tar.xz}

export PATH="$HOME/.cargo/bin:$PATH"

die() { echo "rcan: $*" >&2; exit 1; }
log() { echo "rcan: $*" >&2; }

# Directory of the extracted kernel source (shared by both variants).
rcan_ksrc() { echo "$RCAN_CACHE/src/linux-source-6.12"; }

# The config fragments of the selected variant, in merge order: base.config,
# then release.config or debug.config.
rcan_config_frags() {
	echo "$RCAN_ROOT/tools/testing/rcan/config/base.config $RCAN_ROOT/tools/testing/rcan/config/$RCAN_KERNEL.config"
}

# Cache key: everything that changes the kernel binary.
rcan_kernel_key() {
	local frags
	frags=$(rcan_config_frags)
	{
		ls -l "$KERNEL_TARBALL" 2>/dev/null | awk '{print $5}'
		cat $frags
		rustc --version
		bindgen --version 2>/dev/null
		clang --version | head -n 1
		echo "$RCAN_KERNEL"
	} | sha256sum | cut -c1-12
}

# Build directory (O=) of the selected kernel variant.
rcan_kbuild() { echo "$RCAN_CACHE/kernel/$RCAN_KERNEL-$(rcan_kernel_key)"; }

# QEMU's emulated SJA1000 cards on one virtual CAN bus, for the VM test
# suite: two Kvaser PCIcan (can0/can1 when only rcan_kvaser_pci is loaded),
# a PCM-3680I and a MIOe-3680 (two channels each). On a second bus, so the
# SJA1000 tests see none of its traffic: two CTU CAN FD PCI cards (two cores
# each; can0/can1 are the first card's when only rcan_ctucanfd_pci or
# mainline ctucanfd_pci is loaded, PCI order; the second card is the wire
# peer of ctucanfd_wire_peer_mainline, mainline's driver bound to it, and
# parked for every other test: rcan-vmtest sets its driver_override to a
# name no driver has when it starts).
RCAN_QEMU_CAN="-object can-bus,id=bus0 -device kvaser_pci,canbus=bus0 -device kvaser_pci,canbus=bus0 -device pcm3680_pci,canbus0=bus0,canbus1=bus0 -device mioe3680_pci,canbus0=bus0,canbus1=bus0 -object can-bus,id=bus1 -device ctucan_pci,canbus0=bus1,canbus1=bus1 -device ctucan_pci,canbus0=bus1,canbus1=bus1"

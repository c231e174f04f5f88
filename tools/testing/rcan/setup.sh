#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-2.0
# Install everything the build and the VM tests need. Idempotent; fast when
# all is present. Run as root (apt-get).
set -euo pipefail
. "$(dirname "$0")/lib.sh"

pkgs="linux-source-6.12 clang lld llvm libclang-dev flex bison bc libelf-dev
libssl-dev qemu-system-x86 can-utils busybox-static cpio kmod iproute2 make
tcpdump python3-can python3-pip stress-ng"
missing=""
for p in $pkgs; do
	dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "ok installed" ||
		missing="$missing $p"
done
if [ -n "$missing" ]; then
	log "installing:$missing"
	export DEBIAN_FRONTEND=noninteractive
	apt-get update -qq
	apt-get install -y -qq $missing >/dev/null
fi
# DKMS for make check's real DKMS build (tools/testing/rcan/tests/dkms.sh),
# without the distribution kernel's headers it recommends: it builds
# against the test kernel.
if ! dpkg-query -W -f='${Status}' dkms 2>/dev/null | grep -q "ok installed"; then
	log "installing: dkms"
	export DEBIAN_FRONTEND=noninteractive
	apt-get install -y -qq --no-install-recommends dkms >/dev/null ||
		{ apt-get update -qq && apt-get install -y -qq --no-install-recommends dkms >/dev/null; }
fi

# can-isotp and udsoncan (PyPI only, pure python) for the VM test
# isotp_python_uds, for the guest's /usr/bin/python3 (Debian's 3.11, whose
# python3-can comes from apt). Installed with Debian's pip (python3-pip;
# the pip on PATH may be another interpreter's) into a directory of the
# cache that the guest sees at the same path (vm-run.sh passes RCAN_CACHE
# in), not into the system's site-packages: nothing of Debian's is
# replaced and nothing needs --break-system-packages. The test puts it on
# sys.path. Exact versions; skipped when both are there.
pydir="$RCAN_CACHE/python3"
pypkgs="can_isotp-2.0.7 udsoncan-1.26.1"
pyok=1
for p in $pypkgs; do
	[ -d "$pydir/$p.dist-info" ] || pyok=0
done
if [ "$pyok" = 0 ]; then
	log "installing can-isotp 2.0.7, udsoncan 1.26.1 into $pydir"
	rm -rf "$pydir"
	/usr/bin/python3 -m pip install -q --disable-pip-version-check \
		--root-user-action=ignore --no-deps --only-binary=:all: \
		--target "$pydir" can-isotp==2.0.7 udsoncan==1.26.1
fi

command -v rustup >/dev/null || die "rustup not found"
rustup component list --installed 2>/dev/null | grep -q '^rust-src' ||
	rustup component add rust-src
rustup component list --installed 2>/dev/null | grep -q '^clippy' ||
	rustup component add clippy || log "clippy unavailable"
rustup component list --installed 2>/dev/null | grep -q '^rustfmt' ||
	rustup component add rustfmt || log "rustfmt unavailable"

if ! bindgen --version 2>/dev/null | grep -q "$RCAN_BINDGEN_VERSION"; then
	log "installing bindgen-cli $RCAN_BINDGEN_VERSION"
	cargo install --locked bindgen-cli --version "$RCAN_BINDGEN_VERSION"
fi
log "setup complete"

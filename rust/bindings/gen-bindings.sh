#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-2.0
# Generate rust/bindings/bindings_generated.rs for the kernel in $1 (its O=
# build directory), reusing the exact clang flags the kernel saved for its own
# bindings, so layouts match the running kernel. Never committed.
set -euo pipefail
# An empty KDIR means the kernel build failed (or was not given): say so here
# rather than fail later on an unrelated path.
if [ $# != 2 ] || [ -z "$1" ] || [ -z "$2" ]; then
	echo "gen-bindings: usage: gen-bindings.sh KDIR OUT, KDIR the kernel's (non-empty) build directory" >&2
	exit 2
fi
kbuild=$1
out=$2
[ -d "$kbuild" ] || { echo "gen-bindings: kernel build directory $kbuild not found" >&2; exit 1; }
here=$(cd "$(dirname "$0")" && pwd)
saved="$kbuild/rust/bindings/.bindings_generated.rs.cmd"
[ -f "$saved" ] || { echo "gen-bindings: $saved missing (kernel built without CONFIG_RUST?)" >&2; exit 1; }
ksrc=$(sed -n 's/^savedcmd_.* := bindgen \([^ ]*\)\/rust\/bindings\/bindings_helper.h .*/\1/p' "$saved")
# Clang arguments: everything after " -- ", minus the depfile option.
# Drop the depfile option, the kernel's own module-name defines (re-added
# below, unquoted) and the sed post-processing step that follows ';'.
cflags=$(sed -n 's/^savedcmd_[^ ]* := bindgen .* -- \(.*\)$/\1/p' "$saved" |
	sed -e 's/;.*$//' -e 's/-Wp,-MMD,[^ ]*//' -e "s/-DKBUILD_[A-Z]*='[^']*'//g" \
	    -e 's/-D__KBUILD_MODNAME=[^ ]*//')
params=$(grep -Ev '^#|^$' "$ksrc/rust/bindgen_parameters")
allow_fn='(ioread|iowrite|sock|sk|skb|__skb|kfree_skb|consume_skb|dev|__dev|netdev|netif|register_pernet|unregister_pernet|alloc_netdev|free_netdev|register_netdev|unregister_netdev|register_netdevice|unregister_netdevice|datagram|proto|synchronize_rcu|rcu_barrier|call_rcu|try_module_get|module_put|get_random|rtnl|__rtnl|pci|__pci|request_threaded_irq|free_irq|hrtimer|ktime|rcan|_copy_from_iter|iov_iter_revert|put_cmsg|kfree|__kmalloc|_printk|ether|can|napi|__napi|_raw_spin|_copy_to_iter|__sock_recv_cmsgs)_?.*'
tmp=$(mktemp)
# shellcheck disable=SC2086
(cd "$kbuild" && bindgen "$here/rcan_bindings.h" $params \
	--rust-target 1.68 --use-core --with-derive-default --ctypes-prefix ffi \
	--no-layout-tests --no-debug '.*' --enable-function-attribute-detection \
	--allowlist-function "$allow_fn" \
	--allowlist-type '(napi_struct|net_device_flags|sock_type|netdev_priv_flags|sock|socket|sk_buff|net_device|proto|proto_ops|net_proto_family|packet_type|can_frame|can_skb_priv|notifier_block|netdev_notifier_info|msghdr|sockaddr|hrtimer|pci_dev|pci_driver|pci_device_id|callback_head|rtnl_link_stats64|ifreq|pernet_operations)' \
	--allowlist-var '(AF|PF|SOCK|SOL|SO|MSG|IFF|ARPHRD|ETH_P|CAN|NETDEV|NET_RX|NET_XMIT|NETDEV_TX|PACKET|CHECKSUM|E[A-Z0-9]+|HRTIMER|CLOCK|IRQF|SIOC|NOTIFY|SOCK_RCU|RCAN|NET_NAME|CONFIG_PROVE|__GFP|___GFP)_?.*' \
	--allowlist-var init_net \
	-o "$tmp" -- $cflags -DMODULE '-DKBUILD_MODNAME="rcan"' \
	'-DKBUILD_BASENAME="rcan"' -D__KBUILD_MODNAME=kmod_rcan)
# Constants the kernel hides behind RUST_CONST_HELPER_ names get their
# plain names, as in the kernel's own bindings.
sed -Ei 's/pub const RUST_CONST_HELPER_([a-zA-Z0-9_]*)/pub const \1/g' "$tmp"
# Keep the old file (and its mtime) when nothing changed, so Kbuild does
# not rebuild every module.
if cmp -s "$tmp" "$out"; then
	rm -f "$tmp"
else
	mv "$tmp" "$out"
fi

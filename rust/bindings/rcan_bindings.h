/* SPDX-License-Identifier: GPL-2.0 */
/*
 * Kernel headers the rcan glue needs beyond what the 6.12 `kernel` crate
 * exposes. bindgen turns this into rust/bindings/bindings_generated.rs at
 * build time (scripts/gen-bindings.sh), with the kernel's own flags.
 */
#include <linux/can.h>
#include <linux/can/skb.h>
#include <linux/hrtimer.h>
#include <linux/if_arp.h>
#include <linux/if_ether.h>
#include <linux/interrupt.h>
#include <linux/ip.h>
#include <linux/module.h>
#include <linux/net.h>
#include <linux/netdevice.h>
#include <linux/notifier.h>
#include <linux/pci.h>
#include <linux/random.h>
#include <linux/rcupdate.h>
#include <linux/rtnetlink.h>
#include <linux/skbuff.h>
#include <linux/socket.h>
#include <linux/sockios.h>
#include <linux/wait.h>
#include <net/net_namespace.h>
#include <net/sock.h>
#include "../helpers/rcan_helpers.h"

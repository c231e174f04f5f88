// SPDX-License-Identifier: GPL-2.0
/*
 * C side of rcan_dsor: module parameters (read through
 * rust/glue/params.rs) and the module's private copy of the helpers.
 * params.rs validates the parameters at load and refuses bad ones with
 * EINVAL.
 */
#include <linux/moduleparam.h>
#include <linux/netdevice.h>
#include <linux/string.h>

#include "../../../rust/helpers/rcan_helpers.c"
#include "../../../rust/helpers/rcan_params.h"

#ifndef RCAN_DSOR_NODE_ID
#define RCAN_DSOR_NODE_ID 0x00
#endif

static unsigned int node = RCAN_DSOR_NODE_ID;
module_param(node, uint, 0444);
MODULE_PARM_DESC(node, "DSOR node id of this host, 0x00-0x7f (CONFIG_RCAN_DSOR_NODE_ID, thesis CONFIG_DSOR_NODE_ID)");

static char *ifname = "can0";
module_param(ifname, charp, 0444);
MODULE_PARM_DESC(ifname, "CAN interface that carries DSOR, 1-15 bytes (default can0)");

static unsigned int ack_timeout_ms = 100;
module_param(ack_timeout_ms, uint, 0444);
MODULE_PARM_DESC(ack_timeout_ms, "retransmit a frame after this many ms without its ack (10-60000, default 100)");

static unsigned int max_retx = 10;
module_param(max_retx, uint, 0444);
MODULE_PARM_DESC(max_retx, "retransmissions of one frame before the message fails (0-100, default 10)");

static unsigned int reasm_timeout_ms = 2000;
module_param(reasm_timeout_ms, uint, 0444);
MODULE_PARM_DESC(reasm_timeout_ms, "free a partial incoming message after this many ms of silence; must exceed ack_timeout_ms * (max_retx + 1) (default 2000)");

static unsigned int max_len = 65535;
module_param(max_len, uint, 0444);
MODULE_PARM_DESC(max_len, "longest message sent or accepted, bytes (1-65535, default 65535)");

static unsigned int max_per_peer = 16;
module_param(max_per_peer, uint, 0444);
MODULE_PARM_DESC(max_per_peer, "concurrent incoming messages per source node (1-64, default 16)");

static unsigned int max_bytes = 1048576;
module_param(max_bytes, uint, 0444);
MODULE_PARM_DESC(max_bytes, "reassembly memory for all incoming messages, bytes (max_len-4194240, default 1 MiB)");

static char *udp_saddr = "192.168.1.1";
module_param(udp_saddr, charp, 0444);
MODULE_PARM_DESC(udp_saddr, "IPv4 source address of UDP datagrams received over DSOR (default 192.168.1.1, as the thesis)");

static unsigned int udp_prio = 0x80;
module_param(udp_prio, uint, 0444);
MODULE_PARM_DESC(udp_prio, "bus priority of UDP/IP messages, 0x00-0xff (default 0x80)");

static bool canip = true;
module_param(canip, bool, 0444);
MODULE_PARM_DESC(canip, "create the canip0 UDP/IP device (default yes)");

/* Parameter numbers shared with params.rs (the PARAM_* consts). */
u64 rcan_module_param(unsigned int which, unsigned int idx)
{
	switch (which) {
	case 0: return READ_ONCE(node);
	case 1: return READ_ONCE(ack_timeout_ms);
	case 2: return READ_ONCE(max_retx);
	case 3: return READ_ONCE(reasm_timeout_ms);
	case 4: return READ_ONCE(max_len);
	case 5: return READ_ONCE(max_per_peer);
	case 6: return READ_ONCE(max_bytes);
	case 7: return READ_ONCE(udp_prio);
	case 8: return READ_ONCE(canip);
	default: return 0;
	}
}

/*
 * String parameters: 9 ifname, 10 udp_saddr. Copies at most len - 1
 * bytes; returns strlen(s) so that the Rust side refuses a longer
 * parameter instead of using a truncated copy.
 */
size_t rcan_module_param_str(unsigned int which, char *buf, size_t len)
{
	const char *s;

	switch (which) {
	case 9: s = READ_ONCE(ifname); break;
	case 10: s = READ_ONCE(udp_saddr); break;
	default: s = NULL; break;
	}
	if (len)
		memset(buf, 0, len);
	if (!s)
		return 0;
	if (len)
		strscpy(buf, s, len);
	return strlen(s);
}

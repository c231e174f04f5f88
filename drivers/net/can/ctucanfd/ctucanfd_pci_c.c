// SPDX-License-Identifier: GPL-2.0
/*
 * C side of rcan_ctucanfd_pci: its module parameters (6.12's Rust module!
 * macro has none; read through rust/glue/params.rs) and the module's
 * private copy of the helpers.
 */
#include <linux/kernel.h>
#include <linux/moduleparam.h>

#include "../../../../rust/helpers/rcan_helpers.c"
#include "../../../../rust/helpers/rcan_params.h"

/*
 * The bit timing every core starts with (ctucanfd.rst): read-only, checked
 * at module init.
 */
static unsigned int bitrate;
module_param(bitrate, uint, 0444);
MODULE_PARM_DESC(bitrate, "Initial nominal bit rate of every core in bit/s (default 0: none; ip link set canX type can bitrate replaces it)");

static unsigned int dbitrate;
module_param(dbitrate, uint, 0444);
MODULE_PARM_DESC(dbitrate, "Initial CAN FD data bit rate in bit/s (with bitrate, at least its value; default 0: none; FD is switched on with ip link set canX mtu 72)");

/* Parameter numbers shared with ctucanfd_pci.rs: 0 bitrate, 1 dbitrate. */
u64 rcan_module_param(unsigned int which, unsigned int idx)
{
	switch (which) {
	case 0: return READ_ONCE(bitrate);
	case 1: return READ_ONCE(dbitrate);
	default: return 0;
	}
}

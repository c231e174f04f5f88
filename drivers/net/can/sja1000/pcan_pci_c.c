// SPDX-License-Identifier: GPL-2.0
/*
 * C side of rcan_pcan_pci: bit timing module parameters (6.12's Rust
 * module! macro has none) and the module's private copy of the helpers.
 */
#include <linux/kernel.h>
#include <linux/moduleparam.h>

#include "../../../../rust/helpers/rcan_helpers.c"
#include "../../../../rust/helpers/rcan_params.h"

#include "btr_params.h"

/* Parameter numbers: the SJA1000 core's BTR0/BTR1 (sja1000.rs). */
u64 rcan_module_param(unsigned int which, unsigned int idx)
{
	switch (which) {
	RCAN_SJA1000_BTR_CASES;
	default: return 0;
	}
}

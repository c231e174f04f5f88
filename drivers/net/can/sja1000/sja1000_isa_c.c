// SPDX-License-Identifier: GPL-2.0
/*
 * C side of rcan_sja1000_isa: module parameters (6.12's Rust module!
 * macro has none) and the module's private copy of the helpers.
 */
#include <linux/kernel.h>
#include <linux/moduleparam.h>

#include "../../../../rust/helpers/rcan_helpers.c"
#include "../../../../rust/helpers/rcan_params.h"

#define RCAN_ISA_MAX_BOARDS 8

static unsigned long iomem[RCAN_ISA_MAX_BOARDS];
static unsigned int n_iomem;
module_param_hw_array(iomem, ulong, iomem, &n_iomem, 0444);
MODULE_PARM_DESC(iomem, "Physical addresses of the cards' SJA1000s (up to 8)");

static int irq[RCAN_ISA_MAX_BOARDS];
static unsigned int n_irq;
module_param_hw_array(irq, int, irq, &n_irq, 0444);
MODULE_PARM_DESC(irq, "Interrupt line of each card (0 or missing: autoprobe)");

#include "btr_params.h"

/*
 * Parameter numbers (sja1000_isa.rs): 0/1 the SJA1000 core's BTR0/BTR1,
 * 2 the number of boards given with iomem=, 3 board idx's address, 4 its
 * configured interrupt line (0: autoprobe).
 */
u64 rcan_module_param(unsigned int which, unsigned int idx)
{
	unsigned int n = min_t(unsigned int, READ_ONCE(n_iomem), RCAN_ISA_MAX_BOARDS);

	switch (which) {
	RCAN_SJA1000_BTR_CASES;
	case 2: return n;
	case 3: return idx < n ? READ_ONCE(iomem[idx]) : 0;
	case 4:
		if (idx >= RCAN_ISA_MAX_BOARDS || idx >= READ_ONCE(n_irq))
			return 0;
		return (u64)(s64)READ_ONCE(irq[idx]);
	default: return 0;
	}
}

// SPDX-License-Identifier: GPL-2.0
/*
 * C side of rcan_ctucanfd_pci: the module's private copy of the helpers.
 * The module has no parameters.
 */
#include <linux/kernel.h>
#include <linux/moduleparam.h>

#include "../../../../rust/helpers/rcan_helpers.c"
#include "../../../../rust/helpers/rcan_params.h"

u64 rcan_module_param(unsigned int which, unsigned int idx)
{
	return 0;
}

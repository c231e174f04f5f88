// SPDX-License-Identifier: GPL-2.0
/*
 * C side of rcan_loop: module parameters (6.12's Rust module! macro has
 * none) and the module's private copy of the helpers. Validation of the
 * values is Rust's (rcan_loop_param_record, which also records a valid value
 * for the transmit path); this file only parses and stores.
 */
#include <linux/kernel.h>
#include <linux/moduleparam.h>

#include "../../../rust/helpers/rcan_helpers.c"
#include "../../../rust/helpers/rcan_params.h"

bool rcan_loop_param_record(int which, unsigned int val);

unsigned int rcan_loop_count = 1;
unsigned int rcan_loop_verbose;
unsigned int rcan_loop_droprate;

static int rcan_loop_param_set(const char *val, const struct kernel_param *kp,
			       int which)
{
	unsigned int v;
	int ret = kstrtouint(val, 0, &v);

	if (ret)
		return ret;
	if (!rcan_loop_param_record(which, v))
		return -EINVAL;
	WRITE_ONCE(*(unsigned int *)kp->arg, v);
	return 0;
}

static int rcan_loop_set_count(const char *val, const struct kernel_param *kp)
{
	return rcan_loop_param_set(val, kp, 0);
}

static int rcan_loop_set_verbose(const char *val, const struct kernel_param *kp)
{
	return rcan_loop_param_set(val, kp, 1);
}

static int rcan_loop_set_droprate(const char *val, const struct kernel_param *kp)
{
	return rcan_loop_param_set(val, kp, 2);
}

static const struct kernel_param_ops rcan_loop_count_ops = {
	.set = rcan_loop_set_count,
	.get = param_get_uint,
};

static const struct kernel_param_ops rcan_loop_verbose_ops = {
	.set = rcan_loop_set_verbose,
	.get = param_get_uint,
};

static const struct kernel_param_ops rcan_loop_droprate_ops = {
	.set = rcan_loop_set_droprate,
	.get = param_get_uint,
};

module_param_cb(count, &rcan_loop_count_ops, &rcan_loop_count, 0444);
MODULE_PARM_DESC(count, "number of loopback devices can0.. (1-16, default 1)");
module_param_cb(verbose, &rcan_loop_verbose_ops, &rcan_loop_verbose, 0644);
MODULE_PARM_DESC(verbose, "log every frame with the device name (0/1)");
module_param_cb(droprate, &rcan_loop_droprate_ops, &rcan_loop_droprate, 0644);
MODULE_PARM_DESC(droprate, "percentage of frames dropped to simulate loss (0-100)");

/* Parameter numbers shared with canloop.rs. */
u64 rcan_module_param(unsigned int which, unsigned int idx)
{
	switch (which) {
	case 0: return READ_ONCE(rcan_loop_count);
	case 1: return READ_ONCE(rcan_loop_verbose);
	case 2: return READ_ONCE(rcan_loop_droprate);
	default: return 0;
	}
}

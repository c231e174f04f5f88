// SPDX-License-Identifier: GPL-2.0
/*
 * C side of rcan_rtime: parameters vehicle, dev and timeout_ms, and the
 * helpers.
 */
#include "ticker_params.c"

static int rcan_rtime_set_timeout(const char *val, const struct kernel_param *kp)
{
	return rcan_timesvc_set_uint(val, RCAN_TIMESVC_TIMEOUT_MS);
}

static int rcan_rtime_get_timeout(char *buf, const struct kernel_param *kp)
{
	return sysfs_emit(buf, "%u\n",
			  rcan_timesvc_param_get(RCAN_TIMESVC_TIMEOUT_MS));
}

static const struct kernel_param_ops rcan_rtime_timeout_ops = {
	.set = rcan_rtime_set_timeout,
	.get = rcan_rtime_get_timeout,
};

module_param_cb(timeout_ms, &rcan_rtime_timeout_ops, NULL, 0644);
MODULE_PARM_DESC(timeout_ms,
		 "silence of the other time source, in ms, after which this service takes over (1200-60000, default 2500)");

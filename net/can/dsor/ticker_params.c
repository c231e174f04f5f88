// SPDX-License-Identifier: GPL-2.0
/*
 * Module parameters shared by rcan_time and rcan_rtime, included by their
 * C files (time_c.c, rtime_c.c), together with the module's private copy
 * of the helpers. 6.12's Rust module! macro has no parameters; this file
 * only parses, and hands each value to Rust (ticker.rs), which validates
 * and stores it: a refused value fails the load (or the sysfs write) with
 * EINVAL.
 */
#include <linux/kernel.h>
#include <linux/moduleparam.h>
#include <linux/string.h>
#include <linux/sysfs.h>

#include "../../../rust/helpers/rcan_helpers.c"

/* Parameter numbers shared with ticker.rs. */
#define RCAN_TIMESVC_VEHICLE	0
#define RCAN_TIMESVC_TIMEOUT_MS	1

/* An interface name passed by value: NUL-terminated and NUL-padded. */
struct rcan_ifname {
	char name[IFNAMSIZ];
};

bool rcan_timesvc_param_set(unsigned int which, unsigned int val);
unsigned int rcan_timesvc_param_get(unsigned int which);
bool rcan_timesvc_dev_set(struct rcan_ifname name);
struct rcan_ifname rcan_timesvc_dev_get(void);

static int rcan_timesvc_set_uint(const char *val, unsigned int which)
{
	unsigned int v;
	int ret = kstrtouint(val, 0, &v);

	if (ret)
		return ret;
	return rcan_timesvc_param_set(which, v) ? 0 : -EINVAL;
}

static int rcan_timesvc_set_vehicle(const char *val,
				    const struct kernel_param *kp)
{
	return rcan_timesvc_set_uint(val, RCAN_TIMESVC_VEHICLE);
}

static int rcan_timesvc_get_vehicle(char *buf, const struct kernel_param *kp)
{
	return sysfs_emit(buf, "0x%02x\n",
			  rcan_timesvc_param_get(RCAN_TIMESVC_VEHICLE));
}

static const struct kernel_param_ops rcan_timesvc_vehicle_ops = {
	.set = rcan_timesvc_set_vehicle,
	.get = rcan_timesvc_get_vehicle,
};

static int rcan_timesvc_set_dev(const char *val, const struct kernel_param *kp)
{
	struct rcan_ifname n = {};
	size_t len = strcspn(val, "\n");

	if (len >= sizeof(n.name))
		return -EINVAL;
	memcpy(n.name, val, len);
	return rcan_timesvc_dev_set(n) ? 0 : -EINVAL;
}

static int rcan_timesvc_get_dev(char *buf, const struct kernel_param *kp)
{
	struct rcan_ifname n = rcan_timesvc_dev_get();

	return sysfs_emit(buf, "%.*s\n", (int)sizeof(n.name), n.name);
}

static const struct kernel_param_ops rcan_timesvc_dev_ops = {
	.set = rcan_timesvc_set_dev,
	.get = rcan_timesvc_get_dev,
};

module_param_cb(vehicle, &rcan_timesvc_vehicle_ops, NULL, 0444);
MODULE_PARM_DESC(vehicle,
		 "DSOR vehicle identifier, the time frame's standard CAN id (0x00-0xf0, bits 4-7 only; default 0xc0)");
module_param_cb(dev, &rcan_timesvc_dev_ops, NULL, 0444);
MODULE_PARM_DESC(dev, "CAN interface name, looked up at every send (default can0)");

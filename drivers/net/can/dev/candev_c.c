// SPDX-License-Identifier: GPL-2.0
/*
 * C side of rcan_dev: the "can" rtnl_link_ops table and its attribute
 * policy (data the kernel reads; C designated initialisers for a struct
 * full of unions and bitfields), the netlink helpers that are inline in
 * the kernel headers, and the export of the ops table, which every CAN
 * driver module's devices point to (dev->rtnl_link_ops). The callbacks are
 * Rust: rust/glue/can/link.rs.
 */
#include <linux/export.h>
#include <linux/can/netlink.h>
#include <net/netlink.h>
#include <net/rtnetlink.h>
#include <linux/moduleparam.h>

#include "../../../../rust/helpers/rcan_helpers.c"
#include "../../../../rust/helpers/rcan_params.h"

/*
 * rtnl_link=N loads the module without registering the "can" link kind,
 * so that mainline's can-dev (and its drivers) can hold the kind in the
 * same boot; rcan's devices then take their bit timing from their
 * drivers' module parameters (can-dev.rst, "Beside mainline's can-dev").
 */
static bool rtnl_link = true;
module_param(rtnl_link, bool, 0444);
MODULE_PARM_DESC(rtnl_link, "Register the rtnetlink link kind \"can\" (default Y; N: leave it to mainline's can-dev, ip link set ... type can is then refused on rcan devices)");

/* Parameter numbers shared with candev.rs: 0 rtnl_link. */
u64 rcan_module_param(unsigned int which, unsigned int idx)
{
	switch (which) {
	case 0: return READ_ONCE(rtnl_link);
	default: return 0;
	}
}

int rcan_can_validate(struct nlattr *tb[], struct nlattr *data[],
		      struct netlink_ext_ack *extack);
int rcan_can_changelink(struct net_device *dev, struct nlattr *tb[],
			struct nlattr *data[], struct netlink_ext_ack *extack);
size_t rcan_can_get_size(const struct net_device *dev);
int rcan_can_fill_info(struct sk_buff *skb, const struct net_device *dev);
size_t rcan_can_get_xstats_size(const struct net_device *dev);
int rcan_can_fill_xstats(struct sk_buff *skb, const struct net_device *dev);

/*
 * The attributes a CAN controller is configured with and their sizes
 * (<linux/can/netlink.h>), CAN FD's included: the data bit timing, and
 * TDC, which the device layer refuses (no controller of ours has it).
 */
static const struct nla_policy rcan_can_policy[IFLA_CAN_MAX + 1] = {
	[IFLA_CAN_STATE] = { .type = NLA_U32 },
	[IFLA_CAN_CTRLMODE] = { .len = sizeof(struct can_ctrlmode) },
	[IFLA_CAN_RESTART_MS] = { .type = NLA_U32 },
	[IFLA_CAN_RESTART] = { .type = NLA_U32 },
	[IFLA_CAN_BITTIMING] = { .len = sizeof(struct can_bittiming) },
	[IFLA_CAN_BITTIMING_CONST] = { .len = sizeof(struct can_bittiming_const) },
	[IFLA_CAN_CLOCK] = { .len = sizeof(struct can_clock) },
	[IFLA_CAN_BERR_COUNTER] = { .len = sizeof(struct can_berr_counter) },
	[IFLA_CAN_DATA_BITTIMING] = { .len = sizeof(struct can_bittiming) },
	[IFLA_CAN_DATA_BITTIMING_CONST] = { .len = sizeof(struct can_bittiming_const) },
	[IFLA_CAN_TERMINATION] = { .type = NLA_U16 },
	[IFLA_CAN_TDC] = { .type = NLA_NESTED },
	[IFLA_CAN_CTRLMODE_EXT] = { .type = NLA_NESTED },
};

/* Filled in by rcan_can_link_register() (rtnl_link_register links it). */
struct rtnl_link_ops rcan_can_link_ops = {
	.kind = "can",
	/* As mainline's can_link_ops: a controller in a namespace that is
	 * deleted comes back to init_net instead of being unregistered
	 * under its driver (which still owns it). */
	.netns_refund = true,
	.maxtype = IFLA_CAN_MAX,
	.policy = rcan_can_policy,
	.validate = rcan_can_validate,
	.changelink = rcan_can_changelink,
	.get_size = rcan_can_get_size,
	.fill_info = rcan_can_fill_info,
	.get_xstats_size = rcan_can_get_xstats_size,
	.fill_xstats = rcan_can_fill_xstats,
};
EXPORT_SYMBOL_GPL(rcan_can_link_ops);

int rcan_can_link_register(void);
int rcan_can_link_register(void)
{
	return rtnl_link_register(&rcan_can_link_ops);
}

void rcan_can_link_unregister(void);
void rcan_can_link_unregister(void)
{
	rtnl_link_unregister(&rcan_can_link_ops);
}

/* Payload and its length of an attribute the policy has checked. */
const void *rcan_nla_data(const struct nlattr *nla, int *len);
const void *rcan_nla_data(const struct nlattr *nla, int *len)
{
	*len = nla_len(nla);
	return nla_data(nla);
}

/* nla_put() of the kernel, and a nest holding one u32. */
int rcan_nla_put(struct sk_buff *skb, int type, int len, const void *data);
int rcan_nla_put(struct sk_buff *skb, int type, int len, const void *data)
{
	return nla_put(skb, type, len, data);
}

int rcan_nla_put_nested_u32(struct sk_buff *skb, int outer, int inner, u32 val);
int rcan_nla_put_nested_u32(struct sk_buff *skb, int outer, int inner, u32 val)
{
	struct nlattr *nest = nla_nest_start(skb, outer);

	if (!nest)
		return -EMSGSIZE;
	if (nla_put_u32(skb, inner, val)) {
		nla_nest_cancel(skb, nest);
		return -EMSGSIZE;
	}
	nla_nest_end(skb, nest);
	return 0;
}

/* nla_total_size() */
size_t rcan_nla_total_size(int payload);
size_t rcan_nla_total_size(int payload)
{
	return nla_total_size(payload);
}

/*
 * The extended-ack text of a request (an error's, or with success a
 * warning's, which ip prints as "Warning: ..."), copied into the ack.
 */
void rcan_extack_msg(struct netlink_ext_ack *extack, const char *msg);
void rcan_extack_msg(struct netlink_ext_ack *extack, const char *msg)
{
	NL_SET_ERR_MSG_FMT(extack, "%s", msg);
}

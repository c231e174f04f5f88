// SPDX-License-Identifier: GPL-2.0
/*
 * Out-of-line wrappers for inline kernel functions; see rcan_helpers.h.
 * Included by one small C file per module (e.g. net/can/pf_can_helpers.c)
 * so that every module has its own private copy.
 */
#include <linux/can.h>
#include <linux/capability.h>
#include <linux/can/skb.h>
#include <linux/if_arp.h>
#include <linux/ip.h>
#include <linux/delay.h>
#include <linux/errqueue.h>
#include <linux/interrupt.h>
#include <linux/io.h>
#include <linux/kmemleak.h>
#include <linux/kmod.h>
#include <linux/ioport.h>
#include <linux/module.h>
#include <linux/mutex.h>
#include <linux/netdevice.h>
#include <linux/random.h>
#include <linux/pci.h>
#include <linux/percpu.h>
#include <linux/rcupdate.h>
#include <linux/slab.h>
#include <linux/spinlock.h>
#include <linux/rtnetlink.h>
#include <linux/skbuff.h>
#include <linux/sockptr.h>
#include <linux/uaccess.h>
#include <linux/wait.h>
#include <linux/workqueue.h>
#include <net/net_namespace.h>
#include <net/netns/generic.h>
#include <net/sock.h>

#include "rcan_helpers.h"

void rcan_rcu_read_lock(void)
{
	rcu_read_lock();
}

void rcan_rcu_read_unlock(void)
{
	rcu_read_unlock();
}

void rcan_mutex_lock(struct mutex *lock)
{
	mutex_lock(lock);
}

void rcan_mutex_unlock(struct mutex *lock)
{
	mutex_unlock(lock);
}

void rcan_assert_rtnl(void)
{
	ASSERT_RTNL();
}

struct sk_buff *rcan_alloc_skb(unsigned int size, gfp_t gfp)
{
	return alloc_skb(size, gfp);
}

void rcan_kfree_skb(struct sk_buff *skb)
{
	kfree_skb(skb);
}

/* Frees @skb as dropped from any context, interrupts off included: in
 * hardirq or with interrupts disabled the free is deferred to the
 * NET_TX softirq (dev_kfree_skb_any), so no destructor runs there.
 */
void rcan_dev_kfree_skb_any(struct sk_buff *skb)
{
	dev_kfree_skb_any(skb);
}

/* The same, freed as consumed (not a drop). */
void rcan_dev_consume_skb_any(struct sk_buff *skb)
{
	dev_consume_skb_any(skb);
}

void rcan_consume_skb(struct sk_buff *skb)
{
	consume_skb(skb);
}

void rcan_skb_reset_headers(struct sk_buff *skb)
{
	skb_reset_mac_header(skb);
	skb_reset_network_header(skb);
	skb_reset_transport_header(skb);
}

void rcan_skb_stamp_if_unset(struct sk_buff *skb)
{
	if (!skb->tstamp)
		__net_timestamp(skb);
}

/* Whether a packet socket taps @dev (or every device). */
bool rcan_dev_nit_active(struct net_device *dev)
{
	return dev_nit_active(dev);
}

/* The CAN marks of an skb (protocol, pkt_type, CHECKSUM_UNNECESSARY,
 * headers reset) are written in Rust: Skb::set_can_tx and Skb::set_can_rx
 * in rust/glue/skb.rs.
 */

/* Mainline can_skb_headroom_valid (include/linux/can/skb.h) for a classic
 * CAN frame about to be sent by @dev: false if there is no room for struct
 * can_skb_priv. An skb written through a packet socket (CHECKSUM_NONE:
 * af_packet sets none of the CAN fields) gets them here, including the
 * echo request on an IFF_ECHO device, so local CAN sockets see it as
 * mainline's do.
 */
bool rcan_can_skb_tx_prepare(struct sk_buff *skb, struct net_device *dev)
{
	if (skb_headroom(skb) < sizeof(struct can_skb_priv))
		return false;
	if (skb->ip_summed == CHECKSUM_NONE) {
		can_skb_prv(skb)->ifindex = dev->ifindex;
		can_skb_prv(skb)->skbcnt = 0;
		skb->ip_summed = CHECKSUM_UNNECESSARY;
		skb->pkt_type = (dev->flags & IFF_ECHO) ? PACKET_LOOPBACK : PACKET_HOST;
		skb_reset_mac_header(skb);
		skb_reset_network_header(skb);
		skb_reset_transport_header(skb);
	}
	return true;
}

/* A clone of @skb that keeps its sending socket (mainline can_send's echo). */
struct sk_buff *rcan_skb_clone_owned(struct sk_buff *skb, gfp_t gfp)
{
	struct sk_buff *n = skb_clone(skb, gfp);

	if (n)
		can_skb_set_owner(n, skb->sk);
	return n;
}

/* skb_unshare for a writer: @skb itself if it is neither shared nor
 * cloned, else a private copy (keeping the sending socket, as
 * can_skb_set_owner) with @skb released, or NULL without memory (@skb
 * freed). Takes and returns one reference.
 */
struct sk_buff *rcan_skb_unshare(struct sk_buff *skb, gfp_t gfp)
{
	struct sk_buff *n;

	if (!skb_shared(skb) && !skb_cloned(skb))
		return skb;
	n = skb_copy(skb, gfp);
	if (!n) {
		kfree_skb(skb);
		return NULL;
	}
	if (skb->sk)
		can_skb_set_owner(n, skb->sk);
	consume_skb(skb);
	return n;
}

int rcan_skb_copy_datagram_msg(const struct sk_buff *skb, int offset,
			       struct msghdr *msg, int size)
{
	return skb_copy_datagram_msg(skb, offset, msg, size);
}

void rcan_lock_sock(struct sock *sk)
{
	lock_sock(sk);
}

void rcan_sock_hold(struct sock *sk)
{
	sock_hold(sk);
}

void rcan_sock_put(struct sock *sk)
{
	sock_put(sk);
}

void rcan_sock_orphan(struct sock *sk)
{
	sock_orphan(sk);
}

void rcan_sk_purge_queues(struct sock *sk)
{
	skb_queue_purge(&sk->sk_receive_queue);
	skb_queue_purge(&sk->sk_error_queue);
}

void rcan_release_sock(struct sock *sk)
{
	release_sock(sk);
}

struct net *rcan_sock_net(const struct sock *sk)
{
	return sock_net(sk);
}

void rcan_netif_start_queue(struct net_device *dev)
{
	netif_start_queue(dev);
}

void rcan_netif_stop_queue(struct net_device *dev)
{
	netif_stop_queue(dev);
}

void rcan_dev_hold(struct net_device *dev)
{
	dev_hold(dev);
}

void rcan_dev_put(struct net_device *dev)
{
	dev_put(dev);
}

struct net_device *rcan_dev_get_by_name(struct net *net, const char *name)
{
	return dev_get_by_name(net, name);
}

struct net *rcan_init_net(void)
{
	return &init_net;
}

void *rcan_net_generic(const struct net *net, unsigned int id)
{
	return net_generic(net, id);
}

/*
 * The CAN device of @net with the smallest ifindex above @after_ifindex, with a
 * reference held, or NULL. Lets Rust walk the device list without holding
 * the RCU read lock across sleeping calls.
 */
struct net_device *rcan_next_can_dev(struct net *net, int after_ifindex)
{
	struct net_device *dev, *best = NULL;

	rcu_read_lock();
	for_each_netdev_rcu(net, dev) {
		if (dev->type != ARPHRD_CAN || dev->ifindex <= after_ifindex)
			continue;
		if (!best || dev->ifindex < best->ifindex)
			best = dev;
	}
	if (best)
		dev_hold(best);
	rcu_read_unlock();
	return best;
}

struct net_device *rcan_netdev_notifier_dev(void *info)
{
	return netdev_notifier_info_to_dev(info);
}

bool rcan_try_module_get(struct module *mod)
{
	return try_module_get(mod);
}

void rcan_module_put(struct module *mod)
{
	module_put(mod);
}

void rcan_kmemleak_not_leak(const void *ptr)
{
	kmemleak_not_leak(ptr);
}

void rcan_init_work(struct work_struct *work, work_func_t func)
{
	INIT_WORK(work, func);
}

bool rcan_schedule_work(struct work_struct *work)
{
	return schedule_work(work);
}

bool rcan_flush_work(struct work_struct *work)
{
	return flush_work(work);
}

bool rcan_may_sleep(void)
{
	/* Without CONFIG_PREEMPT_COUNT preemptible() is always false: the
	 * caller then takes the path that never sleeps. */
	return preemptible() && !rcu_preempt_depth();
}

int rcan_request_module(const char *name)
{
	return request_module("%s", name);
}

u32 rcan_get_random_u32(void)
{
	return get_random_u32();
}

void rcan_sk_report_error(struct sock *sk, int err)
{
	WRITE_ONCE(sk->sk_err, err);
	if (!sock_flag(sk, SOCK_DEAD))
		sk_error_report(sk);
}

/*
 * Wakes whoever polls or sleeps on the socket for EPOLLOUT: a protocol
 * whose writability is its own state (Proto::writable), not send-buffer
 * space, calls it when that state changes. Any context.
 */
void rcan_sk_wake_writers(struct sock *sk)
{
	struct socket_wq *wq;

	rcu_read_lock();
	wq = rcu_dereference(sk->sk_wq);
	if (skwq_has_sleeper(wq))
		wake_up_interruptible_poll(&wq->wait, EPOLLOUT | EPOLLWRNORM | EPOLLWRBAND);
	rcu_read_unlock();
}

int rcan_copy_from_sockptr(void *dst, sockptr_t src, size_t size)
{
	return copy_from_sockptr(dst, src, size) ? -EFAULT : 0;
}

int rcan_get_user_int(int __user *p, int *val)
{
	return get_user(*val, p);
}

int rcan_put_user_int(int __user *p, int val)
{
	return put_user(val, p);
}

int rcan_copy_from_user(void *dst, const void __user *src, unsigned long n)
{
	return copy_from_user(dst, src, n) ? -EFAULT : 0;
}

bool rcan_capable_net_admin(void)
{
	return capable(CAP_NET_ADMIN);
}

int rcan_copy_to_user(void __user *dst, const void *src, unsigned long n)
{
	return copy_to_user(dst, src, n) ? -EFAULT : 0;
}

/* spin_lock_init with the caller's class (rust_helper___spin_lock_init). */
void rcan_spin_lock_init_key(spinlock_t *lock, const char *name,
			     struct lock_class_key *key)
{
#ifdef CONFIG_DEBUG_SPINLOCK
# if defined(CONFIG_PREEMPT_RT)
	__spin_lock_init(lock, name, key, false);
# else
	__raw_spin_lock_init(spinlock_check(lock), name, key, LD_WAIT_CONFIG);
# endif
#else
	spin_lock_init(lock);
#endif
}

/* A spinlock in its own allocation, for Rust values that move. */
spinlock_t *rcan_spinlock_alloc(const char *name, struct lock_class_key *key)
{
	spinlock_t *l = kmalloc(sizeof(*l), GFP_KERNEL);

	if (l)
		rcan_spin_lock_init_key(l, name, key);
	return l;
}

void rcan_init_waitqueue_head_key(struct wait_queue_head *wq, const char *name,
				  struct lock_class_key *key)
{
	__init_waitqueue_head(wq, name, key);
}

void rcan_spinlock_free(spinlock_t *lock)
{
	kfree(lock);
}

/*
 * rust/glue/lock.rs calls _raw_spin_lock_irqsave and
 * _raw_spin_unlock_irqrestore on a spinlock_t's raw_spinlock directly
 * (spin_lock_irqsave without a helper): true only without PREEMPT_RT and
 * with the raw lock at offset 0.
 */
#ifdef CONFIG_PREEMPT_RT
#error "rcan's Irq lock backend assumes spinlock_t wraps a raw_spinlock (no PREEMPT_RT)"
#endif
static_assert(offsetof(spinlock_t, rlock) == 0);

unsigned long rcan_local_irq_save(void)
{
	unsigned long flags;

	local_irq_save(flags);
	return flags;
}

void rcan_local_irq_restore(unsigned long flags)
{
	local_irq_restore(flags);
}

void rcan_pci_set_drvdata(struct pci_dev *pdev, void *data)
{
	pci_set_drvdata(pdev, data);
}

void *rcan_pci_get_drvdata(struct pci_dev *pdev)
{
	return pci_get_drvdata(pdev);
}

unsigned long rcan_pci_resource_len(struct pci_dev *pdev, int bar)
{
	return pci_resource_len(pdev, bar);
}

bool rcan_request_mem_region(unsigned long start, unsigned long n, const char *name)
{
	return request_mem_region(start, n, name) != NULL;
}

void rcan_release_mem_region(unsigned long start, unsigned long n)
{
	release_mem_region(start, n);
}

bool rcan_request_region(unsigned long start, unsigned long n, const char *name)
{
	return request_region(start, n, name) != NULL;
}

void rcan_release_region(unsigned long start, unsigned long n)
{
	release_region(start, n);
}

void __iomem *rcan_ioremap(unsigned long start, unsigned long n)
{
	return ioremap(start, n);
}

void rcan_iounmap(void __iomem *addr)
{
	iounmap(addr);
}

void __iomem *rcan_ioport_map(unsigned long port, unsigned int n)
{
	return ioport_map(port, n);
}

void rcan_ioport_unmap(void __iomem *addr)
{
	ioport_unmap(addr);
}

unsigned long rcan_probe_irq_on(void)
{
	return probe_irq_on();
}

int rcan_probe_irq_off(unsigned long mask)
{
	return probe_irq_off(mask);
}

void rcan_udelay(unsigned long usecs)
{
	udelay(usecs);
}

void rcan_netdev_set_no_queue(struct net_device *dev)
{
	dev->priv_flags |= IFF_NO_QUEUE;
}

void rcan_netdev_set_netns_immutable(struct net_device *dev)
{
	dev->netns_immutable = true;
}

void rcan_netif_wake_queue(struct net_device *dev)
{
	netif_wake_queue(dev);
}

void rcan_netif_carrier(struct net_device *dev, bool on)
{
	if (on)
		netif_carrier_on(dev);
	else
		netif_carrier_off(dev);
}

/* Error counters of struct net_device_stats, by RCAN_STAT_* number. */
void rcan_dev_stats_err(struct net_device *dev, int which)
{
	switch (which) {
	case RCAN_STAT_RX_ERRORS:
		DEV_STATS_INC(dev, rx_errors);
		break;
	case RCAN_STAT_RX_OVER_ERRORS:
		DEV_STATS_INC(dev, rx_over_errors);
		DEV_STATS_INC(dev, rx_errors);
		break;
	case RCAN_STAT_TX_ERRORS:
		DEV_STATS_INC(dev, tx_errors);
		break;
	case RCAN_STAT_TX_ABORTED:
		DEV_STATS_INC(dev, tx_aborted_errors);
		DEV_STATS_INC(dev, tx_errors);
		break;
	}
}

long rcan_wait_event_timeout(struct wait_queue_head *wq,
			     bool (*cond)(void *arg), void *arg, long timeo)
{
	return wait_event_interruptible_timeout(*wq, cond(arg), timeo);
}

void rcan_wake_up_all(struct wait_queue_head *wq)
{
	wake_up_all(wq);
}

long rcan_sock_sndtimeo(const struct sock *sk, bool nonblock)
{
	return sock_sndtimeo(sk, nonblock);
}

unsigned int rcan_sock_tsflags(const struct sock *sk)
{
	return READ_ONCE(sk->sk_tsflags);
}

unsigned int rcan_sock_next_tskey(struct sock *sk)
{
	return atomic_inc_return(&sk->sk_tskey) - 1;
}

/*
 * Frees every skb on sk's error queue (its own lock, IRQ-safe); not from
 * hardirq: the skbs' destructors (sock_rmem_free) run.
 */
void rcan_sock_purge_errqueue(struct sock *sk)
{
	skb_queue_purge(&sk->sk_error_queue);
}

/*
 * Queues a notification on sk's error queue: an skb with the `len` bytes
 * at `stats` (netlink attributes when `opt_stats`), stamped now, whose
 * `sock_exterr_skb` has the given errno, origin, info and data.
 */
int rcan_sock_queue_err(struct sock *sk, const void *stats, unsigned int len,
			u32 ee_errno, u8 ee_origin, u32 ee_info, u32 ee_data,
			bool opt_stats)
{
	struct sock_exterr_skb *serr;
	struct sk_buff *skb;
	int err;

	skb = alloc_skb(len, GFP_ATOMIC);
	if (!skb)
		return -ENOMEM;
	skb_put_data(skb, stats, len);
	skb->tstamp = ktime_get_real();
	BUILD_BUG_ON(sizeof(struct sock_exterr_skb) > sizeof(skb->cb));
	serr = SKB_EXT_ERR(skb);
	memset(serr, 0, sizeof(*serr));
	serr->ee.ee_errno = ee_errno;
	serr->ee.ee_origin = ee_origin;
	serr->ee.ee_info = ee_info;
	serr->ee.ee_data = ee_data;
	serr->opt_stats = opt_stats;
	err = sock_queue_err_skb(sk, skb);
	if (err)
		kfree_skb(skb);
	return err;
}

bool rcan_skb_put_zero(struct sk_buff *skb, unsigned int len)
{
	if (skb_is_nonlinear(skb) || skb_tailroom(skb) < len)
		return false;
	skb_put_zero(skb, len);
	return true;
}

void *rcan_skb_push(struct sk_buff *skb, unsigned int len)
{
	if (skb_headroom(skb) < len)
		return NULL;
	return skb_push(skb, len);
}

/* skb->dev is set by the hand-off to the stack (NetDev::rx). */
void rcan_skb_set_ipv4_rx(struct sk_buff *skb)
{
	skb->protocol = htons(ETH_P_IP);
	skb->pkt_type = PACKET_HOST;
	skb->ip_summed = CHECKSUM_UNNECESSARY;
	skb_reset_network_header(skb);
	skb_set_transport_header(skb, sizeof(struct iphdr));
	skb_reset_mac_header(skb);
}

unsigned long rcan_jiffies(void)
{
	return jiffies;
}

unsigned long rcan_msecs_to_jiffies(unsigned int ms)
{
	return msecs_to_jiffies(ms);
}

static DEFINE_PER_CPU(u64, rcan_rx_serial);

/* This CPU's next frame number, and (in *cpu) the CPU: one call per frame
 * on the receive path instead of two. Caller has BH disabled. */
u64 rcan_rx_serial_next(unsigned int *cpu)
{
	*cpu = raw_smp_processor_id();
	return this_cpu_inc_return(rcan_rx_serial);
}

unsigned int rcan_nr_cpu_ids(void)
{
	return nr_cpu_ids;
}

/* NAPI (a driver's receive queue polled in NET_RX softirq). */
void rcan_napi_add(struct net_device *dev, struct napi_struct *napi,
		   int (*poll)(struct napi_struct *, int), int weight)
{
	netif_napi_add_weight(dev, napi, poll, weight);
}

void rcan_napi_enable(struct napi_struct *napi)
{
	napi_enable(napi);
}

void rcan_napi_disable(struct napi_struct *napi)
{
	napi_disable(napi);
}

/* skb->tstamp (a union member bindgen names unpredictably), in ns. */
s64 rcan_skb_tstamp(const struct sk_buff *skb)
{
	return ktime_to_ns(skb->tstamp);
}

void rcan_skb_set_tstamp(struct sk_buff *skb, s64 ns)
{
	skb->tstamp = ns_to_ktime(ns);
}

/* procfs: a directory in a namespace's /proc/net, single_open files. */
#include <linux/proc_fs.h>
#include <linux/seq_file.h>
#include <net/net_namespace.h>

struct proc_dir_entry *rcan_proc_net_mkdir(struct net *net, const char *name)
{
	return proc_net_mkdir(net, name, net->proc_net);
}

/* A reference on a namespace unless it is already being dismantled. */
bool rcan_maybe_get_net(struct net *net)
{
	return maybe_get_net(net) != NULL;
}

void rcan_put_net(struct net *net)
{
	put_net(net);
}

struct proc_dir_entry *rcan_proc_create_single(const char *name,
					       struct proc_dir_entry *parent,
					       int (*show)(struct seq_file *, void *),
					       void *data)
{
	return proc_create_single_data(name, 0644, parent, show, data);
}

void rcan_proc_remove(struct proc_dir_entry *pde)
{
	proc_remove(pde);
}

void *rcan_seq_private(struct seq_file *m)
{
	return m->private;
}

void rcan_seq_write(struct seq_file *m, const char *s, size_t len)
{
	seq_write(m, s, len);
}

/* An address as %pK prints it (hashed, or zeros under kptr_restrict). */
void rcan_seq_kptr(struct seq_file *m, unsigned long addr)
{
	seq_printf(m, "%pK", (void *)addr);
}

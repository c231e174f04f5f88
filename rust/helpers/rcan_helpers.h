/* SPDX-License-Identifier: GPL-2.0 */
/*
 * Out-of-line wrappers for kernel inline functions and macros that bindgen
 * cannot see. No logic lives here: each helper is one call.
 *
 * Every rcan module links its own copy (see rcan_helpers.c); the symbols are
 * not exported, so copies in different modules do not clash.
 */
#ifndef _RCAN_HELPERS_H
#define _RCAN_HELPERS_H

#include <linux/types.h>
#include <linux/sockptr.h>
#include <linux/spinlock_types.h>
#include <linux/workqueue.h>

struct sk_buff;
struct sock;
struct msghdr;
struct net_device;
struct mutex;
struct module;
struct net;

/* RCU */
void rcan_rcu_read_lock(void);
void rcan_rcu_read_unlock(void);

/* Locks defined with DEFINE_MUTEX in the modules' C files */
void rcan_mutex_lock(struct mutex *lock);
void rcan_mutex_unlock(struct mutex *lock);
void rcan_assert_rtnl(void);

/* sk_buff */
struct sk_buff *rcan_alloc_skb(unsigned int size, gfp_t gfp);
void rcan_kfree_skb(struct sk_buff *skb);
void rcan_consume_skb(struct sk_buff *skb);
void rcan_dev_kfree_skb_any(struct sk_buff *skb);
void rcan_dev_consume_skb_any(struct sk_buff *skb);
void rcan_skb_reset_headers(struct sk_buff *skb);
void rcan_skb_stamp_if_unset(struct sk_buff *skb);
s64 rcan_skb_tstamp(const struct sk_buff *skb);
void rcan_skb_set_tstamp(struct sk_buff *skb, s64 ns);
bool rcan_dev_nit_active(struct net_device *dev);
bool rcan_can_skb_tx_prepare(struct sk_buff *skb, struct net_device *dev);
struct sk_buff *rcan_skb_clone_owned(struct sk_buff *skb, gfp_t gfp);
int rcan_skb_copy_datagram_msg(const struct sk_buff *skb, int offset,
			       struct msghdr *msg, int size);

/* sock */
void rcan_lock_sock(struct sock *sk);
void rcan_sock_hold(struct sock *sk);
void rcan_sock_put(struct sock *sk);
void rcan_sock_orphan(struct sock *sk);
void rcan_sk_purge_queues(struct sock *sk);
void rcan_release_sock(struct sock *sk);
struct net *rcan_sock_net(const struct sock *sk);

/* net_device */
void rcan_netif_start_queue(struct net_device *dev);
void rcan_netif_stop_queue(struct net_device *dev);
void rcan_dev_hold(struct net_device *dev);
void rcan_dev_put(struct net_device *dev);
struct net_device *rcan_dev_get_by_name(struct net *net, const char *name);
struct net_device *rcan_next_can_dev(struct net *net, int after_ifindex);

/* network namespaces */
struct net *rcan_init_net(void);
void *rcan_net_generic(const struct net *net, unsigned int id);
struct net_device *rcan_netdev_notifier_dev(void *info);

void rcan_sk_report_error(struct sock *sk, int err);
void rcan_sk_wake_writers(struct sock *sk);

/* user memory */
int rcan_copy_from_sockptr(void *dst, sockptr_t src, size_t size);
int rcan_get_user_int(int __user *p, int *val);
int rcan_put_user_int(int __user *p, int val);
int rcan_copy_to_user(void __user *dst, const void *src, unsigned long n);
int rcan_copy_from_user(void *dst, const void __user *src, unsigned long n);
bool rcan_capable_net_admin(void);

/*
 * Spinlocks and wait queues with the lockdep class of their definition
 * site (a static struct lock_class_key per site, as spin_lock_init's
 * macro makes one): for Rust values that move, a spinlock in its own
 * allocation; for Rust statics, initialisation in place.
 */
struct lock_class_key;
spinlock_t *rcan_spinlock_alloc(const char *name, struct lock_class_key *key);
void rcan_spin_lock_init_key(spinlock_t *lock, const char *name,
			     struct lock_class_key *key);
struct wait_queue_head;
void rcan_init_waitqueue_head_key(struct wait_queue_head *wq, const char *name,
				  struct lock_class_key *key);
void rcan_spinlock_free(spinlock_t *lock);
/* local interrupts off on this CPU (the glue's one-time initialisation) */
unsigned long rcan_local_irq_save(void);
void rcan_local_irq_restore(unsigned long flags);

/* PCI */
struct pci_dev;
void rcan_pci_set_drvdata(struct pci_dev *pdev, void *data);
void *rcan_pci_get_drvdata(struct pci_dev *pdev);
unsigned long rcan_pci_resource_len(struct pci_dev *pdev, int bar);

/* ISA-style I/O windows: memory (request_mem_region + ioremap) and ports
 * (request_region + ioport_map), accessed with ioread8/iowrite8. */
bool rcan_request_mem_region(unsigned long start, unsigned long n, const char *name);
void rcan_release_mem_region(unsigned long start, unsigned long n);
bool rcan_request_region(unsigned long start, unsigned long n, const char *name);
void rcan_release_region(unsigned long start, unsigned long n);
void __iomem *rcan_ioremap(unsigned long start, unsigned long n);
void rcan_iounmap(void __iomem *addr);
void __iomem *rcan_ioport_map(unsigned long port, unsigned int n);
void rcan_ioport_unmap(void __iomem *addr);

/* interrupt autoprobe (ISA) */
unsigned long rcan_probe_irq_on(void);
int rcan_probe_irq_off(unsigned long mask);
void rcan_udelay(unsigned long usecs);

/* net_device queue, carrier and error counters */
void rcan_netif_wake_queue(struct net_device *dev);
void rcan_netdev_set_no_queue(struct net_device *dev);
void rcan_netdev_set_netns_immutable(struct net_device *dev);
void rcan_netif_carrier(struct net_device *dev, bool on);
enum {
	RCAN_STAT_RX_ERRORS,
	RCAN_STAT_RX_OVER_ERRORS,
	RCAN_STAT_TX_ERRORS,
	RCAN_STAT_TX_ABORTED,
};
void rcan_dev_stats_err(struct net_device *dev, int which);

/* module references */
bool rcan_try_module_get(struct module *mod);
void rcan_module_put(struct module *mod);
/* an allocation leaked on purpose (kmemleak: not reported, still scanned) */
void rcan_kmemleak_not_leak(const void *ptr);
/* work items (INIT_WORK with its lockdep key; schedule_work, flush_work) */
void rcan_init_work(struct work_struct *work, work_func_t func);
bool rcan_schedule_work(struct work_struct *work);
bool rcan_flush_work(struct work_struct *work);
/* the caller may sleep: preemptible, not in an RCU read-side section
 * (false on kernels that cannot tell, without CONFIG_PREEMPT_COUNT) */
bool rcan_may_sleep(void);
/* request_module("%s", name): the name is never used as a format */
int rcan_request_module(const char *name);

/* random */
u32 rcan_get_random_u32(void);

/* wait queues (statics of the glue's WaitQueue) */
struct wait_queue_head;
long rcan_wait_event_timeout(struct wait_queue_head *wq,
			     bool (*cond)(void *arg), void *arg, long timeo);
void rcan_wake_up_all(struct wait_queue_head *wq);
long rcan_sock_sndtimeo(const struct sock *sk, bool nonblock);
unsigned int rcan_sock_tsflags(const struct sock *sk);
unsigned int rcan_sock_next_tskey(struct sock *sk);
void rcan_sock_purge_errqueue(struct sock *sk);
int rcan_sock_queue_err(struct sock *sk, const void *stats, unsigned int len,
			u32 ee_errno, u8 ee_origin, u32 ee_info, u32 ee_data,
			bool opt_stats);

/* skb data and IPv4 delivery */
bool rcan_skb_put_zero(struct sk_buff *skb, unsigned int len);
void *rcan_skb_push(struct sk_buff *skb, unsigned int len);
void rcan_skb_set_ipv4_rx(struct sk_buff *skb);
struct sk_buff *rcan_skb_unshare(struct sk_buff *skb, gfp_t gfp);
unsigned long rcan_jiffies(void);
unsigned long rcan_msecs_to_jiffies(unsigned int ms);

/* the receive table's per-CPU frame counter and CPU numbers */
u64 rcan_rx_serial_next(unsigned int *cpu);
unsigned int rcan_nr_cpu_ids(void);
/* NAPI */
struct napi_struct;
void rcan_napi_add(struct net_device *dev, struct napi_struct *napi,
		   int (*poll)(struct napi_struct *, int), int weight);
void rcan_napi_enable(struct napi_struct *napi);
void rcan_napi_disable(struct napi_struct *napi);

/* procfs (rust/glue/procfs.rs) */
struct proc_dir_entry;
struct seq_file;
struct proc_dir_entry *rcan_proc_net_mkdir(struct net *net, const char *name);
bool rcan_maybe_get_net(struct net *net);
void rcan_put_net(struct net *net);
struct proc_dir_entry *rcan_proc_create_single(const char *name,
					       struct proc_dir_entry *parent,
					       int (*show)(struct seq_file *, void *),
					       void *data);
void rcan_proc_remove(struct proc_dir_entry *pde);
void *rcan_seq_private(struct seq_file *m);
void rcan_seq_write(struct seq_file *m, const char *s, size_t len);
void rcan_seq_kptr(struct seq_file *m, unsigned long addr);

#endif /* _RCAN_HELPERS_H */

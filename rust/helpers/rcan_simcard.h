/* SPDX-License-Identifier: GPL-2.0 */
/*
 * The `fault` parameter of the simulated-card modules (rcan_sja1000_sim,
 * rcan_i82527_sim; rust/glue/simcard.rs): a fixed buffer
 * (module_param_string), not a charp, because the simulated bus reads it
 * in softirq context without the parameter lock. A buffer being rewritten
 * can at worst give a torn name (read as unknown: no fault), never freed
 * memory. Each module declares the buffer with its own description:
 *
 *	static char fault[RCAN_SIMCARD_FAULT_LEN] = "none";
 *	module_param_string(fault, fault, sizeof(fault), 0644);
 *
 * and answers rcan_module_param_str (rcan_params.h) for its number with
 * rcan_simcard_fault_str. The Rust side reads it into a buffer of the
 * same length (simcard::param_word).
 */
#ifndef _RCAN_SIMCARD_H
#define _RCAN_SIMCARD_H

#include <linux/string.h>
#include <linux/types.h>

#define RCAN_SIMCARD_FAULT_LEN 16

/*
 * rcan_module_param_str's answer for a module whose one string parameter
 * is `fault`: `is_fault` says whether `which` names it. Any context (a
 * snapshot of the fixed buffer, no lock). Copies at most len - 1 bytes,
 * NUL-padded; returns the full length (0 for another `which`).
 */
static inline size_t rcan_simcard_fault_str(const char *fault, bool is_fault,
					    char *buf, size_t len)
{
	char copy[RCAN_SIMCARD_FAULT_LEN];

	if (len)
		memset(buf, 0, len);
	if (!is_fault)
		return 0;
	memcpy(copy, fault, sizeof(copy));
	copy[sizeof(copy) - 1] = 0;
	if (len)
		strscpy(buf, copy, len);
	return strlen(copy);
}

#endif /* _RCAN_SIMCARD_H */

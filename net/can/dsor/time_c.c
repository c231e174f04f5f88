// SPDX-License-Identifier: GPL-2.0
/* C side of rcan_time: parameters vehicle and dev, and the helpers. */
#include "ticker_params.c"

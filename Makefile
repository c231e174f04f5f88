# SPDX-License-Identifier: GPL-2.0
#
# Front door for humans and CI. Kbuild reads ./Kbuild, not this file.
#
#   make demo     build everything, boot the VM, run the thesis-API sample
#   make check    host tests + VM test suite (what CI runs)
#   make fuzz     the syscall fuzzer on the debug kernel (SECONDS=N per seed,
#                 SEED=S, THREADS=K; default 600 s, a time-derived seed)
#   make modules  just the kernel modules (KDIR=... for your own kernel)
#   make install  install what `make` built (modules, tools, man pages,
#                 completions, /etc/modprobe.d/rcan.conf); builds nothing.
#                 KDIR as for `make modules`; DESTDIR, PREFIX (/usr/local)
#   make uninstall  remove exactly what make install put there
#
# RCAN_KERNEL=debug selects the KASAN/lockdep/kmemleak kernel.

T := tools/testing/rcan

# The kernel to build against: KDIR if given (make modules KDIR=...), else
# the cached test kernel, built by build-kernel.sh when a recipe first needs
# it (after `setup`), once per make run. $(shell ...) drops the exit status,
# so the script prints its error message on stdout and a failure stops make
# right here, with that message last, before any step runs without a kernel.
ifeq ($(origin KDIR),undefined)
KDIR = $(eval KDIR := $$(shell bash $(T)/build-kernel.sh --error-on-stdout))$(if \
	$(filter-out 0,$(.SHELLSTATUS)),$(error $(or $(KDIR),rcan: $(T)/build-kernel.sh failed \
	(exit status $(.SHELLSTATUS)))))$(KDIR)
endif
# What the recipes use: never empty.
kdir = $(or $(strip $(KDIR)),$(error rcan: KDIR is empty: give the kernel build directory \
	(make modules KDIR=...)))
RCAN_CONFIG := CONFIG_RCAN=m CONFIG_RCAN_PF=m CONFIG_RCAN_PROTO_CAN=m CONFIG_RCAN_PROTO_RAW=m CONFIG_RCAN_PROTO_BCM=m CONFIG_RCAN_PROTO_ISOTP=m CONFIG_RCAN_PROTO_J1939=m \
	CONFIG_RCAN_LOOP=m CONFIG_RCAN_DEV=m CONFIG_RCAN_SJA1000=m CONFIG_RCAN_KVASER_PCI=m CONFIG_RCAN_ADVANTECH_PCI=m \
	CONFIG_RCAN_SJA1000_ISA=m CONFIG_RCAN_PCAN_PCI=m CONFIG_RCAN_TSCAN1=m CONFIG_RCAN_SJA1000_SIM=m \
	CONFIG_RCAN_I82527=m CONFIG_RCAN_I82527_ISA=m CONFIG_RCAN_I82527_SIM=m CONFIG_RCAN_CTUCANFD_PCI=m CONFIG_RCAN_CTUCANFD_SIM=m \
	CONFIG_RCAN_DSOR_TIME=m CONFIG_RCAN_DSOR_RTIME=m \
	CONFIG_RCAN_PROTO_DSOR=m CONFIG_RCAN_DSOR_NODE_ID=0x00
BINDINGS := rust/bindings/bindings_generated.rs

.PHONY: all setup kernel modules bindings userspace man demo check soak fuzz bench clean install uninstall \
	debug-kernel-early

all: modules userspace man

setup:
	bash $(T)/setup.sh

kernel: setup
	@echo $(kdir)

# Regenerated on every build: the layout depends on the kernel (KDIR), and
# the script leaves the file alone when nothing changed.
bindings:
	bash rust/bindings/gen-bindings.sh $(kdir) $(BINDINGS)

# Kbuild compiles the modules one at a time unless told otherwise (each
# compiles the glue into itself): as many at once as there are cores,
# unless make was given a -j of its own.
modules_j = $(if $(filter -j%,$(MAKEFLAGS)),,-j$(shell nproc))

# The test-only modules rcan_exittest and rcan_abiskew (tools/testing/rcan/
# exitmod, issue 39's exit sweeps and ABI check) in a Kbuild run of their own: its own modules.order, so that
# `make install` (which installs modules.order) never installs it; it links
# against rcan_pf through this build's Module.symvers.
EXITMOD := $(T)/exitmod

modules: bindings
	$(MAKE) -C $(kdir) M=$(CURDIR) LLVM=1 $(RCAN_CONFIG) $(modules_j) modules
	$(MAKE) -C $(kdir) M=$(CURDIR)/$(EXITMOD) LLVM=1 KBUILD_EXTRA_SYMBOLS=$(CURDIR)/Module.symvers $(modules_j) modules

userspace:
	cargo build --release --workspace --bins

# Man pages and bash/zsh/fish completions of every tool, from the tools'
# own clap definitions (tools/mangen), into target/man.
man: userspace
	target/release/rcan-mangen target/man

# Installs what `make` built and builds nothing, so that `sudo make install`
# after `make` as yourself leaves no root-owned files in the tree. The
# manifest of what it wrote is $(PREFIX)/share/rcan/install-manifest.
PREFIX ?= /usr/local
install:
	KDIR='$(kdir)' DESTDIR='$(DESTDIR)' PREFIX='$(PREFIX)' bash scripts/install.sh install

uninstall:
	DESTDIR='$(DESTDIR)' PREFIX='$(PREFIX)' bash scripts/install.sh uninstall

demo: setup modules userspace
	bash $(T)/demo.sh

# When make started: run-tests.sh counts the setup and builds before it.
RCAN_MAKE_T0 := $(shell date +%s)

check: setup debug-kernel-early modules userspace man
	RCAN_MAKE_T0=$(RCAN_MAKE_T0) bash $(T)/run-tests.sh

# An uncached debug kernel starts make check's longest chain (the debug
# kernel, the debug modules, the debug suite), so its build starts right
# after setup, in the background, beside the release kernel and all else
# before the tests, rather than when run-tests.sh gets to it (2026-11-29:
# a cold make check spent 16 of its 51 minutes waiting for it there).
# run-tests.sh's build-debug job waits for this build through the kernel
# cache's lock (build-kernel.sh) and, if it failed, builds the kernel
# itself and reports why. Nothing to do when the debug kernel is cached.
debug-kernel-early: setup
	@mkdir -p target
	@RCAN_KERNEL=debug nohup bash $(T)/build-kernel.sh >target/debug-kernel-early.log 2>&1 </dev/null &

# The VM stages of make check RUNS times (default 3) beside stress-ng
# --cpu LOAD (default 2): the suite must not depend on the host's speed.
soak: setup debug-kernel-early modules userspace man
	bash $(T)/soak.sh

# A longer run of the syscall fuzzer (tests/fuzz) than make check's, on the
# debug kernel (KASAN, lockdep, kmemleak), in one VM boot; builds the debug
# modules. Prints the seed; replay with SEED=.
SECONDS ?= 600
THREADS ?= 4
fuzz: setup userspace
	RCAN_KERNEL=debug $(MAKE) --no-print-directory modules
	@seed=$${SEED:-$$(date +%s)}; echo "rcan-fuzz: seed $$seed, $(SECONDS) s, $(THREADS) threads"; \
	. $(T)/lib.sh && RCAN_KERNEL=debug bash $(T)/vm-run.sh --timeout $$(( $(SECONDS) + 900 )) \
		--qemu-extra "$$RCAN_QEMU_CAN" -- target/release/rcan-fuzz --seed $$seed \
		--seconds $(SECONDS) --threads $(THREADS) --iterations 100000000

# Benchmarks, not tests: ours vs mainline SocketCAN in one VM boot.
bench: setup modules userspace
	bash $(T)/bench.sh $(BENCH_ARGS)

clean:
	$(MAKE) -C $(kdir) M=$(CURDIR) clean || true
	$(MAKE) -C $(kdir) M=$(CURDIR)/$(EXITMOD) clean || true
	rm -f $(BINDINGS)

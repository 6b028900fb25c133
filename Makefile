# The two commands of the README:
#   make demo   set up, build, and run the main job on the embedded exemplar
#   make test   set up, build, and run the whole test suite
# Everything else is a helper. CUDA=1 builds the GPU variant.

# cargo from rustup (make setup installs it there on a bare machine).
export PATH := $(or $(CARGO_HOME),$(HOME)/.cargo)/bin:$(PATH)

CARGO_FEATURES := $(if $(filter 1,$(CUDA)),--features cuda,)
OUT ?= out/demo

.PHONY: setup setup-check build demo test test-slow figures-check bench bench-poisson decimate-bench fuzz clean cluster-test interop studio-test studio-bench

setup:
	@bash scripts/setup.sh

# `make setup` on a bare Debian 12 chroot (debootstrap minbase; root): what
# it installs, and the versions it leaves (scripts/bare-setup-check.sh).
setup-check:
	bash scripts/bare-setup-check.sh

build: setup
	cargo build --release $(CARGO_FEATURES)

demo: build
	./target/release/shapeshifter demo -o $(OUT)

# Tests that cannot run here (no ../shared/data, a client missing) are not
# "ok": each is listed at the end. SHAPESHIFTER_NO_SKIPS=1 (CI) fails them.
# `make test` runs the quick suite; `make test-slow` the longer versions of
# some checks (marked #[ignore] with the reason; docs/developers.md lists
# them and what covers each in the quick suite). CI runs both.
SKIP_LOG := $(CURDIR)/target/test-skips.log
define run_tests
	@mkdir -p target && rm -f $(SKIP_LOG)
	@SHAPESHIFTER_SKIP_LOG=$(SKIP_LOG) cargo test --release $(CARGO_FEATURES) $(1) -- --test-threads=2 $(2); status=$$?; \
	if [ -s $(SKIP_LOG) ]; then \
	  echo "make $@: $$(wc -l < $(SKIP_LOG)) check(s) SKIPPED:"; sed 's/^/  /' $(SKIP_LOG); \
	else echo "make $@: nothing skipped"; fi; \
	exit $$status
endef
# The quick suite builds only the examples it runs (the integrator examples of
# tests/commands.rs), after the test binaries (one cargo call compiles the
# library and its unit tests side by side on two cores; not the programs' own
# test harnesses, which hold no tests: the programs the suite runs are built
# for it); `make test-slow` builds every target, the benchmarks and tools
# included, so they keep compiling (CI runs it).
test: setup
	bash scripts/venv.sh usd-venv "usd-core==26.11" > /dev/null
	cargo test --release $(CARGO_FEATURES) --lib --test suite --no-run
	cargo build --release $(CARGO_FEATURES) --example encode_mesh --example read_level
	$(call run_tests,--lib --test suite,)
test-slow: setup
	$(call run_tests,,--ignored)

# The pipeline as a SLURM job graph on a real one-node cluster on this machine
# (installs slurm-wlm and munge; daemons in a private network namespace),
# compared with a single-process run. CI runs it after `make test`.
cluster-test: build
	cargo build --release $(CARGO_FEATURES) --example demo_exemplar
	bash scripts/cluster-test.sh

# The files we write opened by real clients: OpenVDB's vdb_print, Debian's
# pyopenvdb, Blender (headless) and Chromium (report.html); installs them from
# Debian when missing. CI runs it after `make test`.
interop: build
	cargo build --release $(CARGO_FEATURES) --example demo_exemplar
	bash scripts/interop-test.sh

# The studio's page driven by a real headless Chromium through WebDriver
# (installs chromium, chromium-driver and the selenium client): load, pick a
# variant, delete a box at level 1 with the mouse, regenerate, keep; the kept
# folder read back; a screenshot in out/studio-test/. CI runs it.
studio-test: build
	bash scripts/studio-test.sh

# The studio's speed: from an edit at 32^3, each finer level ready (the
# demo's run, and the tower's where one is given: STUDIO_RUNS="out/demo out/tower").
STUDIO_RUNS ?= $(OUT)
studio-bench: build
	cargo run --release $(CARGO_FEATURES) --example studio_bench -- $(STUDIO_RUNS)

# Every benchmark of docs/performance.md (the ruined tower from
# ../shared/data where it is present; synthetic shapes stand in otherwise).
TOWER := ../shared/data/towerruins/towerruins.obj
bench: build
	cargo run --release $(CARGO_FEATURES) --example encode_bench
	cargo run --release $(CARGO_FEATURES) --example conv_bench
	if [ -f $(TOWER) ]; then cargo run --release $(CARGO_FEATURES) --example recon_bench -- all --mesh $(TOWER); \
	else cargo run --release $(CARGO_FEATURES) --example recon_bench; fi
	cargo run --release $(CARGO_FEATURES) --example metrics_bench
	if [ -f $(TOWER) ]; then $(MAKE) decimate-bench; fi

# Light meshes of the ruined tower's 256^3 level: fidelity, time and file size
# against the triangle budget (docs/performance.md).
decimate-bench: build
	./target/release/shapeshifter encode $(TOWER) -o out/decimate
	./target/release/shapeshifter mesh out/decimate/level_4.vdb -o out/decimate/full.ply
	cargo run --release $(CARGO_FEATURES) --example decimate_bench -- \
	  --mesh $(TOWER) --level out/decimate/level_4.vdb --full-mesh out/decimate/full.ply --out out/decimate

# A long mutation campaign against every reader (docs/hostile-files.md).
COUNT ?= 2000
SEED ?= 1
fuzz: build
	cargo run --release $(CARGO_FEATURES) --example hostile_campaign -- --count $(COUNT) --seed $(SEED)

# Also empties the build folder every clone of this machine shares (make setup).
clean:
	cargo clean

# Our Poisson meshing against Open3D's screened Poisson (depth 9) on the
# ruined tower's 256^3 level, side by side in one run (docs/performance.md);
# installs Open3D from PyPI into a cache folder outside the work tree.
bench-poisson: build
	bash scripts/poisson-vs-open3d.sh

# Which figures of the README and docs are older than the code they measure
# (docs/figures.toml: each figure's command, code and commit); exit 1 if any.
figures-check:
	python3 scripts/figures-check.py

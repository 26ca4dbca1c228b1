# tofmat: the entry point. `make demo` and `make test` do all set-up themselves.
SHELL    := /bin/bash
PYTHON   ?= python3
JOBS     ?= 2
DB       ?= $(abspath ../shared/data/tanaka2017_kinect2_db)
BUILD    := build/release
# One sanitizer build (clang, ASan + UBSan, the fuzzers' coverage instrumentation) serves both the
# sanitized C++ suites and the libFuzzer targets: one compile of everything instead of two.
ASAN     := build/sanitize
FUZZDIR  := $(ASAN)
TABLE    := build/tanaka2017.tmx
FUZZ_SECONDS ?= 30
TOFMAT   = $(PYTHON) -m tofmat
SUDO     := $(shell [ "$$(id -u)" -eq 0 ] || echo sudo)

# Debian 12 packages: compilers and build tools, GoogleTest, zlib (CRC-32),
# clang and its runtime for libFuzzer, libusb-1.0 (the Kinect driver); for
# tofmatd: spdlog (logging), CLI11 (flags and config file); OpenCV imgproc for
# the tests (the float reference of the segmentation's integer smoothing).
APT_PACKAGES := build-essential cmake ninja-build pkg-config libgtest-dev zlib1g-dev nlohmann-json3-dev clang libclang-rt-14-dev libusb-1.0-0-dev \
                libspdlog-dev libcli11-dev libopencv-imgproc-dev libgpiod-dev clang-format clang-tidy ccache

# The SDK's extension build (scikit-build-core, build/sdk-*) compiles the core, the simulator and the
# driver again with the flags build-cpp uses (Release, make's $(CXX)): ccache hands it build-cpp's objects. CMake
# takes its compiler and launcher from these variables when it configures a build tree the first
# time; the launcher is looked up when each recipe runs (after `make setup` has installed ccache;
# none where it is missing); ccache keeps its cache in build/ccache (make clean removes it).
export CXX CC
export CMAKE_CXX_COMPILER_LAUNCHER = $(shell command -v ccache)
export CMAKE_C_COMPILER_LAUNCHER = $(shell command -v ccache)
export CCACHE_DIR := $(CURDIR)/build/ccache

CROSS    := build/aarch64
# The aarch64 cross build of everything that runs on the box: Debian's cross
# compiler, qemu user mode, and the arm64 libraries tofmatd links, from
# multiarch beside the amd64 ones (CLI11 and nlohmann-json are headers: the
# host's serve both). libgpiod is there for the sorting line's GPIO.
CROSS_APT_PACKAGES := g++-aarch64-linux-gnu qemu-user zlib1g-dev:arm64 libgtest-dev:arm64 libusb-1.0-0-dev:arm64 \
                      libspdlog-dev:arm64 libopencv-imgproc-dev:arm64 libgpiod-dev:arm64 libcli11-dev nlohmann-json3-dev

.PHONY: all setup setup-cross cross cross-test cross-test-all build-cpp build-python typecheck test test-cpp test-sanitize test-python fuzz demo demo-line bench clean check-db

all: build

# Idempotent: apt runs only when a package is missing; pip pins live in sdk/requirements.txt.
setup:
	@missing=$$(mk/apt-missing.sh $(APT_PACKAGES)); \
	if [ -n "$$missing" ]; then \
	  echo "setup: installing $$missing"; \
	  $(SUDO) apt-get update -qq && DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -qq $$missing >/dev/null; \
	fi
	$(PYTHON) -m pip install -q --disable-pip-version-check -r sdk/requirements.txt
	mk/fetch-deps.sh onnxruntime

# Idempotent: adds the arm64 architecture to dpkg once, installs what is missing.
setup-cross:
	@dpkg --print-foreign-architectures | grep -qx arm64 || { echo "setup-cross: adding arm64"; $(SUDO) dpkg --add-architecture arm64; $(SUDO) apt-get update -qq; }
	@missing=$$(mk/apt-missing.sh $(CROSS_APT_PACKAGES)); \
	if [ -n "$$missing" ]; then \
	  echo "setup-cross: installing $$missing"; \
	  $(SUDO) apt-get update -qq && DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -qq $$missing >/dev/null; \
	fi

build: setup build-cpp build-python

build-cpp:
	cmake -S . -B $(BUILD) -G Ninja -DCMAKE_BUILD_TYPE=Release -DTOFMAT_DB_DIR=$(DB) >/dev/null
	cmake --build $(BUILD) -j$(JOBS)

# The SDK builds the extension from this CMake project (scikit-build-core);
# build/sdk-* keeps its build tree so a rebuild is incremental.
build-python:
	$(PYTHON) -m pip install -q --disable-pip-version-check --no-build-isolation ./sdk

check-db:
	@test -d "$(DB)" || { echo "error: real database not found at $(DB) (set DB=...)" >&2; exit 1; }

test: setup check-db lint build-cpp build-python typecheck docs test-cpp test-sanitize test-python

# Formatting and linting with the ecosystem's tools, configured in the repo: ruff for
# Python (ruff.toml); clang-format, clang-tidy and the SPDX check for C++ (mk/lint-cpp.mk,
# docs/coding-style.md). `make format` applies the formatters.
.PHONY: lint lint-python format
lint: lint-python lint-cpp
lint-python:
	$(PYTHON) -m ruff format --check --diff .
	$(PYTHON) -m ruff check .
format:
	$(PYTHON) -m ruff format .
	$(PYTHON) -m ruff check --fix .
	git ls-files -z -- $(LINT_CPP_FORMAT_FILES) | xargs -0 $(CLANG_FORMAT) -i

# The SDK is fully typed (the extension through sdk/tofmat/_tofmat.pyi), and the stub is
# checked against the built extension by mypy's stubtest (from the top folder, so that the
# installed package is the one imported; sdk/stubtest-allowlist.txt says what pybind11 makes differ).
typecheck:
	cd sdk && $(PYTHON) -m mypy --strict tofmat ../examples
	$(PYTHON) -m mypy.stubtest tofmat._tofmat --allowlist sdk/stubtest-allowlist.txt

test-cpp:
	ctest --test-dir $(BUILD) --output-on-failure -j$(JOBS)

# The same C++ suites under AddressSanitizer + UndefinedBehaviorSanitizer (not the
# benchmark programs), but for the simulator's statistical suites: they repeat the
# code paths the other suites run under the sanitizers thousands of times for their
# statistics (over 40 % of the sanitized run's time), and run natively in test-cpp;
# test-sanitize-all runs them too. The build is clang's at -O1 (clang's ASan also
# finds a stack object used after its scope where gcc's at -O0 did not), with the
# libFuzzer targets and their instrumentation in it, so `make fuzz` reuses it.
ASAN_SLOW_SUITES := ^(DecodeNoise|KinectSimFaults|RendererThreads)\.|^KinectSim\.EndToEnd
.PHONY: test-sanitize-all build-sanitize
build-sanitize: setup
	cmake -S . -B $(ASAN) -G Ninja -DCMAKE_CXX_COMPILER=clang++ -DCMAKE_BUILD_TYPE=Debug -DCMAKE_CXX_FLAGS_DEBUG="-g -O1" \
	  -DTOFMAT_SANITIZE=ON -DTOFMAT_FUZZ=ON -DTOFMAT_BUILD_BENCH=OFF -DTOFMAT_DB_DIR=$(DB) >/dev/null
	cmake --build $(ASAN) -j$(JOBS)
test-sanitize: build-sanitize
	ctest --test-dir $(ASAN) --output-on-failure -j$(JOBS) -E '$(ASAN_SLOW_SUITES)'
test-sanitize-all: test-sanitize
	ctest --test-dir $(ASAN) --output-on-failure -j$(JOBS) -R '$(ASAN_SLOW_SUITES)'

# JOBS pytest workers (pytest-xdist): most tests wait on a daemon or a subprocess, so two workers
# on two cores take about 60 % of one worker's time.
test-python:
	TOFMAT_DB_DIR=$(DB) $(PYTHON) -m pytest tests/python -q -n $(JOBS)

# libFuzzer targets (clang, ASan+UBSan), each run for FUZZ_SECONDS from its seed corpus, JOBS at
# once; any failure fails the target after all have run, its report and input printed last.
# FUZZ_SEED: the commit's (each commit explores afresh), 0 for libFuzzer's own.
FUZZ_SEED ?= $(shell echo $$((0x$$(git rev-parse --short=7 HEAD 2>/dev/null || echo 1) % 2147483647 + 1)))
fuzz: build-sanitize
	mk/fuzz.sh $(FUZZDIR) $(FUZZ_SECONDS) $(JOBS) $(FUZZ_SEED)

# Everything that runs on the box, for aarch64: tofmatd (with libusb, spdlog,
# CLI11), the core, the driver, the protocol, the simulator source, and
# the GoogleTest suites (run under qemu-aarch64 by cross-test).
cross: setup-cross
	mk/fetch-deps.sh onnxruntime qemu10
	cmake -S . -B $(CROSS) -G Ninja -DCMAKE_TOOLCHAIN_FILE=cmake/aarch64-linux-gnu.cmake -DCMAKE_BUILD_TYPE=Release \
	  -DTOFMAT_DB_DIR=$(DB) >/dev/null
	@cmake --build $(CROSS) -j$(JOBS) > $(CROSS)/build.log 2>&1; rc=$$?; tail -n 20 $(CROSS)/build.log; exit $$rc

# The box's build under qemu-aarch64: its GoogleTest suites, then tofmatd end
# to end. Learned classifiers run under qemu 10 (mk/fetch-deps.sh qemu10):
# onnxruntime crashes qemu 7.2 while it reads the CPU's features. The tests marked `board` in tests/python/test_daemon.py start the
# aarch64 tofmatd (tests/cross/tofmatd-qemu) and talk to it with the host's
# Python client; a replayed recording must give the x86 daemon's labels.
# The board tests run JOBS at once (pytest-xdist; 144 s for the ten daemon tests on two cores
# against 227 s one at a time). Two statistical suites of the simulator (DecodeNoise: 270 s, KinectSimFaults:
# 130 s under qemu, over half the suites' time) run natively in `make test` and
# under qemu only in cross-test-all.
QEMU_SLOW_SUITES := ^(DecodeNoise|KinectSimFaults)\.
cross-test: cross check-db setup build-python
	ctest --test-dir $(CROSS) --output-on-failure -j$(JOBS) -E '$(QEMU_SLOW_SUITES)'
	TOFMAT_DAEMON=$(abspath tests/cross/tofmatd-qemu) TOFMAT_DAEMON_AARCH64=$(abspath $(CROSS)/firmware/daemon/tofmatd) \
	  TOFMAT_DB_DIR=$(DB) $(PYTHON) -m pytest tests/python/test_daemon.py -m board -q -n $(JOBS)
	QEMU_AARCH64=$(abspath build/deps/qemu10/qemu-aarch64) TOFMAT_DAEMON=$(abspath tests/cross/tofmatd-qemu) \
	  TOFMAT_DAEMON_AARCH64=$(abspath $(CROSS)/firmware/daemon/tofmatd) \
	  TOFMAT_DB_DIR=$(DB) $(PYTHON) -m pytest tests/python/test_learn.py -m board -q -n $(JOBS)

cross-test-all: cross-test
	ctest --test-dir $(CROSS) --output-on-failure -j$(JOBS) -R '$(QEMU_SLOW_SUITES)'

# The box's Debian packages, tofmatd_<version>_{amd64,arm64}.deb in
# build/packages (CPack over the amd64 and the aarch64 builds; the default
# table is the real database, imported once), and their test: lintian, and
# install / start / status / upgrade / removal in a scratch Debian root
# (debootstrap) that is thrown away afterwards. Needs root.
PACKAGES     := build/packages
PKG_TABLE    := build/package/tanaka2017.tmx
PACKAGE_APT_PACKAGES := dpkg-dev lintian debootstrap systemd man-db
.PHONY: package package-test setup-package
setup-package:
	@missing=$$(mk/apt-missing.sh $(PACKAGE_APT_PACKAGES)); \
	if [ -n "$$missing" ]; then \
	  echo "setup-package: installing $$missing"; \
	  $(SUDO) apt-get update -qq && DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -qq $$missing >/dev/null; \
	fi

package: setup setup-package check-db build-cpp build-python cross
	@mkdir -p $(dir $(PKG_TABLE)) $(PACKAGES)
	$(TOFMAT) table import $(DB) -o $(PKG_TABLE)
	@for dir in $(BUILD) $(CROSS); do \
	  cmake -S . -B $$dir -DTOFMAT_PACKAGE_TABLE=$(abspath $(PKG_TABLE)) >/dev/null && \
	  cmake --build $$dir -j$(JOBS) --target tofmatd tofmat_package_docs >/dev/null && \
	  arch=$$(grep -q aarch64 $$dir/CMakeCache.txt && echo arm64 || echo amd64) && \
	  (cd $$dir && rm -rf packages && DEB_HOST_ARCH=$$arch cpack -G DEB >/dev/null) && \
	  cp $$dir/packages/tofmatd_*_$$arch.deb $(PACKAGES)/ || exit 1; \
	done
	@ls -l $(PACKAGES)/*.deb

package-test: package
	TOFMAT_DEB_AMD64=$$(ls $(abspath $(PACKAGES))/tofmatd_*_amd64.deb) TOFMAT_DEB_ARM64=$$(ls $(abspath $(PACKAGES))/tofmatd_*_arm64.deb) \
	  TOFMAT_PACKAGE_TABLE=$(abspath $(PKG_TABLE)) TOFMAT_DB_DIR=$(DB) $(PYTHON) -m pytest tests/package -q

$(TABLE): check-db
	$(TOFMAT) table import $(DB) -o $(TABLE)

# tofmatd on the simulated camera (hand-held sweeps of five materials), watched
# through the Python client; records the simulated camera's table once and calibrates it for itself
# (again when the file there is an older tofmat's, without a depth distortion: --keep-current keeps a
# current one, and calibrates it if it has no calibration yet).
SIM_TABLE := build/sim_table.tmx
.PHONY: $(SIM_TABLE)
$(SIM_TABLE):
	$(TOFMAT) sim table --keep-current -o $(SIM_TABLE)

demo: setup build-python $(SIM_TABLE)
	$(TOFMAT) demo --table $(SIM_TABLE)

# The sorting line, simulated end to end (belt, light barrier, camera, outlets) for a minute.
demo-line: setup build-python $(SIM_TABLE)
	$(TOFMAT) line-demo --table $(SIM_TABLE)

# The simulated sorting line over belt speeds, loads and seeds (docs/benchmarks.md): about 20 min.
.PHONY: bench-line
bench-line: setup build-python $(SIM_TABLE)
	$(TOFMAT) bench-line --table $(SIM_TABLE)

bench: setup check-db build-python $(TABLE)
	$(TOFMAT) bench --table $(TABLE)

clean:
	rm -rf build

# Benchmarks of the fixed-point path (issue 5; docs/benchmarks.md), printed as
# markdown: bench-cpp times float vs fixed on this host (one core); bench-cross
# counts guest instructions of the aarch64 build under qemu-aarch64 (scalar vs
# NEON) with a TCG plugin built for the host.
.PHONY: bench-cpp bench-cross
BENCH_DIR    := build/bench
QEMU_PLUGIN  := $(BENCH_DIR)/tests/bench/qemu_insn_count.so

bench-cpp:
	cmake -S . -B $(BENCH_DIR) -G Ninja -DCMAKE_BUILD_TYPE=Release -DTOFMAT_BUILD_TESTS=OFF \
	  -DTOFMAT_WITH_SIM=OFF -DTOFMAT_WITH_LIBUSB=OFF -DTOFMAT_DB_DIR=$(DB) >/dev/null
	cmake --build $(BENCH_DIR) -j$(JOBS) --target tofmat_bench_fixed qemu_insn_count
	$(BENCH_DIR)/tests/bench/tofmat_bench_fixed --op all --db $(DB)

# What each scene profile costs per frame, from the depth packet to the
# event's bytes (docs/benchmarks.md, "The box"): host ms on one core with
# error against truth and the float path, and aarch64 instructions under qemu.
.PHONY: bench-profiles bench-profiles-cross
bench-profiles: check-db build-cpp
	$(BUILD)/tests/bench/tofmat_bench_profiles --profile all --reps 11 --table $(DB)

bench-profiles-cross: cross check-db
	cmake -S . -B $(BENCH_DIR) -G Ninja -DCMAKE_BUILD_TYPE=Release -DTOFMAT_BUILD_TESTS=OFF \
	  -DTOFMAT_WITH_SIM=OFF -DTOFMAT_WITH_LIBUSB=OFF -DTOFMAT_DB_DIR=$(DB) >/dev/null
	cmake --build $(BENCH_DIR) -j$(JOBS) --target qemu_insn_count
	tests/bench/profile_counts.sh $(QEMU_PLUGIN) $(CROSS)/tests/bench/tofmat_bench_profiles $(DB)

# Where one profile's aarch64 instructions go, per function (tests/bench/profile_frame.sh):
#   make profile-frame PROFILE=handheld PROFILE_OPTIONS="--kernel best --no-truth"
PROFILE ?= handheld
PROFILE_OPTIONS ?= --kernel best --no-truth
PROFILE_TABLE ?= $(DB)
.PHONY: profile-frame
profile-frame: cross check-db
	cmake -S . -B $(BENCH_DIR) -G Ninja -DCMAKE_BUILD_TYPE=Release -DTOFMAT_BUILD_TESTS=OFF \
	  -DTOFMAT_WITH_SIM=OFF -DTOFMAT_WITH_LIBUSB=OFF -DTOFMAT_DB_DIR=$(DB) >/dev/null
	cmake --build $(BENCH_DIR) -j$(JOBS) --target qemu_tb_profile
	tests/bench/profile_frame.sh $(BENCH_DIR)/tests/bench/qemu_tb_profile.so $(CROSS)/tests/bench/tofmat_bench_profiles \
	  $(PROFILE_TABLE) $(PROFILE) 2 -- $(PROFILE_OPTIONS)

bench-cross: cross check-db
	cmake -S . -B $(BENCH_DIR) -G Ninja -DCMAKE_BUILD_TYPE=Release -DTOFMAT_BUILD_TESTS=OFF \
	  -DTOFMAT_WITH_SIM=OFF -DTOFMAT_WITH_LIBUSB=OFF -DTOFMAT_DB_DIR=$(DB) >/dev/null
	cmake --build $(BENCH_DIR) -j$(JOBS) --target qemu_insn_count
	tests/bench/insn_counts.sh $(QEMU_PLUGIN) $(CROSS)/tests/bench/tofmat_bench_fixed $(DB)

# Issue 16's attacks on tofmatd, each while a well-behaved subscriber is
# measured (figures only), and the 30-minute soak of them mixed: outside
# `make test` and CI (tests/soak/README.md).
include tests/soak/attacks.mk

# The documentation site: `make docs` (Sphinx, warnings as errors; part of `make test`).
include mk/docs.mk
include mk/lint-cpp.mk

# The error-against-run-time report: `make report` (docs/report.md).
include mk/report.mk

# The classifiers' held-out evaluation: `make evaluate` (docs/evaluation.md).
include mk/evaluate.mk

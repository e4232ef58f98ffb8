# The front door. `make demo` and `make test` each set up what is missing first (Debian
# packages, .venv, builds), so both work on a fresh clone.
#
# One optimised profile (release) for everything: binaries, tests and the extension module share
# one target directory, so dependencies compile once.

SHELL := /bin/bash
CARGO ?= cargo
CARGO_FLAGS := --release --locked
VENV := .venv
PY := $(VENV)/bin/python
LEVEL_PACK := build/temple.pack
GLTF_PACK := build/demo.pack
CHARACTER_PACK := build/golem.pack
BENCH_DIR := build/bench
GLTF_SAMPLES_DIR ?= $(abspath ../shared/gltf-samples)
export GLTF_SAMPLES_DIR

# The cooker extension is rebuilt when any Rust or Python source it is made of changes.
COOKER_SOURCES := $(shell find asset_pipeline engine/pack -name '*.rs' -o -name '*.toml' -o -name '*.py' 2>/dev/null | grep -v __pycache__) Cargo.lock

.PHONY: all setup build cooker demo test test-rust test-python cook bench soak clean fuzz fuzz-build check-long

all: build

setup:
	@bash tools/setup.sh

build: setup
	$(CARGO) build $(CARGO_FLAGS) --workspace --exclude asset_pipeline --lib --bins

cooker: setup $(VENV)/.cooker-built

$(VENV)/.cooker-built: $(COOKER_SOURCES) tools/requirements-dev.txt tools/constraints.txt
	VIRTUAL_ENV=$(abspath $(VENV)) PATH=$(abspath $(VENV))/bin:$$PATH PIP_CONSTRAINT=$(abspath tools/constraints.txt) \
	  $(VENV)/bin/maturin develop --release --locked --extras test,denoise,ray -m asset_pipeline/Cargo.toml -q
	@touch $@

# The project's own content, cooked: the CSG demo level, and a generated glTF scene that keeps
# the glTF path covered without third-party files. The cooker skips what is up to date.
cook: cooker
	@mkdir -p build/content
	$(PY) content/characters/make_creature.py content/levels/characters/golem.gltf
	$(PY) content/birds/make_dove.py content/levels/birds/dove.gltf
	$(PY) content/props/make_lantern.py content/levels/props/lantern.gltf
	$(VENV)/bin/cook content/levels/temple.toml -o $(LEVEL_PACK)
	$(VENV)/bin/cook content/levels/characters/golem.gltf -o $(CHARACTER_PACK)
	$(PY) content/demo/make_scene.py build/content/demo.gltf
	$(VENV)/bin/cook build/content/demo.gltf -o $(GLTF_PACK)

demo: build cook
	target/release/demo $(LEVEL_PACK) $(DEMO_ARGS)

test: build cooker cook
	ENGINE_VALIDATION=1 $(CARGO) test $(CARGO_FLAGS) --workspace --exclude asset_pipeline
	ENGINE_VALIDATION=1 $(PY) -m pytest tests -q -rs

# Every frame-time scenario at 1280x720 (`bench --help`; BENCH_ARGS adds options, e.g.
# BENCH_ARGS="--frames 300"), then the plots and the summary table from build/bench/*.json.
bench: build cook
	target/release/bench --all --json-dir $(BENCH_DIR) $(BENCH_ARGS)
	$(PY) tools/bench_report.py $(BENCH_DIR)

# The validation soak (issues 11, 27): 10,000 headless frames with validation on and every pass
# running (the overlay, a render scale below 1 for the upscale pass; one run with FXAA, one with
# MSAA's resolve); zero validation messages, and the memory allocated (heap and device) at the end
# within 1% of frame 1,000's (tools/soak.py). Outside `make test`.
soak: build cook
	$(PY) tools/soak.py $(SOAK_ARGS)

# Fuzzing (issues 11, 27), outside `make test`: libFuzzer through cargo-fuzz on the readers of
# untrusted input, the pack reader (pack_from_bytes; pack_manifest, which fixes up the length and
# checksum so mutations reach the manifest checks) and glTF import (gltf_import); and atheris
# (libFuzzer for Python, pinned in tools/requirements-dev.txt) on the level TOML loader
# (level_toml: fuzz/python/level_toml.py). The Rust crate is fuzz/, outside the workspace.
# cargo-fuzz's flags (-Zsanitizer=address, -Cpasses=sancov-module) need a nightly toolchain:
# FUZZ_TOOLCHAIN (rustup's `nightly`). Each target runs FUZZ_SECONDS, one job, from corpora that
# tools/fuzz_seed.sh seeds (cooked packs, ../shared/gltf-samples, glTF scenes using each supported
# extension, the project's and the tests' levels); tools/fuzz_run.py prints executions and crashes
# per target. A crash stops its target with the input in fuzz/artifacts/<target>/ (`cargo fuzz
# tmin` minimises a Rust one; it then becomes a regression test in the crate, a level one in
# tests/test_level.py). cargo-fuzz itself is installed into build/tools on first use.
FUZZ_SECONDS ?= 300
FUZZ_TARGETS ?= pack_from_bytes pack_manifest gltf_import level_toml
FUZZ_TOOLCHAIN ?= nightly
export FUZZ_TOOLCHAIN
CARGO_FUZZ := build/tools/bin/cargo-fuzz
FUZZ := PATH=$(abspath build/tools/bin):$$PATH $(CARGO) +$(FUZZ_TOOLCHAIN) fuzz

$(CARGO_FUZZ):
	$(CARGO) install cargo-fuzz --locked --root build/tools

fuzz-build: $(CARGO_FUZZ)
	$(FUZZ) build --fuzz-dir fuzz -O

fuzz: fuzz-build cooker
	bash tools/fuzz_seed.sh
	$(PY) tools/fuzz_run.py $(foreach t,$(FUZZ_TARGETS),$(t)=$(FUZZ_SECONDS))

# The long checks (issue 27), outside `make test`, ~45 min here: the soak above (every pass,
# 2 x CHECK_LONG_FRAMES frames), each fuzz target for its fixed time in CHECK_LONG_FUZZ (chosen so
# each reaches 1,000,000 executions on this 2-core machine: measured 9,000, 5,000, 2,200 and 4,500
# executions a second), and a Ray cook of the demo level with a worker SIGKILLed mid-bake that must
# give `make cook`'s pack and EXR byte for byte (tools/ray_kill_cook.py). tools/check_long.py runs
# them in order and prints the summary table, also written to build/check-long.txt.
CHECK_LONG_FRAMES ?= 10000
CHECK_LONG_FUZZ ?= pack_from_bytes=240 pack_manifest=360 gltf_import=900 level_toml=480

check-long: build cook fuzz-build
	$(PY) tools/check_long.py --frames $(CHECK_LONG_FRAMES) --fuzz "$(CHECK_LONG_FUZZ)"

clean:
	rm -rf build target $(VENV)

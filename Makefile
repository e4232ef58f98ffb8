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

.PHONY: all setup build cooker demo test test-rust test-python cook bench soak clean fuzz fuzz-build

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

# The validation soak (issue 11): 10,000 headless frames with validation on; zero validation
# messages and resident memory after frame 10,000 within 1% of frame 1,000. Outside `make test`.
soak: build cook
	$(PY) tools/soak.py $(SOAK_ARGS)

# Fuzzing (issue 11), outside `make test`: libFuzzer through cargo-fuzz on the readers of untrusted
# input, the pack reader (pack_from_bytes; pack_manifest, which fixes up the length and checksum
# so mutations reach the manifest checks) and glTF import (gltf_import). The crate is fuzz/, outside
# the workspace. cargo-fuzz's flags (-Zsanitizer=address, -Cpasses=sancov-module) need a nightly
# toolchain: FUZZ_TOOLCHAIN (rustup's `nightly`). Each target runs FUZZ_SECONDS, one job, from
# corpora that tools/fuzz_seed.sh seeds (cooked packs, ../shared/gltf-samples); a crash stops the
# run with the input in fuzz/artifacts/<target>/ (`cargo fuzz tmin` minimises it; it then becomes a
# regression test in the crate). cargo-fuzz itself is installed into build/tools on first use.
FUZZ_SECONDS ?= 300
FUZZ_TARGETS ?= pack_from_bytes pack_manifest gltf_import
FUZZ_TOOLCHAIN ?= nightly
CARGO_FUZZ := build/tools/bin/cargo-fuzz
FUZZ := PATH=$(abspath build/tools/bin):$$PATH $(CARGO) +$(FUZZ_TOOLCHAIN) fuzz

$(CARGO_FUZZ):
	$(CARGO) install cargo-fuzz --locked --root build/tools

fuzz-build: $(CARGO_FUZZ)
	$(FUZZ) build --fuzz-dir fuzz -O

fuzz: fuzz-build
	bash tools/fuzz_seed.sh
	@for t in $(FUZZ_TARGETS); do \
	  echo "== fuzz $$t for $(FUZZ_SECONDS) s"; \
	  $(FUZZ) run --fuzz-dir fuzz -O $$t -- -max_total_time=$(FUZZ_SECONDS) -timeout=10 \
	    -rss_limit_mb=2048 -malloc_limit_mb=1024 -print_final_stats=1 2>&1 | tee build/fuzz-$$t.log \
	    | grep -E '^(==|#[0-9]+[[:space:]]+DONE|stat::number_of_executed_units|stat::peak_rss_mb|Done|SUMMARY|Test unit written)'; \
	  [ $${PIPESTATUS[0]} -eq 0 ] || { echo "fuzz $$t: crash, see build/fuzz-$$t.log"; exit 1; }; \
	done

clean:
	rm -rf build target $(VENV)

#!/usr/bin/env bash
# Idempotent machine setup for `make demo` / `make test`: installs only what is missing.
#   1. Debian packages (Vulkan loader, lavapipe, glslc, validation layers, Xvfb, ...)
#   2. the Python venv at .venv with the pinned build and test tools
# The Rust build and the cooker's extension module are built by the Makefile afterwards.
set -euo pipefail
cd "$(dirname "$0")/.."

# Runtime: Vulkan loader + lavapipe + validation layers; build: glslc; window tests: Xvfb and
# the libraries winit loads at run time; screenshots of the X screen: imagemagick's `import`;
# synthetic keys and mouse for the window tests: xdotool (XTEST);
# OpenEXR's own tools (exrheader) to check that our lightmap files are real EXR; a C++ compiler
# for meshoptimizer (the cooker's mesh_opt stage builds it from the meshopt crate's source);
# gdb, so a test whose program hangs fails with every thread's stack (tests/conftest.py's
# run_bounded): a hang seen once in many runs is found from that one failure.
APT_PACKAGES=(
  mesa-vulkan-drivers libvulkan1 vulkan-validationlayers glslc g++
  xvfb xauth libxkbcommon-x11-0 libxcursor1 libxrandr2 libxi6 libx11-xcb1 imagemagick xdotool
  openexr gdb
)

missing=()
for p in "${APT_PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "setup: installing Debian packages: ${missing[*]}"
  SUDO=""
  if [ "$(id -u)" != 0 ]; then
    command -v sudo >/dev/null || { echo "setup: need root (or sudo) to install: ${missing[*]}" >&2; exit 1; }
    SUDO="sudo"
  fi
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

command -v cargo >/dev/null || { echo "setup: cargo not found; install Rust (rustup) first" >&2; exit 1; }

# Python venv with pinned tools. Re-run pip only when the pins change.
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  echo "setup: creating .venv"
  "$PY" -m venv .venv
fi
pins=tools/requirements-dev.txt
stamp=.venv/.pins-installed
if [ ! -f "$stamp" ] || ! cmp -s "$pins" "$stamp"; then
  echo "setup: installing pinned Python tools into .venv"
  .venv/bin/python -m pip install -q --disable-pip-version-check -r "$pins" -c tools/constraints.txt
  cp "$pins" "$stamp"
fi

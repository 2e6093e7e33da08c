#!/usr/bin/env bash
# The README's test command. On a fresh Debian machine with a Rust toolchain it installs the
# system packages the tests need, then runs the whole test suite (one integration binary).
#
#   bash tests/run.sh            # everything that runs on bundled data
#   PYGMALION_DATA=../shared/data bash tests/run.sh   # plus the checks over every real scan
#   PYGMALION_RENDER_TESTS=0 bash tests/run.sh        # without the GPU rendering test
#   bash tests/run.sh kiosk_render                    # only the tests whose name has this
#   bash tests/run.sh --include-ignored               # plus the long tier (regression statues)
#   bash tests/run.sh --ignored                       # the long tier alone
#
# The kiosk's rendering test draws the bundled statue with the real renderer. Without a GPU it
# runs on Mesa's software Vulkan (lavapipe) in a virtual X server (Xvfb), which this script
# installs when apt is there, starts when no display is set, and stops at the end. When neither
# a display nor Xvfb can be had, that test is skipped (it says so) and the rest still runs.
set -euo pipefail
cd "$(dirname "$0")/.."

# System packages: a virtual X server and software Vulkan for the rendering test, and a UI
# font with the typographic characters of the kiosk's texts (Bevy's built-in font is ASCII).
packages=(xvfb mesa-vulkan-drivers libvulkan1 fonts-dejavu-core)
missing=()
if command -v dpkg >/dev/null 2>&1; then
  for p in "${packages[@]}"; do
    dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
  done
fi
as_root() {
  if [ "$(id -u)" -eq 0 ]; then
    env DEBIAN_FRONTEND=noninteractive "$@"
  else
    sudo env DEBIAN_FRONTEND=noninteractive "$@"
  fi
}
if [ ${#missing[@]} -gt 0 ]; then
  if ! command -v apt-get >/dev/null 2>&1; then
    echo "tests/run.sh: no apt-get; not installing ${missing[*]}" >&2
  elif [ "$(id -u)" -ne 0 ] && ! command -v sudo >/dev/null 2>&1; then
    echo "tests/run.sh: not root and no sudo; not installing ${missing[*]}" >&2
  else
    echo "tests/run.sh: installing ${missing[*]}" >&2
    { as_root apt-get update -q &&
      as_root apt-get install -y -q --no-install-recommends "${missing[@]}"; } ||
      echo "tests/run.sh: could not install ${missing[*]}; the rendering test may be skipped" >&2
  fi
fi

# A display for the rendering test: the caller's, or a virtual one on a free display number.
xvfb_pid=""
cleanup() {
  if [ -n "$xvfb_pid" ]; then
    kill "$xvfb_pid" 2>/dev/null || true
    wait "$xvfb_pid" 2>/dev/null || true
  fi
}
trap cleanup EXIT
if [ -z "${DISPLAY:-}" ] && command -v Xvfb >/dev/null 2>&1; then
  n=99
  while [ -e "/tmp/.X11-unix/X$n" ] || [ -e "/tmp/.X$n-lock" ]; do
    n=$((n + 1))
  done
  Xvfb ":$n" -screen 0 1280x1024x24 -nolisten tcp >/dev/null 2>&1 &
  xvfb_pid=$!
  for _ in $(seq 1 50); do
    [ -e "/tmp/.X11-unix/X$n" ] && break
    kill -0 "$xvfb_pid" 2>/dev/null || break
    sleep 0.1
  done
  if [ -e "/tmp/.X11-unix/X$n" ]; then
    export DISPLAY=":$n"
  else
    echo "tests/run.sh: Xvfb did not start; the rendering test will be skipped" >&2
    cleanup
    xvfb_pid=""
  fi
fi
if [ -z "${XDG_RUNTIME_DIR:-}" ]; then
  export XDG_RUNTIME_DIR="/tmp/xdg-runtime-$(id -u)"
fi
mkdir -p -m 700 "$XDG_RUNTIME_DIR" 2>/dev/null || true
if [ -n "${DISPLAY:-}" ]; then
  export PYGMALION_RENDER_TESTS="${PYGMALION_RENDER_TESTS:-1}"
fi

cargo test --locked --test integration -- --test-threads 2 "$@"

#!/usr/bin/env bash
# The README's test command. On a fresh Debian machine with a Rust toolchain it installs the
# system packages the tests need, then runs the whole test suite (one integration binary).
#
#   bash tests/run.sh            # everything that runs on bundled data
#   PYGMALION_DATA=../shared/data bash tests/run.sh   # plus the checks over every real scan
set -euo pipefail
cd "$(dirname "$0")/.."

# System packages (none are needed by the core tests yet; rendering tests will add Xvfb and
# Mesa's software Vulkan here).
packages=()
missing=()
for p in "${packages[@]}"; do
  dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  sudo_cmd=""
  [ "$(id -u)" -ne 0 ] && sudo_cmd="sudo"
  $sudo_cmd apt-get update -q
  $sudo_cmd apt-get install -y -q --no-install-recommends "${missing[@]}"
fi

cargo test --locked --test integration -- --test-threads 2

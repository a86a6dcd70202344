#!/usr/bin/env bash
# The live soak (issue 38): `parallax serve` of the 16-projector wall under
# `mpirun -n 3`, one client driving it quietly, then for SECONDS (default
# 600) beside a hostile client mix on loopback (a flood never read, 2 MiB
# messages, sockets that never finish their header, a reconnect storm,
# garbage, recordings started and stopped, a page that reads nothing).
# Passes when the driver's rate stays within 20 % of the quiet one, no
# input waits over 5 s, a new page is served within 2 s, and memory stays
# flat. Run from the repository root:
#   bash bench/live_soak.sh [SECONDS]
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/setup.sh
cargo build --release --locked 2>&1 | tail -n 1
PARALLAX_SOAK_SECS=${1:-600} cargo test --release --locked --test live \
  a_hostile_client_mix -- --ignored --nocapture 2>&1 | grep -vE '^serve: |^$'

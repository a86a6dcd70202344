#!/usr/bin/env bash
# Input to new frame in the live coordinator, as a WebSocket client sees it,
# for the desktop view and the 8-projector wall, embedded on this machine.
#   bash bench/live_latency.sh [INPUTS]      (default 200 rotations each)
set -euo pipefail
cd "$(dirname "$0")/.."
. scripts/setup.sh
set +e
PARALLAX_LATENCY_INPUTS="${1:-200}" cargo test --release --locked --test live latency -- --ignored --nocapture 2>&1 \
  | grep -E "^latency|test result"

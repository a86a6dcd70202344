#!/bin/bash
# The longer fuzzing run: every parser for SECONDS (default 300) each, from
# the committed seeds (scripts/fuzz.sh; figures in out/fuzz/summary.tsv).
# A finding goes to fuzz/regressions/<target>/ once fixed, where
# `cargo test --test fuzz` replays it.
set -euo pipefail
cd "$(dirname "$0")/.."
exec bash scripts/fuzz.sh "${1:-300}"

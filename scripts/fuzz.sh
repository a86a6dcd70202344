#!/bin/bash
# Coverage-guided fuzzing of every parser (libFuzzer through libfuzzer-sys,
# on stable Rust: the instrumentation is sanitizer coverage, as cargo-fuzz
# sets it, without a sanitizer).
#
#   scripts/fuzz.sh [SECONDS_PER_TARGET] [TARGET ...]
#
# Builds fuzz/ (its own workspace, target folder fuzz/target), then runs each
# target (default: all of parallax_fuzz::TARGETS) for SECONDS_PER_TARGET
# (default 10) from its seeds in fuzz/corpus/<target>/, keeping what it
# finds in out/fuzz/<target>/ (new inputs in corpus/, a failing input as
# crash-*, timeout-* or oom-*). An input that takes over 2 s is a failure:
# every parser must answer within a second. Prints each target's
# executions, coverage and findings, writes them to out/fuzz/summary.tsv,
# and exits non-zero if any target found something. The test command runs
# it briefly with PARALLAX_FUZZ_SEED=1 (libFuzzer's -seed: a run that was
# clean stays clean); bench/fuzz.sh runs it for longer from random seeds.
set -euo pipefail
cd "$(dirname "$0")/.."
SECS=${1:-10}
shift || true
TARGETS=("$@")
if [ ${#TARGETS[@]} -eq 0 ]; then
  TARGETS=(nrrd nhdr nifti raw dicom tiff pxo toml preset live wire zarr)
fi
export RUSTFLAGS="-Cpasses=sancov-module -Cllvm-args=-sanitizer-coverage-level=4 \
-Cllvm-args=-sanitizer-coverage-inline-8bit-counters -Cllvm-args=-sanitizer-coverage-pc-table \
-Cllvm-args=-sanitizer-coverage-trace-compares --cfg fuzzing -Cdebug-assertions -Coverflow-checks"
# With an explicit --target, RUSTFLAGS reach the crates of the binary but
# not build scripts and proc macros (which must not be instrumented).
HOST=$(rustc -vV | sed -n 's/^host: //p')
(cd fuzz && cargo build --release --locked --target "$HOST" --bin parallax-fuzz 2>&1 | tail -3)
BIN=fuzz/target/$HOST/release/parallax-fuzz
mkdir -p out/fuzz
SUMMARY=out/fuzz/summary.tsv
printf 'target\tseconds\texecutions\texec_per_s\tcoverage\tcorpus\tfindings\n' > "$SUMMARY"
failed=0
for t in "${TARGETS[@]}"; do
  dir=out/fuzz/$t
  rm -rf "$dir"
  mkdir -p "$dir/corpus"
  set +e
  PARALLAX_FUZZ=$t "$BIN" "$dir/corpus" "fuzz/corpus/$t" \
    -max_total_time="$SECS" -timeout=2 -rss_limit_mb=2048 -max_len=65536 \
    -print_final_stats=1 -artifact_prefix="$dir/" ${PARALLAX_FUZZ_SEED:+-seed=$PARALLAX_FUZZ_SEED} \
    > "$dir/log.txt" 2>&1
  rc=$?
  set -e
  runs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$dir/log.txt" | grep -o '[0-9]*$' || echo 0)
  cov=$(grep -o 'cov: [0-9]*' "$dir/log.txt" | tail -1 | grep -o '[0-9]*' || echo 0)
  corpus=$(ls "$dir/corpus" | wc -l)
  findings=$(ls "$dir" | grep -cE '^(crash|timeout|oom|leak|slow-unit)-' || true)
  printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$t" "$SECS" "$runs" "$((runs / SECS))" "$cov" "$corpus" "$findings" >> "$SUMMARY"
  printf '%-7s %8s executions in %s s, coverage %s, %s new inputs, %s findings\n' \
    "$t" "$runs" "$SECS" "$cov" "$corpus" "$findings"
  if [ "$rc" -ne 0 ] || [ "$findings" -ne 0 ]; then
    failed=1
    echo "fuzz: $t found a failure (exit $rc); the input and log are in $dir:" >&2
    grep -E 'panicked|ERROR|SUMMARY|Test unit written' "$dir/log.txt" | head -8 >&2
  fi
done
exit $failed

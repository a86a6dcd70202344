#!/usr/bin/env bash
# The test command: installs what is missing, builds, runs every test
# (unit, integration, GPU on whatever adapter there is — lavapipe without a
# GPU — and multi-rank tests under mpirun).
set -euo pipefail
cd "$(dirname "$0")/.."
# pydicom and tifffile write the DICOM series and TIFF stacks the input tests
# read; the live page is tested in a real browser (headless Chromium). The
# presented windows are tested on an X server of their own (Xvfb).
PARALLAX_EXTRA_PACKAGES="python3-pydicom python3-tifffile python3-numpy python3-venv chromium xvfb libxcb1" . scripts/setup.sh
# The OME-Zarr images of tests/zarr.rs come from the ome-zarr and zarr
# packages (not in Debian 12), its 4-D NIfTI from nibabel, pinned, in a
# virtual environment of their own.
if ! target/py-zarr/bin/python -c "import ome_zarr, zarr, numcodecs, nibabel" 2>/dev/null; then
  rm -rf target/py-zarr
  /usr/bin/python3 -m venv target/py-zarr
  target/py-zarr/bin/pip install -q zarr==3.1.6 ome-zarr==0.18.0 numcodecs==0.16.6 nibabel==5.3.2
fi
cargo build --release --locked 2>&1 | tail -n 3
log=$(mktemp)
trap 'rm -f "$log"' EXIT
status=0
cargo test --release --locked --workspace 2>&1 | tee "$log" || status=$?
echo
awk '/^test result:/ { for (i = 1; i <= NF; i++) { if ($(i+1) ~ /^passed/) p += $i; if ($(i+1) ~ /^failed/) f += $i } }
     END { printf "tests: %d passed, %d failed\n", p, f }' "$log"
# Coverage-guided fuzzing of every parser, time-boxed (10 s a target; the
# longer run is bench/fuzz.sh). A finding fails the test command.
echo
echo "fuzzing (scripts/fuzz.sh 10):"
PARALLAX_FUZZ_SEED=1 bash scripts/fuzz.sh 10 || status=1
exit $status

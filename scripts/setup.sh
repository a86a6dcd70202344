#!/usr/bin/env bash
# Installs what Parallax needs on a Debian machine, skipping what is there:
# MPI (OpenMPI + headers, libclang for the bindings), the Vulkan software
# rasteriser (lavapipe) for machines without a GPU, and the Colin27 head MRI
# used by the demo and the tests.
set -euo pipefail

packages=(openmpi-bin libopenmpi-dev libclang-dev clang pkg-config mesa-vulkan-drivers libvulkan1 mricron-data)
# What a caller needs beyond that (the tests: the independent DICOM and TIFF
# writers their inputs come from).
read -r -a extra <<< "${PARALLAX_EXTRA_PACKAGES:-}"
packages+=("${extra[@]}")
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
  echo "installing: ${missing[*]}"
  SUDO=""
  [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

if ! command -v cargo >/dev/null 2>&1; then
  [ -f "$HOME/.cargo/env" ] && . "$HOME/.cargo/env"
fi
command -v cargo >/dev/null 2>&1 || { echo "cargo not found: install Rust (rustup) first" >&2; exit 1; }

# OpenMPI refuses to run as root, and more ranks than cores, unless told.
if [ "$(id -u)" -eq 0 ]; then
  export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
fi
export OMPI_MCA_rmaps_base_oversubscribe=1

# Vulkan loaders look for a per-user runtime folder; give them one when a
# headless session has none.
if [ -z "${XDG_RUNTIME_DIR:-}" ]; then
  export XDG_RUNTIME_DIR="${TMPDIR:-/tmp}/parallax-runtime-$(id -u)"
  mkdir -p "$XDG_RUNTIME_DIR" && chmod 700 "$XDG_RUNTIME_DIR"
fi

#!/usr/bin/env bash
# Installs the Debian 12 packages caps needs to build, test and run its demo.
# Safe to run again: it installs only what is missing. docs/dependencies.md says why each one is here.
set -euo pipefail

packages=(
  build-essential cmake pkg-config
  libeigen3-dev libcgal-dev libopenvdb-dev libboost-iostreams-dev libtbb-dev
  libsuitesparse-dev libmumps-seq-dev libopenblas0-pthread libgdcm-dev libgdcm-tools
  nlohmann-json3-dev libcli11-dev libgtest-dev libbenchmark-dev
  libnifti2-dev libteem-dev libarchive-dev libpng-dev zlib1g-dev
  libcairo2-dev fonts-dejavu-core libtinygltf-dev libjpeg-dev libembree-dev libgif-dev
  libcpp-httplib-dev
  invesalius-examples mricron-data
  calculix-ccx
  python3-dev python3-pybind11 python3-numpy python3-pytest snakemake
)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi
echo "caps setup: installing ${missing[*]}" >&2
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null

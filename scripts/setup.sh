#!/usr/bin/env bash
# Installs the Debian 12 packages caps needs to build, test and run its demo.
# Safe to run again: it installs only what is missing. docs/dependencies.md says why each one is here.
set -euo pipefail

packages=(
  build-essential cmake pkg-config ccache
  libeigen3-dev libcgal-dev libopenvdb-dev libboost-iostreams-dev libtbb-dev
  libsuitesparse-dev libmumps-seq-dev libopenblas0-pthread libgdcm-dev libgdcm-tools
  nlohmann-json3-dev libcli11-dev libgtest-dev libbenchmark-dev
  libnifti2-dev libteem-dev libarchive-dev libpng-dev zlib1g-dev
  libcairo2-dev fonts-dejavu-core libtinygltf-dev libjpeg-dev libembree-dev libgif-dev
  libcpp-httplib-dev libopen3d-dev
  invesalius-examples mricron-data
  calculix-ccx
  poppler-utils
  chromium
  clang libclang-rt-14-dev
  python3-dev python3-pybind11 python3-numpy python3-pytest snakemake python3-matplotlib
  python3-pydicom python3-nibabel
  python3-vtk9 python3-jsonschema
)
# node and npm bundle the planner page (web/); Debian's only when no node is installed already.
if ! command -v node >/dev/null 2>&1; then packages+=(nodejs npm); fi

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -ne 0 ]; then
  echo "caps setup: installing ${missing[*]}" >&2
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

# The planner page's packages (three.js, three-mesh-bvh, esbuild, playwright-core), exactly as
# web/package-lock.json pins them, when web/node_modules is missing or older than the lock file.
# Playwright drives the chromium installed above: it downloads no browser of its own.
web="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)/web"
if [ ! -f "$web/node_modules/.package-lock.json" ] ||
   [ "$web/package-lock.json" -nt "$web/node_modules/.package-lock.json" ]; then
  echo "caps setup: npm ci in $web" >&2
  (cd "$web" && PLAYWRIGHT_SKIP_BROWSER_DOWNLOAD=1 npm ci --no-audit --no-fund >/dev/null)
fi

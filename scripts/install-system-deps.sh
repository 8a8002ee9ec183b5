#!/usr/bin/env bash
# Installs the system libraries voxwarp needs when they are missing (Debian/Ubuntu).
# As root it installs them with apt-get; otherwise it prints the command to run.
#   OpenGL through EGL (headless rendering, Mesa llvmpipe on machines without a GPU):
#     libegl1 libgl1 libegl-mesa0 libgl1-mesa-dri
set -euo pipefail

missing=()
have_lib() { ldconfig -p 2>/dev/null | grep -q "$1"; }
have_lib 'libEGL.so.1' || missing+=(libegl1)
have_lib 'libGL.so.1' || missing+=(libgl1)
have_lib 'libEGL_mesa.so.0' || missing+=(libegl-mesa0)
ls /usr/lib/*/dri/swrast_dri.so >/dev/null 2>&1 || ls /usr/lib/*/dri/libdril_dri.so >/dev/null 2>&1 \
  || missing+=(libgl1-mesa-dri)

if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi
if ! command -v apt-get >/dev/null 2>&1; then
  echo "voxwarp: please install OpenGL/EGL (Mesa) libraries: ${missing[*]} (Debian names)" >&2
  exit 0
fi
if [ "$(id -u)" -ne 0 ]; then
  echo "voxwarp: missing system packages: ${missing[*]}" >&2
  echo "voxwarp: run: sudo apt-get install -y ${missing[*]}" >&2
  exit 0
fi
echo "voxwarp: installing system packages: ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq
apt-get install -y -qq --no-install-recommends "${missing[@]}"

#!/usr/bin/env bash
# Installs the system libraries voxwarp needs when they are missing (Debian/Ubuntu).
# As root it installs them with apt-get; otherwise it prints the command to run.
#   OpenGL through EGL (headless rendering, Mesa llvmpipe on machines without a GPU):
#     libegl1 libgl1 libegl-mesa0 libgl1-mesa-dri
#   The desktop GUI (PySide6 on X11/xcb) and its tests (a private Xvfb server):
#     xvfb xauth libglib2.0-0 libxkbcommon0 libxkbcommon-x11-0 libfontconfig1 libfreetype6
#     libdbus-1-3 libxcb-cursor0 libxcb-icccm4 libxcb-image0 libxcb-keysyms1
#     libxcb-render-util0 libxcb-shape0 libxcb-xkb1 libxcb-randr0 libxcb-xfixes0 libx11-xcb1
#   An OpenCL driver for the CPU when none is registered (the wire field's build):
#     pocl-opencl-icd. The PoCL that pyopencl's wheels bundle builds no kernel on CPUs
#     its LLVM does not know (AMD Zen 5 with its LLVM 14: "unknown target CPU
#     'generic'"); the distribution's PoCL does, and voxwarp takes the first device
#     whose kernels build.
set -euo pipefail

missing=()
have_lib() { ldconfig -p 2>/dev/null | grep -q "$1"; }
have_lib 'libEGL.so.1' || missing+=(libegl1)
have_lib 'libGL.so.1' || missing+=(libgl1)
have_lib 'libEGL_mesa.so.0' || missing+=(libegl-mesa0)
ls /usr/lib/*/dri/swrast_dri.so >/dev/null 2>&1 || ls /usr/lib/*/dri/libdril_dri.so >/dev/null 2>&1 \
  || missing+=(libgl1-mesa-dri)
command -v Xvfb >/dev/null 2>&1 || missing+=(xvfb)
command -v xauth >/dev/null 2>&1 || missing+=(xauth)
have_lib 'libglib-2.0.so.0' || missing+=(libglib2.0-0)
have_lib 'libxkbcommon.so.0' || missing+=(libxkbcommon0)
have_lib 'libxkbcommon-x11.so.0' || missing+=(libxkbcommon-x11-0)
have_lib 'libfontconfig.so.1' || missing+=(libfontconfig1)
have_lib 'libfreetype.so.6' || missing+=(libfreetype6)
have_lib 'libdbus-1.so.3' || missing+=(libdbus-1-3)
have_lib 'libX11-xcb.so.1' || missing+=(libx11-xcb1)
ls /etc/OpenCL/vendors/*.icd >/dev/null 2>&1 || missing+=(pocl-opencl-icd)
for pair in cursor:0 icccm:4 image:0 keysyms:1 render-util:0 shape:0 xkb:1 randr:0 xfixes:0; do
  have_lib "libxcb-${pair%%:*}.so" || missing+=("libxcb-${pair%%:*}${pair##*:}")
done

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

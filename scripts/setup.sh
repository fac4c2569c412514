#!/usr/bin/env bash
# Installs every Debian package gearpulse needs to build, test and run its demo.
# Safe to run again; needs root (or sudo) on Debian 12.
set -euo pipefail
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
packages=(
  build-essential cmake pkg-config clang-format ccache
  libasound2-dev alsa-utils
  libgps-dev gpsd gpsd-clients python3-gps
  libeigen3-dev libnlopt-cxx-dev libspdlog-dev catch2
  libgpiod-dev gpiod libsystemd-dev
  libtomlplusplus-dev nlohmann-json3-dev libcli11-dev
  libsndfile1-dev libfftw3-dev
  scdoc
)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "setup: installing ${missing[*]}"
  $SUDO apt-get update -q
  $SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
else
  echo "setup: all packages present"
fi
# gpsd's own service must not hold the default port or a device while tests start their own gpsd.
if command -v systemctl >/dev/null 2>&1 && systemctl is-active --quiet gpsd.socket 2>/dev/null; then
  $SUDO systemctl stop gpsd.socket gpsd.service || true
fi

#!/usr/bin/env bash
# Debian packages for headless GL (EGL, Mesa llvmpipe), the virtual display used by GUI tests, and the C compiler
# that builds the primitives' display march (models/avatars/primitives/native.py; without it the torch march shows).
# Installs only when running as root and something is missing; otherwise says what to install.
set -euo pipefail
PKGS=(libegl1 libegl-mesa0 libgl1-mesa-dri libgles2 libglx-mesa0 xvfb xauth gcc libc6-dev)
missing=()
for p in "${PKGS[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
    echo "system packages: present"
    exit 0
fi
if [ "$(id -u)" -eq 0 ]; then
    echo "system packages: installing ${missing[*]}"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends "${missing[@]}"
else
    echo "system packages missing (run as root to install): ${missing[*]}" >&2
fi

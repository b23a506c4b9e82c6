#!/usr/bin/env bash
# Debian packages for headless GL (EGL, Mesa llvmpipe), the virtual display used by GUI tests, the C compiler
# that builds the primitives' display march (models/avatars/primitives/native.py; without it the torch march shows),
# Chromium for the tests that open exported avatars in a browser (app/chromium.py), Blender (and the numpy its glTF
# importer needs) for the test that imports them into Blender, and Node.js with npm where there is none (the glTF
# validator and three.js come from npm: scripts/setup_python.sh).
# Installs only when running as root and something is missing; otherwise says what to install. The Makefile runs it
# again whenever this file changes, so a machine set up before a package was added gets it.
set -euo pipefail
PKGS=(libegl1 libegl-mesa0 libgl1-mesa-dri libgles2 libglx-mesa0 xvfb xauth gcc libc6-dev chromium blender python3-numpy)
missing=()
for p in "${PKGS[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
# Node.js may come from elsewhere than Debian (NodeSource bundles npm): only its commands are looked for.
command -v node >/dev/null || missing+=(nodejs)
command -v npm >/dev/null || missing+=(npm)
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

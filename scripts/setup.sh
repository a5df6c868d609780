#!/bin/sh
# Installs what mcpt needs on Debian 12 (as root, or through sudo), builds it, and renders the
# default scene to cornell-box.exr and cornell-box.png.  Safe to run again.
set -eu
cd "$(dirname "$0")/.."

PKGS="gcc make pkg-config libc6-dev libopenexr-dev libpng-dev libcriterion-dev"
missing=""
for p in $PKGS; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" ||
        missing="$missing $p"
done
if [ -n "$missing" ]; then
    if [ "$(id -u)" -eq 0 ]; then
        SUDO=""
    elif command -v sudo >/dev/null 2>&1; then
        SUDO="sudo"
    else
        echo "setup: error: expected root or sudo to install:$missing" >&2
        exit 1
    fi
    echo "setup: installing:$missing"
    # env, not a plain assignment: sudo's env_reset would drop DEBIAN_FRONTEND.
    if ! { $SUDO apt-get update -qq &&
           $SUDO env DEBIAN_FRONTEND=noninteractive \
               apt-get install -y -qq --no-install-recommends $missing; }; then
        echo "setup: error: expected apt-get to install:$missing" >&2
        exit 1
    fi
fi

make -j"$(nproc)"
./mcpt scenes/cornell-box.txt -o cornell-box.exr
echo "setup: wrote cornell-box.exr and cornell-box.png"

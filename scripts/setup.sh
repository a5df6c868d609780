#!/bin/sh
# Installs what mcpt and its test suite need on Debian 12 (as root, or through sudo), builds it,
# and renders the default scene to cornell-box.exr and cornell-box.png, unless those are newer
# than ./mcpt and the scene's files.  Safe to run again.
#   sh scripts/setup.sh              all three steps
#   sh scripts/setup.sh --packages   print the package list only (.ci/run installs the same)
#   sh scripts/setup.sh --render     only the last step, the render (or its skip)
set -eu
cd "$(dirname "$0")/.."

# to build: the compiler, make, pkg-config, OpenEXR's C API, libpng.  For `make test`:
# Criterion; GNU parallel (the distributed-rendering test), tmux (the progress line in a real
# terminal), openexr (exrheader, which reads mcpt's EXR metadata as other tools do).
PKGS="gcc make pkg-config libc6-dev libopenexr-dev libpng-dev libcriterion-dev"
PKGS="$PKGS parallel tmux openexr"

install_packages() {
    missing=""
    for p in $PKGS; do
        dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" ||
            missing="$missing $p"
    done
    [ -n "$missing" ] || return 0
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
}

# The render takes about 95 CPU-seconds: skipped when both images are newer than everything
# they come from (the binary, the scene, its model and materials).
render() {
    scene=scenes/cornell-box.txt
    is_fresh=yes
    for f in ./mcpt "$scene" scenes/models/CornellBox-Original.obj \
             scenes/models/CornellBox-Original.mtl; do
        [ cornell-box.exr -nt "$f" ] && [ cornell-box.png -nt "$f" ] || is_fresh=no
    done
    if [ "$is_fresh" = yes ]; then
        echo "setup: cornell-box.exr and cornell-box.png are newer than ./mcpt and $scene:" \
             "not rendered again (delete them to render)"
        return 0
    fi
    ./mcpt "$scene" -o cornell-box.exr
    echo "setup: wrote cornell-box.exr and cornell-box.png"
}

case "${1:-}" in
--packages)
    echo "$PKGS" ;;
--render)
    render ;;
"")
    install_packages
    make -j"$(nproc)"
    render ;;
*)
    echo "setup: error: expected no option, --packages or --render, got '$1'" >&2
    exit 2 ;;
esac

#!/usr/bin/env bash
# Installs what GMA needs on a fresh Debian/Ubuntu machine, skipping what is already there.
# - a Vulkan driver: Mesa's lavapipe (CPU) when no Vulkan ICD is present, xvfb for window tests;
# - torch pinned first, so that the CPU wheel is used instead of the multi-GB CUDA build;
# - this package in editable mode, with the SMPL-X, viewer (Dear ImGui), cluster (Ray, for gma batch) and dev extras;
# - with LAVAPIPE=backports (opt-in: `make install LAVAPIPE=backports`), on Debian 12 Mesa 25's lavapipe from
#   bookworm-backports, on Debian 13 Mesa 26's from trixie-backports, for this user beside the system's Mesa
#   (scripts/lavapipe_backport.py: checked against Debian's signed index, listed in the Vulkan loader's per-user
#   folder; `python3 scripts/lavapipe_backport.py remove` takes it out again).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
case "${LAVAPIPE:-system}" in
    system|backports) ;;
    *) echo "[install] LAVAPIPE=${LAVAPIPE}: use system (the default) or backports" >&2; exit 2 ;;
esac

have_vulkan_icd() {
    local f
    for f in /usr/share/vulkan/icd.d/*.json /etc/vulkan/icd.d/*.json; do
        [ -e "$f" ] && return 0
    done
    return 1
}

need_apt=()
have_vulkan_icd || need_apt+=(mesa-vulkan-drivers libvulkan1)
command -v Xvfb >/dev/null 2>&1 || need_apt+=(xvfb)
if [ ${#need_apt[@]} -gt 0 ]; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
        echo "[install] apt-get install ${need_apt[*]}"
        export DEBIAN_FRONTEND=noninteractive
        apt-get update -qq
        apt-get install -y -qq "${need_apt[@]}" >/dev/null
    else
        echo "[install] missing system packages: ${need_apt[*]} (install them with your package manager)" >&2
    fi
fi

if ! "$PY" -c "import torch" >/dev/null 2>&1; then
    echo "[install] pip install torch==2.13.0"
    "$PY" -m pip install -q torch==2.13.0
fi

stamp=.gma-installed
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
    echo "[install] pip install -e .[smplx,viewer,cluster,dev]"
    "$PY" -m pip install -q -e ".[smplx,viewer,cluster,dev]"
    touch "$stamp"
fi

# Debian 12's own lavapipe (Mesa 22.3) and Debian 13's (Mesa 25.0) render markedly slower than their backports'
# (docs/design.md); offline, the system's is used. As root, the few libraries the backport links against that
# the system's Mesa did not pull in are installed too (Debian 13: libdisplay-info2).
if [ "${LAVAPIPE:-system}" = backports ]; then
    lavapipe_args=()
    [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1 && lavapipe_args+=(--with-dependencies)
    if ! "$PY" scripts/lavapipe_backport.py install "${lavapipe_args[@]}"; then
        echo "[install] keeping the system's lavapipe" >&2
    fi
elif grep -qsE '^VERSION_CODENAME="?(bookworm|trixie)' /etc/os-release \
        && [ ! -e "${XDG_DATA_HOME:-$HOME/.local/share}/vulkan/icd.d/gma_lavapipe_backport.json" ]; then
    echo "[install] renders faster on lavapipe with the backports' Mesa: make install LAVAPIPE=backports (README, Settings)"
fi

# --- Web export (gma export avatar.gma page.html) -------------------------------------------------------------
# node and npm build the page's JavaScript (web/: Spark and three.js, pinned in web/package-lock.json) into
# web/dist/gma-page.js; Debian's chromium runs the page's tests headless. Both are optional: without them
# the export says what is missing and the browser tests are skipped with the reason.
web_apt=()
command -v npm >/dev/null 2>&1 || web_apt+=(nodejs npm)
command -v chromium >/dev/null 2>&1 || command -v chromium-browser >/dev/null 2>&1 || web_apt+=(chromium)
if [ ${#web_apt[@]} -gt 0 ]; then
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
        echo "[install] apt-get install ${web_apt[*]} (web export)"
        export DEBIAN_FRONTEND=noninteractive
        if ! { apt-get update -qq && apt-get install -y -qq "${web_apt[@]}" >/dev/null; }; then
            echo "[install] could not install ${web_apt[*]}; web pages cannot be exported or tested" >&2
        fi
    else
        echo "[install] missing for the web export: ${web_apt[*]} (install them with your package manager)" >&2
    fi
fi
web_bundle=web/dist/gma-page.js
if command -v npm >/dev/null 2>&1; then
    if [ ! -f "$web_bundle" ] || [ web/package-lock.json -nt "$web_bundle" ] || [ web/src/page.js -nt "$web_bundle" ]; then
        echo "[install] npm ci && npm run build in web/"
        if ! (cd web && npm ci --no-audit --no-fund --loglevel=error && npm run build --silent); then
            echo "[install] could not build $web_bundle; gma export ... .html will say so" >&2
        fi
    fi
fi

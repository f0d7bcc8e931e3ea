#!/usr/bin/env bash
# Screenshot of the rerun viewer showing an .rrd recording, rendered headless (docs tool, not part of CI).
#
#   scripts/screenshot_rrd.sh outputs/rollout.rrd docs/images/rerun_rollout.png [1600x1000]
#
# Uses the viewer of the installed rerun-sdk (0.33+: `rerun --headless --screenshot-to`): no browser and no
# display needed, but a Vulkan or OpenGL driver is; on a headless Debian/Ubuntu machine the software one
# (llvmpipe/lavapipe) is `apt-get install mesa-vulkan-drivers`. The layout is the blueprint stored in the
# recording (RolloutLogger.blueprint() for lerobot-efm-log-rollouts): the first episode's tab, time cursor at the end
# (the recording is compacted first, into a temporary file, so that it is all loaded when the shot is taken).
# The headless viewer renders 2 pixels per point; the png is scaled back to WIDTHxHEIGHT pixels (smaller file
# for the README) with Pillow when the venv has it (FULL_RES=1 keeps the 2x image).
# Env: RERUN (viewer binary; default .venv/bin/rerun, else rerun on PATH), RERUN_RENDERER (vulkan | gl),
# TIMEOUT (seconds, default 180).
set -euo pipefail

if [[ $# -lt 2 || $# -gt 3 ]]; then
    echo "usage: $0 RECORDING.rrd OUTPUT.png [WIDTHxHEIGHT]" >&2
    exit 2
fi
rrd=$1
png=$2
size=${3:-1600x1000}
[[ -f $rrd ]] || { echo "error: no recording at '$rrd'" >&2; exit 1; }
[[ $size =~ ^[0-9]+x[0-9]+$ ]] || { echo "error: window size must be WIDTHxHEIGHT, got '$size'" >&2; exit 1; }

repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
rerun_bin=${RERUN:-}
if [[ -z $rerun_bin ]]; then
    if [[ -x $repo/.venv/bin/rerun ]]; then rerun_bin=$repo/.venv/bin/rerun; else rerun_bin=$(command -v rerun || true); fi
fi
[[ -n $rerun_bin && -x $rerun_bin ]] || { echo "error: rerun viewer not found (pip install rerun-sdk, or set RERUN=...)" >&2; exit 1; }

mkdir -p "$(dirname "$png")"
runtime=$(mktemp -d)
log=$runtime/viewer.log
trap 'rm -rf "$runtime"' EXIT
rm -f "$png"
# The viewer screenshots once its first frames are drawn, while a long recording is still loading (a 22 MB,
# 4,853-chunk store_pot rollout showed step 365 of 878): compacted first (`rerun rrd optimize`: 153 chunks), it
# loads at once and the cursor really is at the end.
compact=$runtime/compact.rrd
if ! "$rerun_bin" rrd optimize "$rrd" >"$compact" 2>"$runtime/optimize.log"; then
    echo "error: 'rerun rrd optimize $rrd' failed; its log:" >&2
    cat "$runtime/optimize.log" >&2
    exit 1
fi
args=("$compact" --headless --screenshot-to "$png" --window-size "$size" --port auto --hide-welcome-screen)
[[ -n ${RERUN_RENDERER:-} ]] && args+=(--renderer "$RERUN_RENDERER")
# RUST_LOG=warn: info messages ("Loading ...", "Listening for gRPC ...") would show as toasts on the screenshot
if ! XDG_RUNTIME_DIR=$runtime RUST_LOG=${RUST_LOG:-warn} timeout "${TIMEOUT:-180}" "$rerun_bin" "${args[@]}" >"$log" 2>&1 \
        || [[ ! -s $png ]]; then
    echo "error: the headless viewer did not write '$png'; its log:" >&2
    cat "$log" >&2
    exit 1
fi
py=$repo/.venv/bin/python
if [[ -z ${FULL_RES:-} && -x $py ]] && "$py" -c "import PIL" 2>/dev/null; then
    "$py" - "$png" "${size%x*}" "${size#*x}" <<'PY'
import sys
from PIL import Image

path, w, h = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
img = Image.open(path)
if img.size != (w, h):
    img.convert("RGB").resize((w, h), Image.LANCZOS).save(path, optimize=True)
PY
fi
echo "wrote $png from $rrd"

#!/usr/bin/env bash
# Creates .venv (Python 3.12, pinned by .python-version) with lerobot 0.6.1 and this plugin installed
# in editable mode, plus Debian libraries: EGL/Mesa for MuJoCo's offscreen rendering (MUJOCO_GL=egl) and
# the FFmpeg 5 shared libraries that torchcodec (LeRobot's video decoder) loads; without them LeRobot falls
# back to the slower pyav decoder after a long warning.
set -euo pipefail
cd "$(dirname "$0")/.."

if command -v apt-get >/dev/null 2>&1 && [ "$(id -u)" = 0 ]; then
  missing=""
  for pkg in libegl1 libegl-mesa0 libgl1-mesa-dri libavutil57 libavcodec59 libavformat59 libavdevice59 \
    libavfilter8 libswscale6 libswresample4; do
    dpkg -s "$pkg" >/dev/null 2>&1 || missing="$missing $pkg"
  done
  if [ -n "$missing" ]; then
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $missing
  fi
fi

PY="${PYTHON:-python3}"
"$PY" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 12) else "Python >= 3.12 is needed (lerobot 0.6.1); got " + sys.version)'
[ -x .venv/bin/python ] || "$PY" -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip
.venv/bin/python -m pip install -q -e '.[all,test,bench]'
touch .venv/.installed

#!/usr/bin/env bash
# docs/demo_avatar_iper_motion.gif: the demo avatar (make demo) driven by the motion that
# `gma import motion` takes from the iPER clip in ../shared/data (the video pipeline's body fit, no masks).
# The motion import takes minutes on a 2-core CPU and is resumable (OUT.work/).
set -euo pipefail
cd "$(dirname "$0")/.."
work=${WORK:-out/motion}
mkdir -p "$work"
[ -f "$work/iper_motion.npz" ] || python3 -m gma.cli import motion ../shared/data/iper_turn_512.gif "$work/iper_motion.npz"
python3 -m gma.cli render out/demo/avatar.gma --motion "$work/iper_motion.npz" -o docs/demo_avatar_iper_motion.gif \
    --size 240 --orbit 0 --fps 33.33 --seconds 1.59 --force

#!/usr/bin/env bash
# docs/demo_avatar_iper_motion.gif: the demo avatar (make demo) driven by the motion that
# `gma import motion` takes from the iPER turn clip (the video pipeline's body fit, no masks).
# The clip is for research use only and not shipped: docs/data.md ("Real footage") says where to get it;
# put it at data/iper_turn_512.gif or set GMA_IPER_CLIP. The motion import is resumable (OUT.work/).
set -euo pipefail
cd "$(dirname "$0")/.."
clip=${GMA_IPER_CLIP:-data/iper_turn_512.gif}
if [ ! -f "$clip" ]; then
    echo "$clip: not found; the iPER turn clip is not shipped: see docs/data.md (\"Real footage\")" >&2
    exit 2
fi
work=${WORK:-out/motion}
mkdir -p "$work"
[ -f "$work/iper_motion.npz" ] || python3 -m gma.cli import motion "$clip" "$work/iper_motion.npz"
python3 -m gma.cli render out/demo/avatar.gma --motion "$work/iper_motion.npz" -o docs/demo_avatar_iper_motion.gif \
    --size 240 --orbit 0 --fps 33.33 --seconds 1.59 --force

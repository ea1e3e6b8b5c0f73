#!/bin/bash
# Runs (or resumes) the pre-registered live study v3 from the fixed commit 1bc3ebf, in the background.
# The study folder, worktree and render cache live outside the repository:
#   worktree /work/wt/study (1bc3ebf, detached), output /work/studies/live-study-v3, cache /work/cache-study.
# A walk in flight when the process ends is run again on --resume (its cached renders are reused when the cache
# is still there). Finished walks are copied into studies/live-v3/progress/ by save.sh at the end of each session
# and restored from there by this script when the machine is new (see README.md beside it).
set -euo pipefail
. "$(dirname "$0")/common.sh"
ensure_worktree
mkdir -p "$CACHE"
if [ ! -d "$OUT" ] && [ -d "$HERE/progress" ]; then
  mkdir -p "$(dirname "$OUT")" && cp -r "$HERE/progress" "$OUT"
  echo "restored $OUT from $HERE/progress"
fi
RESUME=()
[ -d "$OUT" ] && RESUME=(--resume)
cd "$WT"
exec env PYTHONPATH="$WT" nice -n 10 "$REPO/.venv/bin/python" -m emulator.cli validate live -o "$OUT" \
  --render study-sun64 --stochastic-seeds 4 --replicates 22 --no-run-images --cache-dir "$CACHE" \
  --scheduler local --workers 2 "${RESUME[@]}"

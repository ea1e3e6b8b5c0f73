#!/bin/bash
# The study's stop (DECISIONS.md, stopping rule): ends the study's process, draws its one final look with main's
# `validate live --stop`, copies the study's own files into docs/results/live-study-v3-DATE and checks that the copy
# redraws to the same bytes. Usage: stop.sh go YYYY-MM-DD   (the word "go" guards against a stray call)
set -euo pipefail
[ "${1:-}" = go ] && [ -n "${2:-}" ] || { echo "usage: $0 go YYYY-MM-DD" >&2; exit 2; }
. "$(dirname "$0")/common.sh"
DEST="$REPO/docs/results/live-study-v3-$2"
[ -e "$DEST" ] && { echo "$DEST exists; not overwritten" >&2; exit 2; }
pkill -f "validate live -o $OUT" || true
sleep 20
if [ -n "$(study_pids)" ]; then
  echo "the study's processes are still running ($(study_pids | tr '\n' ' ')); stop refused" >&2; exit 2
fi
cd "$REPO"
EXPOSIM_CACHE="$CACHE" .venv/bin/python -m emulator.commands.cli validate live -o "$OUT" \
  --stop "the budget: 24 h of two cores (DECISIONS.md)"
mkdir -p "$DEST"
find "$OUT" -maxdepth 1 -type f -exec cp -p -t "$DEST" {} +
cp -p "$HERE/DECISIONS.md" "$HERE/run.sh" "$HERE/common.sh" "$DEST/"
"$HERE/redraw_check.sh" "$REPO" "live-study-v3-$2"

#!/bin/bash
# Redraws committed live-study folders under docs/results/ in a temporary copy and compares them byte for byte
# with the committed ones: IDENTICAL or DIFFERS per folder. Usage: redraw_check.sh REPO FOLDER [FOLDER ...]
set -uo pipefail
REPO="$1"; shift
TMP="$(mktemp -d)"
rc=0
for name in "$@"; do
  cp -r "$REPO/docs/results/$name" "$TMP/$name"
  (cd "$REPO" && EXPOSIM_CACHE="$TMP/cache" .venv/bin/python -m emulator.commands.cli validate live -o "$TMP/$name" \
     --redraw -q) > "$TMP/$name.log" 2>&1 || { echo "$name: redraw FAILED ($TMP/$name.log)"; rc=1; continue; }
  if diff -r "$REPO/docs/results/$name" "$TMP/$name" > "$TMP/$name.diff"; then echo "$name: IDENTICAL"
  else echo "$name: DIFFERS ($TMP/$name.diff)"; rc=1; fi
done
exit $rc

#!/bin/bash
# Copies what --resume needs of the running study into progress/ beside this script, for a commit at the end of a
# session (the machine may be new next session, with /work/studies gone): the study's top-level files and every
# finished walk's record (replicates/seed<S>/walks/<scene>.json) and per-seed top-level files. Recordings, run
# folders, benchmarks' folders and walks in flight are left out (a walk in flight is run again on --resume).
# Nothing is read or summarised: the records are copied as bytes.
set -euo pipefail
. "$(dirname "$0")/common.sh"
[ -d "$OUT" ] || { echo "$OUT: no study folder" >&2; exit 2; }
mkdir -p "$HERE/progress"
cd "$OUT"
find . -maxdepth 1 -type f -print0 | xargs -0 -r cp --parents -p -t "$HERE/progress"
find replicates -mindepth 2 -maxdepth 2 -type f -print0 | xargs -0 -r cp --parents -p -t "$HERE/progress"
find replicates -mindepth 3 -maxdepth 3 -path "*/walks/*.json" -type f -print0 | xargs -0 -r cp --parents -p -t "$HERE/progress"
echo "saved: $(find "$HERE/progress/replicates" -path '*/walks/*.json' 2>/dev/null | wc -l) walk records"

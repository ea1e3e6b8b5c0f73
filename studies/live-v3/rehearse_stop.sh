#!/bin/bash
# Rehearses the study's stop on a throwaway study, never on the study itself: the fixed commit 1bc3ebf (the
# worktree run.sh makes) runs a tiny study of the same kind (2 scenes x 4 seeds, 4 cycles, 64x40 px, 1 spp, Kim on
# 2 seeds); its folder is then cut to what a study ended mid-walk leaves (no derived file, the last seed one walk
# short), main's `validate live --stop` draws the final look on it, and a copy is redrawn and compared byte for
# byte. It checks that main reads 1bc3ebf's walk records, writes the final look's checks (report.md) and redraws
# to the same bytes. About 7 min of walks, 3 min of stop and 12 min of redraw at nice 19 beside the study.
# Usage: rehearse_stop.sh [WORKDIR]   (default: a new temporary folder; the study's folders are not touched)
set -euo pipefail
. "$(dirname "$0")/common.sh"
ensure_worktree
W="${1:-$(mktemp -d)}"
[ -e "$W/study" ] && { echo "$W/study exists; not overwritten" >&2; exit 2; }
mkdir -p "$W"
(cd "$WT" && PYTHONPATH="$WT" nice -n 19 "$REPO/.venv/bin/python" -m emulator.cli validate live -o "$W/study" \
   --cycles 4 --size 64x40 --spp 1 --scenes forest_edge,sun_glare --replicates 4 --stochastic-seeds 2 \
   --noise-repeats 3 --no-run-images --cache-dir "$W/cache" --scheduler serial -q) > "$W/walks.log" 2>&1
cp -r "$W/study" "$W/stopped"
find "$W/stopped" -maxdepth 1 -type f ! -name study.json ! -name preregistration.json -delete
for s in "$W"/stopped/replicates/seed*; do find "$s" -maxdepth 1 -type f -delete; done
rm "$W/stopped/replicates/seed3/walks/sun_glare.json"
cd "$REPO"
EXPOSIM_CACHE="$W/cache" nice -n 19 .venv/bin/python -m emulator.commands.cli validate live -o "$W/stopped" \
  --stop "rehearsal" > "$W/stop.log" 2>&1
grep -q "^## The final look's checks" "$W/stopped/report.md" || { echo "no final look's checks in report.md" >&2; exit 1; }
grep -q '"n_walks": 6' "$W/stopped/stop.json" || { echo "stop.json does not judge the 6 walks of 3 seeds" >&2; exit 1; }
cp -r "$W/stopped" "$W/redrawn"
EXPOSIM_CACHE="$W/cache" nice -n 19 .venv/bin/python -m emulator.commands.cli validate live -o "$W/redrawn" \
  --redraw -q > "$W/redraw.log" 2>&1
diff -r "$W/stopped" "$W/redrawn" > "$W/redraw.diff" && echo "rehearsal: stopped, checks written, redraw IDENTICAL ($W)" \
  || { echo "rehearsal: redraw DIFFERS ($W/redraw.diff)"; exit 1; }

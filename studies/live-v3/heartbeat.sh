#!/bin/bash
# Writes the time (UTC) to /work/studies/heartbeat.log once a minute while the study's process lives, and ends with
# it: the ledger bounds each unrecorded run-on by the last line plus 1 min (DECISIONS.md, decision of 2026-12-06
# 09:40). Start it after run.sh: `(nohup /work/main/studies/live-v3/heartbeat.sh >/dev/null 2>&1 &)`.
# The study's processes are those stop.sh waits for (common.sh's study_pids: every process running in the worktree,
# Dask's workers included).
set -euo pipefail
. "$(dirname "$0")/common.sh"
sleep 30   # run.sh may still be restoring or checking the worktree
while [ -n "$(study_pids)" ]; do
  date -u +%FT%TZ >> "$(dirname "$OUT")/heartbeat.log"
  sleep 60
done

#!/usr/bin/env bash
# Render noise against sensor noise: the committed measure over the four study scenes, at b0157cc, two processes one after the other.
set -u
cd /work/wt/r43  # a worktree at b0157cc
. /work/main/.venv/bin/activate
export PYTHONPATH=/work/wt/r43
SW=0,6,12,18,22,28,34,40,44
SET='oidn-hq@64+sun=16~x16:20%@32ms'
python scripts/render_noise_balance.py -o /work/r43/balance-edge-glare.json --scenes forest_edge,sun_glare --sweeps $SW --bias-reference off@256 --cache-dir /work/cache-r43 "$SET" > /work/r43/edge-glare.log 2>&1
python scripts/render_noise_balance.py -o /work/r43/balance-winter-summer.json --scenes forest_winter,forest_summer --sweeps $SW --bias-reference off@256 --cache-dir /work/cache-r43 "$SET" > /work/r43/winter-summer.log 2>&1

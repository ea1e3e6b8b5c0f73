#!/usr/bin/env bash
# The ~x16:30%@32ms runs: forest_summer, then (it met the goal) the other three study scenes, then forest_edge's mean
# radiance on nine sweeps; at b0157cc, the same worktree, sweeps and render cache as run.sh.
set -u
cd /work/wt/r43  # a worktree at b0157cc
. /work/main/.venv/bin/activate
export PYTHONPATH=/work/wt/r43
SW=0,6,12,18,22,28,34,40,44
SET='oidn-hq@64+sun=16~x16:30%@32ms'
python scripts/render_noise_balance.py -o /work/r43b/balance-summer-x16-30.json --scenes forest_summer --sweeps $SW --bias-reference off@256 --cache-dir /work/cache-r43 "$SET" > /work/r43b/summer-x16-30.log 2>&1
python scripts/render_noise_balance.py -o /work/r43b/balance-edge-glare-winter-x16-30.json --scenes forest_edge,sun_glare,forest_winter --sweeps $SW --bias-reference off@256 --cache-dir /work/cache-r43 "$SET" > /work/r43b/edge-glare-winter-x16-30.log 2>&1
python /work/r43b/edge_bias.py /work/cache-r43 /work/r43b/edge-bias-9sweeps.json > /work/r43b/edge-bias.log 2>&1  # edge_bias.py here

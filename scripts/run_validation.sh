#!/usr/bin/env bash
# The full validation study (issue 6): emulation, selectors, motion, speed.
#
# usage: scripts/run_validation.sh OUTPUT_DIR [extra options for every experiment, e.g. --force]
#
# Sizes are the experiments' defaults (see validation/*.py *Config): emulation with 1000
# ground-truth exposures x 25 repeats over six static scenes, four responses and two extra
# vignetting strengths at 96x60; selectors with 400 exposures on 3 training + 3 held-out
# scenes; motion on two forest scenes at 0.5-2 m/s; speed with 1920x1200 timings.
# Renders go through the render cache ($EXPOSIM_CACHE or ~/.cache/exposim/renders).
# Progress bars go to stderr; each experiment writes OUTPUT_DIR/<experiment>/.
set -euo pipefail
if [[ $# -lt 1 ]]; then
    echo "usage: $0 OUTPUT_DIR [options]" >&2
    exit 2
fi
out="$1"
shift
for experiment in emulation selectors motion speed; do
    exposim validate "$experiment" -o "$out/$experiment" "$@"
done

"""Pilot figures from the walk records in a study folder (finished or not)."""
import json, math, sys
from pathlib import Path
import numpy as np
from validation.live.config import config_from_dict, COMPARISONS, HEADLINE_METRICS
from validation.live.experiment import assemble_raw
from validation.live.evidence import walk_values
from validation.live.seeds import loop_names, split_seeds, seed_noise, residual_shares, recommended_seeds, shares_by_seeds
from validation.live.headline import with_derived

out = Path(sys.argv[1])
study = json.loads((out / "study.json").read_text())
cfg = config_from_dict(study["config"])
done = [s for s in cfg.scenes if (out / "walks" / f"{s}.json").is_file()]
print("walks done:", done)
for s in done:
    t = json.loads((out / "walks" / f"{s}.json").read_text())["timings"]
    tot = t[f"walk_{s}_s"]
    parts = {k.replace(f"_{s}_s", ""): round(v) for k, v in t.items()}
    print(f"{s}: {tot/60:.1f} min; parts (s): {parts}")
failed = {s: "not run yet" for s in cfg.scenes if s not in done}
raw = assemble_raw(out, cfg, failed)
names = loop_names(cfg.methods, cfg.stochastic_seeds)
walks, tables = walk_values([raw], names)
k = cfg.stochastic_seeds
means, seed_names, seeds = split_seeds(tables, names, cfg.methods, k)
noise = seed_noise(seeds, seed_names, cfg.methods, k)["kim"]
print("\nKim seed-to-seed SD (pooled within walks) per run, headline metrics (RPE rank not defined per seed):")
metrics = [m for m in HEADLINE_METRICS if m in next(iter(noise.values()))]
for run, per in sorted(noise.items()):
    print(f"  {run:30s}", "  ".join(f"{m}={per[m]['seed_sd']:.4g}" if per[m]['seed_sd'] is not None else f"{m}=NA" for m in metrics))
rms = {m: math.sqrt(np.mean([per[m]["seed_sd"] ** 2 for per in noise.values() if per[m]["seed_sd"] is not None])) for m in metrics}
print("  RMS over runs:", {m: round(v, 4) for m, v in rms.items()})
if len(walks) >= 2:
    sh = residual_shares(with_derived(means), list(cfg.methods), COMPARISONS)
    by = shares_by_seeds(means, list(cfg.methods), seed_names, seeds, k)["kim"]
    for label in ("emulated vs cycle-rate live", "emulated native vs native-rate live", "cycle-rate live re-seeded vs cycle-rate live"):
        print(f"\n{label}:")
        for m in HEADLINE_METRICS:
            e = sh[label][m]
            print(f"  {m:28s} residual_sd_others={e['residual_sd_others']}  kim share by j seeds={['%.3f' % x if x is not None else None for x in by[label][m]]}")
json.dump({"walks": walks, "seed_noise": noise}, open(sys.argv[2] if len(sys.argv) > 2 else "pilot_noise.json", "w"), indent=1)

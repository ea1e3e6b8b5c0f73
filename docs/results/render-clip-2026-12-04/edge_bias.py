"""forest_edge's mean radiance at study-adaptive30 against off@256 on 9 sweeps (the committed measure on 3 left its
interval across 1 %): validation.render_study.balance.radiance_bias as the script calls it, more sweeps."""
import json
import sys
from pathlib import Path

from validation.render_study.balance import radiance_bias

cache = Path(sys.argv[1])
out = Path(sys.argv[2])
if out.exists():
    sys.exit(f"{out}: exists")
sweeps = (0, 6, 11, 17, 22, 28, 33, 39, 44)
r = radiance_bias("oidn-hq@64+sun=16~x16:30%@32ms", scene_key="forest_edge", reference="off@256", sweeps=sweeps,
                  cache_dir=cache / "forest_edge-1", reference_cache_dir=cache / "reference")
out.write_text(json.dumps(r, indent=1))
print("forest_edge", r["setting"], "vs", r["reference"], "on", len(sweeps), "sweeps:",
      "%+.2f %% [%+.2f, %+.2f]" % tuple(r["difference_percent"]),
      "without the sun disk %+.2f %% [%+.2f, %+.2f]" % tuple(r["difference_percent_sun_excluded"]))

"""One walk of validate blur's live-against-emulated table at 960x600 (seed from argv)."""
import os, resource, sys, time
from dataclasses import replace
from validation.blur.config import BlurConfig
from validation.blur.versus import run_versus
from emulator.io.files import write_results
seed = int(sys.argv[2])
cfg = replace(BlurConfig(), seed=seed, versus_walks=1, width=960, height=600, cache_dir=os.environ.get("EXPOSIM_CACHE"))
t = time.time(); load0 = os.getloadavg()
r = run_versus(sys.argv[1], cfg)
ru = resource.getrusage(resource.RUSAGE_SELF)
r["timing"] = {"wall_s": time.time() - t, "cpu_s": ru.ru_utime + ru.ru_stime, "load_start": load0, "load_end": os.getloadavg()}
r["config"] = cfg.as_dict()
write_results(os.path.join(sys.argv[1], "versus.json"), r, float_digits=12)

import sys, time, dataclasses
import numpy as np
import finsler
from solvers.certify_nd import NDSpec, certify_nd
m = finsler.get_metric("poincare-slab")
pairs = finsler.sample_pairs(m, 10, 5)
idx = [int(a) for a in sys.argv[1].split(",")]
kw = eval("dict(" + (sys.argv[2] if len(sys.argv) > 2 else "") + ")")
spec = dataclasses.replace(NDSpec.preset("coarse"), element="P2", **kw)
for i in idx:
    s, g = pairs[i]
    c0 = time.process_time()
    r = certify_nd(m, s, g, spec)
    ex = float(m.distance(s[None], g[None])[0])
    print(i, f"lower {r.lower:.6f} upper {r.upper:.6f} exact {ex:.6f} gap {r.gap:.3e} R {r.verified_ratio:.5f} cells {r.cells} rel {r.relevant_cells} {r.status} cpu {time.process_time()-c0:.1f}", {k: round(v,1) for k,v in r.times.items()}, flush=True)
    for rd in r.rounds: print("   ", {k: (round(v,5) if isinstance(v,float) else v) for k,v in rd.items()}, flush=True)

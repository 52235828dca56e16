#!/usr/bin/env python3
"""Compares two `milliego selftest` outputs (native vs qemu-aarch64): every digest must be identical,
model outputs must agree within the check's tolerance (floating-point kernels differ between
architectures). Usage: compare-selftest.py A.json B.json"""
import json
import sys

a, b = (json.load(open(p))["checks"] for p in sys.argv[1:3])
bad = []
if a.keys() != b.keys():
    bad.append(f"different checks: {sorted(set(a) ^ set(b))}")
digests = models = 0
for name in sorted(set(a) & set(b)):
    x, y = a[name], b[name]
    if "outputs" in x:
        models += 1
        tol = x["tolerance"]
        if len(x["outputs"]) != len(y["outputs"]):
            bad.append(f"{name}: {len(x['outputs'])} vs {len(y['outputs'])} outputs")
            continue
        d = max((abs(p - q) for p, q in zip(x["outputs"], y["outputs"])), default=0.0)
        print(f"{name}: max output difference {d:.3g} (tolerance {tol}); ok {x['ok']} / {y['ok']}; "
              f"plan passes: {x.get('accel')} / {y.get('accel')}; AMX guard: {x.get('amx_guard')} / "
              f"{y.get('amx_guard')}")
        if d > tol or not (x["ok"] and y["ok"]):
            bad.append(f"{name}: outputs differ by {d:.3g} > {tol} or a run was not ok")
    elif x != y:
        bad.append(f"{name}: {x} vs {y}")
    else:
        digests += 1
if bad:
    print("selftest differs between the two runs:\n  " + "\n  ".join(bad))
    sys.exit(1)
print(f"selftest agrees: {digests} digests identical, {models} model checks within tolerance")

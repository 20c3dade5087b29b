"""``python -m bench.trace_versions BASE [--rounds N] [--size WxH]``: the exact ray tracer of this
checkout against the one in BASE (a directory holding another ``clcsg`` package, e.g. from
``git archive COMMIT clcsg | tar -x -C BASE``) on the many-leaf scenes and the gear.

Each round runs one child process per version, alternating (the machine is shared, so the
load drifts); a child traces every scene once to build its kernels, then once timed (process
CPU of the whole ``trace`` call).  Reported: the least CPU per version and scene over the
rounds, and whether both versions give the same depth and id images bit for bit.  Writes
``bench/results/trace_versions.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

from .common import write

HERE = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def scenes(W, H):
    """(name, tape, camera) of the plates, the sphere column and the gear at W x H."""
    import clcsg

    from . import zoo
    from .common import fit_to_silhouette

    out = [(name, tape, cam.resized(W, H)) for name, tape, cam in zoo.many_leaf_scenes()]
    m = next(x for x in zoo.MODELS if x.name == "gear")
    tree = clcsg.Scene(m.build(), source=m.name).compile("tree")
    out.append(("gear", tree, fit_to_silhouette(tree, W, H, m.direction)))
    return out


def child(path, W, H):
    """Trace each scene (build, then timed) and save CPU seconds, stats and images to ``path``."""
    import numpy as np

    import clcsg
    from clcsg.cl.device import context_of
    from clcsg.rendering.raytracer import trace
    from clcsg.rendering.shading import Shading

    ctx = context_of(None)
    out, meta = {}, {"clcsg": os.path.dirname(clcsg.__file__)}
    for name, tape, cam in scenes(W, H):
        trace(ctx, tape, cam, Shading())
        c0 = time.process_time()
        img = trace(ctx, tape, cam, Shading())
        meta[name] = {"cpu_seconds": time.process_time() - c0, "prune_s": img.stats["prune_s"],
                      "kernel_s": img.stats["kernel_s"], "prune_evaluations": img.stats["prune_evaluations"],
                      "tile_tape_mean": img.stats["tile_tape_mean"], "slab_tape_mean": img.stats["slab_tape_mean"]}
        out[name + ".depth"], out[name + ".ids"] = img.depth, img.ids
    np.savez(path, meta=json.dumps(meta), **out)


def run(base, rounds, W, H):
    import numpy as np

    versions = {"before": f"{os.path.abspath(base)}{os.pathsep}{HERE}", "after": HERE}
    best, images, meta = {}, {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(rounds):
            for key, pypath in versions.items():
                path = os.path.join(tmp, f"{key}.npz")
                env = dict(os.environ, PYTHONPATH=pypath)
                subprocess.run([sys.executable, "-m", "bench.trace_versions", "--child", path, "--size", f"{W}x{H}"],
                               cwd=tmp, env=env, check=True)
                with np.load(path) as z:
                    m = json.loads(str(z["meta"]))
                    images[key] = {k: z[k] for k in z.files if k != "meta"}
                meta[key] = m
                for name, rec in m.items():
                    if name == "clcsg":
                        continue
                    b = best.setdefault(key, {}).get(name)
                    if b is None or rec["cpu_seconds"] < b["cpu_seconds"]:
                        best[key][name] = rec
                print(f"round {r + 1} {key} ({m['clcsg']}): " + ", ".join(
                    f"{n} {1e3 * v['cpu_seconds']:.0f} ms" for n, v in m.items() if n != "clcsg"), flush=True)
    rows = []
    for name in best["after"]:
        same = all(np.array_equal(images["before"][f"{name}.{k}"], images["after"][f"{name}.{k}"])
                   for k in ("depth", "ids"))
        b, a = best["before"][name], best["after"][name]
        rows.append({"scene": name, "width": W, "height": H, "before": b, "after": a, "same_image": same,
                     "cpu_gain": b["cpu_seconds"] / a["cpu_seconds"]})
        print(f"{name}: CPU {1e3 * b['cpu_seconds']:.0f} -> {1e3 * a['cpu_seconds']:.0f} ms "
              f"({rows[-1]['cpu_gain']:.2f}x), prune evaluations {b['prune_evaluations']} -> "
              f"{a['prune_evaluations']}, same image: {same}", flush=True)
    print(write("trace_versions", {"rounds": rounds, "base": meta["before"]["clcsg"], "rows": rows,
                                   "load_average": os.getloadavg()}))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("base", nargs="?")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--size", default="1920x1080")
    ap.add_argument("--child")
    a = ap.parse_args(argv)
    W, H = (int(v) for v in a.size.split("x"))
    if a.child:
        child(a.child, W, H)
    else:
        run(a.base, a.rounds, W, H)


if __name__ == "__main__":
    main()

"""Plots (matplotlib, PNG) from the JSON files of the other parts, written to bench/results/:

* ``sampling_vs_samples.png``: sampling time against sample count (models.json zoo rows, one
  line per model and shape of the tape over its three splat sizes, and sampler.json rows);
* ``sampling_vs_quadrics.png``: sampling time and time per distance query against unique
  quadric count (models.json, tree and DNF shape), beside the paper's Table 2;
* ``render_vs_resolution.png``: splat and ray tracer time against pixel count
  (render.json resolution sweep);
* ``peers_error.png``: manifold3d's error and time against tessellation level (peers.json).

``python -m bench plots`` reads whatever JSON files exist and says which plots it skipped.
"""

from __future__ import annotations

import json
import os

from . import common

MARKERS = "osD^v<>p*h"


def _load(name):
    path = os.path.join(common.RESULTS, f"{name}.json")
    if not os.path.exists(path):
        return None
    with open(path) as f:
        return json.load(f)


def _subtitle(env):
    return f"{env['device']} ({env['compute_units']} CUs), commit {env['git_commit']}"


def run(quick=False, device=None):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    written, skipped = [], []
    models = _load("models")
    sampler = _load("sampler")
    peers = _load("peers")
    render = _load("render")

    def save(fig, name):
        path = os.path.join(common.RESULTS, name)
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)

    if models:
        rows = [r for r in models["rows"] if r.get("kind", "zoo") == "zoo" and not r.get("skipped")]
        names = list(dict.fromkeys(r["model"] for r in rows))
        fig, ax = plt.subplots(figsize=(7, 4.5))
        for k, name in enumerate(names):
            for nf, style in (("tree", "-"), ("dnf", ":")):
                rr = sorted((r for r in rows if r["model"] == name and r.get("normal_form", "tree") == nf),
                            key=lambda r: r["samples"])
                if not rr:
                    continue
                ax.loglog([r["samples"] for r in rr], [1e3 * r["sampling_s"] for r in rr], marker=MARKERS[k % 10],
                          linestyle=style, color=f"C{k}", label=f"{name} ({rr[0]['quadrics']} quadrics), {nf}")
        if sampler:
            sr = sampler["rows"]
            ax.loglog([r["samples"] for r in sr], [1e3 * r["seconds"] for r in sr], "k.", alpha=0.5,
                      label="sampler.json scenes")
        ax.set_xlabel("samples")
        ax.set_ylabel("sampling time (ms, whole clcsg.sample call)")
        ax.set_title("Sampling time against sample count\n" + _subtitle(models["environment"]), fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=6, ncol=2)
        save(fig, "sampling_vs_samples.png")

        fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4.2))
        sizes = list(dict.fromkeys(r["size"] for r in rows))
        for k, size in enumerate(sizes):
            for nf, style in (("tree", "-"), ("dnf", ":")):
                rr = sorted((r for r in rows if r["size"] == size and r.get("normal_form", "tree") == nf),
                            key=lambda r: r["quadrics"])
                if not rr:
                    continue
                a1.semilogy([r["quadrics"] for r in rr], [1e3 * r["sampling_s"] for r in rr], marker=MARKERS[k],
                            linestyle=style, color=f"C{k}", label=f"clcsg {nf}, {size}")
                a2.semilogy([r["quadrics"] for r in rr],
                            [1e6 * r["sampling_s"] / max(r["distance_queries"], 1) for r in rr], marker=MARKERS[k],
                            linestyle=style, color=f"C{k}", label=f"clcsg {nf}, {size}")
            rr = sorted((r for r in rows if r["size"] == size and r.get("normal_form", "tree") == "tree"),
                        key=lambda r: r["quadrics"])
            a1.semilogy([r["quadrics"] for r in rr], [r["paper"]["sampling_ms"] for r in rr], marker=MARKERS[k],
                        linestyle="--", color=f"C{k}", alpha=0.5, label=f"paper Table 2, {size}")
            a2.semilogy([r["quadrics"] for r in rr],
                        [1e3 * r["paper"]["sampling_ms"] / r["paper"]["distance_queries"] for r in rr],
                        marker=MARKERS[k], linestyle="--", color=f"C{k}", alpha=0.5, label=f"paper, {size}")
        a1.set_xlabel("unique quadrics")
        a1.set_ylabel("sampling time (ms)")
        a1.set_title("Sampling time against quadric count", fontsize=9)
        a2.set_xlabel("unique quadrics")
        a2.set_ylabel("sampling time / distance query (us)")
        a2.set_title("Time per distance query", fontsize=9)
        for a in (a1, a2):
            a.grid(True, which="both", alpha=0.3)
            a.legend(fontsize=6)
        fig.suptitle(_subtitle(models["environment"]) + "; paper: one 4.8 GHz core", fontsize=8)
        save(fig, "sampling_vs_quadrics.png")
    else:
        skipped.append("sampling plots (no models.json: run python -m bench models)")

    sweep = (render or {}).get("resolution_sweep") or []
    if sweep:
        fig, ax = plt.subplots(figsize=(7, 4.5))
        for k, name in enumerate(dict.fromkeys(s["model"] for s in sweep)):
            ss = sorted((s for s in sweep if s["model"] == name), key=lambda s: s["pixels"])
            q = ss[0]["quadrics"]
            ax.loglog([s["pixels"] for s in ss], [1e3 * s["splat_s"] for s in ss], marker=MARKERS[k],
                      label=f"splat, {name} ({q} quadrics)")
            ax.loglog([s["pixels"] for s in ss], [1e3 * s["raytrace_s"] for s in ss], marker=MARKERS[k],
                      linestyle="--", label=f"tree ray tracer, {name} ({q} quadrics)")
        ax.set_xlabel("pixels")
        ax.set_ylabel("render time (ms, device kernels)")
        ax.set_title("Render time against resolution (480x270 ... 3840x2160)\n"
                     + _subtitle(render["environment"]), fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
        save(fig, "render_vs_resolution.png")
    else:
        skipped.append("render_vs_resolution.png (render.json has no resolution sweep: run python -m bench render "
                       "without --quick)")

    if peers and peers.get("available"):
        fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4.2))
        for k, r in enumerate(peers["models"]):
            lv = r["levels"]
            if not lv:
                continue
            a1.loglog([v["segments"] for v in lv], [v["max_rel_error"] for v in lv], marker=MARKERS[k % 10],
                      label=r["model"])
            a2.loglog([v["segments"] for v in lv], [1e3 * v["total_s"] for v in lv], marker=MARKERS[k % 10],
                      label=f"{r['model']} (clcsg {1e3 * r['ours_s']:.0f} ms)")
        a1.axhline(peers["target_rel_error"], color="k", linestyle=":", label="target 1e-4")
        a1.set_xlabel("circular segments")
        a1.set_ylabel("max error / bound diagonal")
        a1.set_title("manifold3d surface error", fontsize=9)
        a2.set_xlabel("circular segments")
        a2.set_ylabel("build + sampling (ms)")
        a2.set_title("manifold3d time", fontsize=9)
        for a in (a1, a2):
            a.grid(True, which="both", alpha=0.3)
            a.legend(fontsize=7)
        save(fig, "peers_error.png")
    else:
        skipped.append("peers_error.png (no peers.json with manifold3d results)")

    for p in written:
        print(f"wrote {p}")
    for s in skipped:
        print(f"skipped {s}")
    return written

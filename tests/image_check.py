"""An image from either renderer against the float64 tree oracle, pixel by pixel."""

from __future__ import annotations

import numpy as np

import tree_oracle as T


def compare(img, shape, tape, cam, rel=None):
    """Kernel vs the tree oracle: masks, quadric and primitive ids identical away from fragile
    pixels; depth within 1e-6 relative with double (2e-5 when the float32 path is forced,
    CLCSG_PRECISION=float)."""
    double = img.stats["precision"] == "double"
    if rel is None:
        rel = 1e-6 if double else 2e-5
    o, d = cam.rays()
    ref = T.cast(shape, o, d)
    skip = T.fragile(shape, o, d, rel=1e-9 if double else 1e-5)
    ok = ~skip
    assert skip.mean() < 0.02, f"too many fragile pixels: {skip.sum()}"
    # float32: rays grazing a silhouette (discriminant ~ 0) may also flip
    allowed = 0 if double else max(2, img.mask.size // 1000)
    mism = (img.mask != ref.mask) & ok
    assert mism.sum() <= allowed, f"{mism.sum()} mask mismatches at {np.argwhere(mism)[:5].tolist()}"
    both = ref.mask & img.mask & ok
    rd = np.abs(img.depth[both].astype(np.float64) - ref.depth[both]) / ref.depth[both]
    assert rd.max(initial=0) <= rel, f"depth rel diff {rd.max()}"
    ids = T.quadric_table(shape).match(tape.quadrics)[img.ids]
    bad_ids = both & (ids != ref.quadric)
    assert bad_ids.sum() <= allowed, f"{bad_ids.sum()} id mismatches"
    bad_prims = both & (img.primitives != ref.primitive)
    assert bad_prims.sum() <= allowed, f"{bad_prims.sum()} primitive mismatches at {np.argwhere(bad_prims)[:5].tolist()}"
    assert np.all(np.isinf(img.depth[~img.mask])) and np.all(img.ids[~img.mask] == -1)
    return ref

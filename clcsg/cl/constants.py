"""Constants that host and kernels share, defined once here (this module imports nothing of
ours: the tape compiler, the host interpreter and every kernel read them from here).

:func:`defines` turns them into ``-D`` build options (:mod:`clcsg.cl.programs` adds them to
every program), so a kernel's counter slot or sentinel is never typed twice.  Counter slots are
given as tuples of names; slot ``k`` of ``NAMES`` becomes ``-DC_<NAME>=k`` and ``N_<GROUP>`` is
their count.
"""

from __future__ import annotations

#: the tape's opcodes (a row is op, out, a, b: see :class:`clcsg.compile.tape.Tape`)
OP_LEAF, OP_AND, OP_OR, OP_COPY, OP_CONST = 0, 1, 2, 3, 4
OP_NAMES = ("LEAF", "AND", "OR", "COPY", "CONST")

#: counters of the sampler's classify kernel, in slot order
SAMPLER_COUNTERS = (
    "cells", "samples", "distance_queries", "leaf_distances", "unresolved", "discarded", "filled",
    "single", "split", "split_in_place", "prune_evaluations", "pruned_decided", "tape_rows", "tape_max", "tapes_written",
    "arena", "clip_rows", "finish_prune_evaluations", "status",
)

#: the sampler's sample columns (sampling/finish.h writes them, sampling/sampler.py reads them
#: into the Samples arrays): a buffer of reals and one of ints, each a run of regions of
#: ``capacity`` entries, an entry ``width`` values wide; (name, width) in region order
SAMPLE_REAL_COLUMNS = (("pos", 3), ("normal", 3), ("radius", 1))
SAMPLE_INT_COLUMNS = (("quadric", 1), ("sign", 1), ("primitive", 1), ("clip_first", 1), ("clip_count", 1))

#: counters of the splat kernel, in slot order
SPLAT_COUNTERS = (
    "splats_drawn", "splats_culled", "splats_offscreen", "bound_pixels", "fragments_occluded", "fragments",
    "clip_evaluations", "fragments_passed", "atomics",
)

#: rounding margin of pruning, bound and splat tests, in units of the precision's epsilon
#: (REAL_EPS on the device, float64's on the host reference)
ROUNDING_ULPS = 64

#: registers of the instance program's interpreter (cl/include/primitives.h); a scene whose
#: instance program needs more falls back to the first instance whose boundary holds a point
INSTANCE_REGS = 32

#: pixels of a row per work-item of the splat resolve pass (rendering/resolve.cl): their
#: shading runs as one float8 vector
RESOLVE_LANES = 8

#: pixels of a row per work-item of the exact ray tracer (rendering/raytrace.cl): their rays'
#: branch-free arithmetic runs as real8 vectors, their shading as one float8 (pixel.h's pixel_lanes)
RAY_LANES = 8

#: the sampler's table of clip programs (sampling/clip_table.h): the entries a lookup probes, an
#: entry's 32-bit words (a 64-byte line: state, first row, rows and the first CLIP_TABLE_INLINE
#: rows of the program)
CLIP_TABLE_PROBES = 8
CLIP_ENTRY_WORDS = 16
CLIP_TABLE_INLINE = 3
#: the programs a work-item of the sampler keeps at hand before it looks in that table
CLIP_RECENT = 4
#: clip programs of at most this many rows are built in a work-item's private memory and stored
#: once per run where they can be; longer ones are written as they are
CLIP_BUILD_ROWS = 32

#: the framebuffer word of a pixel no fragment reached (float bits of t << 32 | index; splat.cl)
EMPTY_KEY = 0xFFFFFFFFFFFFFFFF


def _slots(prefix: str, group: str, names) -> dict:
    out = {f"{prefix}_{n.upper()}": k for k, n in enumerate(names)}
    out[f"N_{group}"] = len(names)
    return out


def _columns(prefix: str, group: str, columns) -> dict:
    """``-D<prefix>_<NAME>=offset`` of each column's region, in units of the capacity (the region
    of a column of width w starts at offset * capacity; its entry k at w * k past that), and
    ``N_<group>`` the total width."""
    out, offset = {}, 0
    for name, width in columns:
        out[f"{prefix}_{name.upper()}"] = offset
        offset += width
    out[f"N_{group}"] = offset
    return out


def defines() -> dict:
    d = {"OP_LEAF": OP_LEAF, "OP_AND": OP_AND, "OP_OR": OP_OR, "OP_COPY": OP_COPY, "OP_CONST": OP_CONST}
    d.update(_slots("SC", "SAMPLER_COUNTERS", SAMPLER_COUNTERS))
    d.update(_slots("PC", "SPLAT_COUNTERS", SPLAT_COUNTERS))
    d.update(_columns("SR", "SAMPLE_REALS", SAMPLE_REAL_COLUMNS))
    d.update(_columns("SI", "SAMPLE_INTS", SAMPLE_INT_COLUMNS))
    d["ROUNDING_ULPS"] = ROUNDING_ULPS
    d["INSTANCE_REGS"] = INSTANCE_REGS
    d["RESOLVE_LANES"] = RESOLVE_LANES
    d["RAY_LANES"] = RAY_LANES
    d["CLIP_TABLE_PROBES"] = CLIP_TABLE_PROBES
    d["CLIP_ENTRY_WORDS"] = CLIP_ENTRY_WORDS
    d["CLIP_TABLE_INLINE"] = CLIP_TABLE_INLINE
    d["CLIP_RECENT"] = CLIP_RECENT
    d["CLIP_BUILD_ROWS"] = CLIP_BUILD_ROWS
    d["EMPTY_KEY"] = f"0x{EMPTY_KEY:016x}UL"
    return d

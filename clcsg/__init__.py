"""clcsg: exact point sampling and pixel-perfect splat rendering of quadric CSG solids.

The data flows one way, one package per stage (every module and the layers:
``docs/architecture.md``):

1. ``model``: the scene — quadrics, primitives, the CSG graph (:class:`Shape`), :class:`Scene`;
   2-D :class:`Profile` s (``square``, ``circle``, ``polygon``, ``offset``) become exact solids
   with :func:`extrude` and :func:`revolve`; :func:`hull` and :func:`minkowski` build rounded
   solids; ``readers`` read scene files into it (JSON scene files, OpenSCAD ``.csg`` / ``.scad``).
2. ``compile``: the graph becomes a tape over unique canonical quadrics (transforms and
   complements pushed to the leaves, shared sub-graphs once), with primitive instances, bounds
   and estimates (``compile.bounds``) and principal frames; the paper's DNF is one shape of tape.
3. ``sampling``: per (quadric, sampling plane, sheet) an adaptive subdivision on the device,
   each cell with its pruned tape: :func:`sample` returns :class:`Samples`, plain arrays that
   ``writers`` turn into PLY, NPZ, Open3D or trimesh (:func:`write_samples`).
4. ``rendering``: splats with local ray tracing and clipping by tape (:func:`render`) and the
   exact tree ray tracer (:func:`raytrace`), both into an :class:`Image`.
5. ``cl`` is the OpenCL plumbing (devices, programs, records, shared constants).
6. ``queries``: occupancy and a conservative signed distance at given points, on the device
   (:func:`inside`, :func:`distance`).
7. ``pipeline``: scene -> tape -> radius -> samples -> camera -> image, the one path the front
   ends take: ``cli`` (one module per command), ``viewer`` and ``batching`` (many scenes into a
   folder with a manifest, on a process pool or a Dask cluster: :func:`batch`).
"""
__version__ = "0.2.0"

#: public name -> the module that defines it; imported on first use (PEP 562), so that
#: ``clcsg --version`` and ``clcsg --help`` load neither numpy nor pyopencl
_EXPORTS = {
    "ClcsgError": "errors",
    **dict.fromkeys(("Shape", "contains", "difference", "intersection", "union"), "model.csg"),
    "Quadric": "model.quadric",
    **dict.fromkeys(("box", "cone", "cylinder", "ellipsoid", "halfspace", "quadric", "slab", "sphere"),
                    "model.solids"),
    "Scene": "model.scene",
    **dict.fromkeys(("load", "save", "as_scene"), "readers.scenes"),
    "devices": "cl.device",
    **dict.fromkeys(("Camera", "orbit"), "rendering.camera"),
    "Image": "rendering.image",
    "raytrace": "rendering.raytracer",
    "render": "rendering.splat",
    "sample": "sampling.surfel_csg",
    "Samples": "sampling.samples",
    "load_samples": "writers.samples_npz",
    "write_samples": "writers.output_files",
    **dict.fromkeys(("to_open3d", "to_trimesh"), "writers.interop"),
    **dict.fromkeys(("distance", "inside"), "queries"),
    "batch": "batching.api",
    **dict.fromkeys(("Profile", "circle", "polygon", "square"), "model.profile"),
    "offset": "model.profile_ops",
    "extrude": "model.extrude",
    "revolve": "model.revolve",
    **dict.fromkeys(("hull", "minkowski"), "model.hull"),
    "mesh": "meshing",
    "polyhedron": "model.polyhedron",
    "surfels": "model.surfels",
    "load_mesh": "readers.mesh_files",
}
__all__ = ["__version__", *_EXPORTS]


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'clcsg' has no attribute {name!r}")
    import importlib  # stdlib; the import machinery itself

    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(_EXPORTS))

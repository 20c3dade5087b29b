"""clcsg: exact point sampling and pixel-perfect splat rendering of quadric CSG solids.

The data flows one way, one package per stage:

1. ``model``: the scene — quadrics, primitives, the CSG graph (:class:`Shape`), :class:`Scene`;
   2-D :class:`Profile` s (``square``, ``circle``, ``polygon``, ``offset``) become exact solids
   with :func:`extrude` and :func:`revolve`; :func:`hull` and :func:`minkowski` build rounded
   solids; ``io`` reads and writes it (JSON scene files, OpenSCAD ``.csg`` / ``.scad``, PLY samples).
2. ``compile``: the graph becomes a tape over unique canonical quadrics (transforms and
   complements pushed to the leaves, shared sub-graphs once), with primitive instances, bounds
   and principal frames; the paper's DNF is one shape of tape.
3. ``sampling``: per (quadric, sampling plane, sheet) an adaptive subdivision on the device,
   each cell with its pruned tape: :func:`sample` returns :class:`Samples`.
4. ``rendering``: splats with local ray tracing and clipping by tape (:func:`render`) and the
   exact tree ray tracer (:func:`raytrace`), both into an :class:`Image`.
5. ``cl`` is the OpenCL plumbing (devices, programs, records, shared constants); ``cli`` the
   command line, one module per command.
6. ``queries``: occupancy and a conservative signed distance at given points, on the device
   (:func:`inside`, :func:`distance`); ``batching``: many scenes sampled (and rendered) into a
   folder with a manifest, on a process pool or a Dask cluster (:func:`batch`).
"""
from .errors import ClcsgError
from .model.csg import Shape, contains, difference, intersection, union
from .model.quadric import Quadric
from .model.solids import box, cone, cylinder, ellipsoid, halfspace, quadric, slab, sphere
from .model.profile import Profile, circle, polygon, square
from .model.profile_ops import offset
from .model.extrude import extrude
from .model.revolve import revolve
from .model.hull import hull, minkowski

__version__ = "0.2.0"
from .cl.device import devices
from .model.scene import Scene, load, save
from .rendering.camera import Camera, orbit
from .rendering.image import Image
from .rendering.raytracer import raytrace
from .rendering.splat import render
from .sampling.sampler import sample
from .sampling.samples import Samples, load_samples
from .queries import distance, inside
from .batching.api import batch
from .meshing import mesh

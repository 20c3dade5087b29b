"""clcsg: exact point sampling and pixel-perfect splat rendering of quadric CSG solids."""
from .model.csg import Shape, contains, difference, intersection, union
from .errors import ClcsgError
from .model.quadric import Quadric
from .model.solids import box, cone, cylinder, ellipsoid, halfspace, quadric, slab, sphere

__version__ = "0.1.0"
from .model.scene import Scene, load, save
from .cl.device import devices
from .sampling.sampler import sample
from .sampling.samples import Samples
from .rendering.camera import Camera, orbit
from .rendering.image import Image
from .rendering.api import raytrace, render

"""clcsg: exact point sampling and pixel-perfect splat rendering of quadric CSG solids."""
from .csg import Shape, contains, difference, intersection, union
from .errors import ClcsgError
from .quadric import Quadric
from .solids import box, cone, cylinder, ellipsoid, halfspace, quadric, slab, sphere

__version__ = "0.1.0"
from .scene import Scene, load, save
from .host.device import devices
from .host.sampler import sample
from .samples import Samples
from .camera import Camera, orbit
from .image import Image
from .render import raytrace, render

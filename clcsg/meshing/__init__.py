"""Triangle meshes of quadric CSG solids: closed, 2-manifold, every vertex on the exact surface,
sharp edges on the exact intersection curves (:func:`mesh`), and their files (:mod:`.writers`)."""

from .mesher import DEFAULT_TOLERANCE, Mesh, mesh

__all__ = ["DEFAULT_TOLERANCE", "Mesh", "mesh"]

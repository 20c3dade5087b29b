"""``clcsg mesh``: a closed, 2-manifold triangle mesh of a scene for printing or CAD."""

from __future__ import annotations

from ..meshing.mesher import DEFAULT_CELLS, DEFAULT_TOLERANCE, METHODS, mesh
from ..meshing.writers import FORMATS, check_output, write
from ..sampling.radius import Radius
from .app import add_subcommand, parse_bound, positive_int
from .runs import Run, load_scene


def add_parser(subparsers):
    p = add_subcommand(
        subparsers,
        "mesh",
        help="write a watertight triangle mesh (STL, 3MF, OBJ, PLY, OFF)",
        description=f"""
            Mesh a scene (.json, OpenSCAD .csg or .scad) into a closed, consistently oriented,
            2-manifold triangle mesh whose vertices lie on the exact quadric surfaces in double
            precision, on their exact intersection curves at sharp edges and at the exact
            corners.  Method "facets" (the default wherever every primitive is a box, cylinder,
            cone, sphere, ellipsoid, half-space, slab, infinite or elliptic cylinder): each primitive
            faceted within the tolerance (circles get the fewest segments whose chord error
            is under it), manifold3d's exact Booleans, then every vertex solved onto its
            quadrics; primitives faceted again finer where the result strays.  Method
            "contour" (any quadric): marching tetrahedra on the grid cells the pruned tape
            keeps, edges split onto the intersection curves and collapsed within the chord
            error (flat faces to their boundary).  Formats: {', '.join(FORMATS)}
            (from the extension, checked before any work; STL is binary; 3MF, PLY and OBJ get
            each triangle's primitive colour).  An empty solid is an error (exit code 3) and
            writes no file.  Runs on the host (numpy); --device is not used.
        """,
        epilog="""
            examples:
              clcsg mesh examples/pipe_flange.scad -o flange.stl
              clcsg mesh examples/bracket.json -o bracket.3mf --tolerance 0.05%
              clcsg mesh examples/rook.csg -o rook.ply --tolerance 0.02
        """,
    )
    p.add_argument("scene", metavar="SCENE", help="scene file (.json, OpenSCAD .csg or .scad)")
    p.add_argument("-o", "--output", metavar="OUT", required=True, help=f"mesh file ({', '.join(FORMATS)})")
    p.add_argument("-t", "--tolerance", metavar="T", default=DEFAULT_TOLERANCE,
                   help="largest chord error: scene units, or a percentage of the bound's diagonal "
                        f"(default {DEFAULT_TOLERANCE.replace('%', '%%')})")
    p.add_argument("--method", choices=METHODS, default="auto",
                   help="facets, contour, or auto: facets where every primitive has a closed-form faceting "
                        "(default auto)")
    p.add_argument("--cells", metavar="N", type=positive_int, default=DEFAULT_CELLS,
                   help=f"contour method: grid cells over the bound's longest side before refinement (default "
                        f"{DEFAULT_CELLS}); features thinner than an eighth of a cell may be lost, raise it for thinner walls")
    p.add_argument("--bound", metavar="x0,y0,z0,x1,y1,z1", default=None,
                   help="box that clips unbounded terms (overrides the scene's own bound)")


def run(args) -> int:
    check_output(args.output)
    Radius.parse(args.tolerance, "--tolerance")
    bound = None if args.bound is None else parse_bound(args.bound, "--bound")
    run_ = Run("mesh")
    scene = load_scene(run_, args.scene, bound)
    with run_.step("mesh", "meshing"):
        m = mesh(scene, tolerance=args.tolerance, cells=max(int(args.cells), 4), method=args.method)
    with run_.step("write", f"writing {args.output}"):
        write(m, args.output)
        run_.wrote(args.output)
    st = m.stats
    run_.summary(f"{len(m.triangles):,} triangles, {len(m.vertices):,} vertices (tolerance {m.tolerance:.6g}, "
                 f"{st.get('spanning_triangles', 0)} triangles across a sharp edge)",
                 triangles=len(m.triangles), vertices=len(m.vertices), tolerance=m.tolerance,
                 spanning_triangles=st.get("spanning_triangles", 0))
    return 0

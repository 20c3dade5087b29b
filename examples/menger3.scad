// menger3.scad: a level-3 Menger sponge, the classic recursive way: one cube minus, for each
// axis, a bar through the middle plus the same pattern one third the size in the eight
// cells around it, three levels deep.  Optionally stood on a corner.
// Units: mm.  Export for clcsg: openscad -o menger3.csg menger3.scad

size      = 81;      // edge length
level     = 3;       // recursion depth
on_corner = true;    // stand it on a corner (body diagonal vertical)

// the holes along x: a bar of one third the cell, then the same in the 8 cells around it
module holes_x(cell, level) {
    bar = cell / 3;
    cube([size * 1.1, bar, bar], center = true);
    if (level > 1)
        for (i = [-1 : 1], j = [-1 : 1])
            if (i != 0 || j != 0)
                translate([0, i * bar, j * bar])
                    holes_x(bar, level - 1);
}

module menger() {
    difference() {
        color("gold") cube(size, center = true);
        for (r = [[0, 0, 0], [0, 0, 90], [0, 90, 0]])   // x, y and z
            rotate(r) holes_x(size, level);
    }
}

if (on_corner)
    rotate([45, atan(1 / sqrt(2)), 0]) menger();
else
    menger();

// plate_12_holes.scad: a mounting plate with twelve counterbored holes for M6 socket head cap
// screws; each counterbore has a chamfered edge and the through hole is deburred underneath.
// Units: mm.  Export for clcsg: openscad -o plate_12_holes.csg plate_12_holes.scad

/* [Plate] */
plate      = [160, 110, 12];
margin     = 16;          // hole centres from the plate edges
cols       = 4;
rows       = 3;

/* [Holes: M6 SHCS] */
hole_d     = 6.6;         // clearance
cbore_d    = 11;
cbore_h    = 6.5;
chamfer    = 0.8;         // 45 degree chamfer on the counterbore edge
deburr     = 0.5;         // 45 degree chamfer under the through hole

$fn = 48;

eps = 0.01;

module counterbored_hole() {
    t = plate.z;
    translate([0, 0, -1]) cylinder(h = t + 2, d = hole_d);                      // through
    translate([0, 0, t - cbore_h]) cylinder(h = cbore_h + 1, d = cbore_d);      // counterbore
    translate([0, 0, t - chamfer])
        cylinder(h = chamfer + eps, d1 = cbore_d, d2 = cbore_d + 2 * chamfer);  // edge chamfer
    translate([0, 0, -eps])
        cylinder(h = deburr + eps, d1 = hole_d + 2 * deburr, d2 = hole_d);      // deburr
}

dx = (plate.x - 2 * margin) / (cols - 1);
dy = (plate.y - 2 * margin) / (rows - 1);

color("lightsteelblue") difference() {
    cube(plate);
    for (i = [0 : cols - 1], j = [0 : rows - 1])
        translate([margin + i * dx, margin + j * dy, 0]) counterbored_hole();
}

// l_bracket.scad: an L (angle) bracket with a fillet, a centre gusset and four countersunk
// holes for 90-degree flat-head screws (cone frusta over through holes).
// Units: mm.  Export for clcsg: openscad -o l_bracket.csg l_bracket.scad

/* [Bracket] */
width      = 40;    // along y
base_len   = 50;    // horizontal leg, along x
upright_h  = 45;    // vertical leg, along z
thickness  = 5;
fillet_r   = 4;     // inside corner fillet

/* [Gusset] */
gusset_t   = 4;
gusset_x   = 30;
gusset_z   = 27;

/* [Holes] */
hole_d     = 4.5;   // M4 clearance
head_d     = 8.6;   // countersink diameter at the surface
hole_edge  = 12;    // hole centre from the free end of each leg
hole_y     = [10, 30];

$fn = 64;

eps = 0.01;

// a countersunk hole whose surface is the plane z = 0 (material below)
module countersunk_hole(depth) {
    sink = (head_d - hole_d) / 2;   // 90 degree countersink
    translate([0, 0, -depth - 1]) cylinder(h = depth + 2, d = hole_d);
    translate([0, 0, -sink]) cylinder(h = sink + eps, d1 = hole_d, d2 = head_d);
    cylinder(h = 1, d = head_d);    // clearance above the surface
}

color("silver") difference() {
    union() {
        cube([base_len, width, thickness]);                     // horizontal leg
        cube([thickness, width, upright_h]);                    // vertical leg
        // inside fillet: a square minus a quarter cylinder
        translate([thickness - eps, 0, thickness - eps]) difference() {
            cube([fillet_r, width, fillet_r]);
            translate([fillet_r, -1, fillet_r]) rotate([-90, 0, 0]) cylinder(h = width + 2, r = fillet_r);
        }
        // gusset: a box with the hypotenuse cut off by a rotated box
        translate([0, (width - gusset_t) / 2, 0]) difference() {
            cube([gusset_x, gusset_t, gusset_z]);
            translate([0, -1, gusset_z])
                rotate([0, atan(gusset_z / gusset_x), 0])
                    cube([2 * (gusset_x + gusset_z), gusset_t + 2, gusset_x + gusset_z]);
        }
    }
    // holes in the horizontal leg, screwed from above
    for (y = hole_y)
        translate([base_len - hole_edge, y, thickness]) countersunk_hole(thickness);
    // holes in the vertical leg, screwed from the inside face
    for (y = hole_y)
        translate([thickness, y, upright_h - hole_edge]) rotate([0, 90, 0]) countersunk_hole(thickness);
}

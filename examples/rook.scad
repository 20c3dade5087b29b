// rook.scad: a turned chess rook (Staunton-ish) with a crenellated, hollow turret and a felt pad.
// Units: mm.  Export for clcsg: openscad -o rook.csg rook.scad

/* [Size] */
base_r     = 15;    // foot radius
foot_h     = 4;
bevel_h    = 3;
body_h     = 26;
body_r0    = 10.5;  // body radius at the bottom
body_r1    = 7.5;   // body radius under the turret
turret_r   = 10.5;
turret_h   = 11;

/* [Crenels] */
crenels    = 6;
crenel_w   = 4.2;   // width of each gap
crenel_d   = 4.5;   // depth of each gap
well_r     = 7;     // radius of the hollow in the turret
well_d     = 6;

$fn = 120;

eps = 0.01;
z_body   = foot_h + bevel_h;
z_flare  = z_body + body_h - 2;
z_turret = z_flare + 3;
top      = z_turret + turret_h;

color("ivory") difference() {
    union() {
        cylinder(h = foot_h, r = base_r);                                        // foot
        translate([0, 0, foot_h - eps])
            cylinder(h = bevel_h + eps, r1 = base_r, r2 = base_r - 3);          // bevel
        translate([0, 0, z_body])
            scale([1, 1, 0.38]) sphere(r = base_r - 2.5);                       // bead (an ellipsoid)
        translate([0, 0, z_body])
            cylinder(h = body_h, r1 = body_r0, r2 = body_r1);                   // tapered body
        translate([0, 0, z_flare])
            cylinder(h = 3 + eps, r1 = body_r1, r2 = turret_r);                 // flare
        translate([0, 0, z_turret])
            cylinder(h = turret_h, r = turret_r);                               // turret
        translate([0, 0, z_turret - 1.2])
            cylinder(h = 1.2, r = turret_r + 0.8);                              // turret ring
    }
    // hollow top
    translate([0, 0, top - well_d])
        cylinder(h = well_d + 1, r = well_r);
    // crenels: boxes cut through the turret wall
    for (i = [0 : crenels - 1])
        rotate([0, 0, i * 360 / crenels])
            translate([0, -crenel_w / 2, top - crenel_d])
                cube([turret_r + 2, crenel_w, crenel_d + 1]);
    // hollow under the foot
    translate([0, 0, -1])
        cylinder(h = 4, r1 = 10, r2 = 7.5);
}

// felt pad
color("darkgreen") translate([0, 0, -0.6]) difference() {
    cylinder(h = 0.6, r = base_r - 0.5);
    cylinder(h = 2, r = 10, center = true);
}

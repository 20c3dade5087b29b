// pipe_flange.scad: a weld-neck pipe flange (DN 150 style) with a raised face, a tapered hub,
// a 16-hole bolt circle and a spot face (shallow counterbore) for every nut on the back.
// Units: mm.  Export for clcsg: openscad -o pipe_flange.csg pipe_flange.scad

/* [Flange] */
flange_d        = 300;   // outside diameter of the disc
flange_t        = 24;    // disc thickness
raised_face_d   = 212;   // gasket (raised) face
raised_face_h   = 2;

/* [Hub and bore] */
hub_base_d      = 190;   // hub diameter where it meets the disc
hub_top_d       = 168;   // hub diameter at the weld end
hub_h           = 56;    // hub height above the disc
bore_d          = 154;
weld_bevel      = 4;     // 37.5 deg weld prep on the hub end

/* [Bolting] */
bolts           = 16;
bolt_circle_d   = 256;
bolt_hole_d     = 22;    // M20 clearance
spot_face_d     = 40;
spot_face_depth = 2.5;

$fn = 96;

eps = 0.01;

module bolt_hole() {
    // through hole
    translate([0, 0, -raised_face_h - 1])
        cylinder(h = raised_face_h + flange_t + 2, d = bolt_hole_d);
    // spot face on the nut side (back of the disc, next to the hub)
    translate([0, 0, flange_t - spot_face_depth])
        cylinder(h = spot_face_depth + 1, d = spot_face_d);
}

color("slategray") difference() {
    union() {
        cylinder(h = flange_t, d = flange_d);                                  // disc
        translate([0, 0, -raised_face_h])
            cylinder(h = raised_face_h + eps, d = raised_face_d);              // raised face
        translate([0, 0, flange_t - eps])
            cylinder(h = hub_h + eps, d1 = hub_base_d, d2 = hub_top_d);        // tapered hub
    }
    // bore, right through
    translate([0, 0, -raised_face_h - 1])
        cylinder(h = raised_face_h + flange_t + hub_h + 2, d = bore_d);
    // weld bevel: a cone that thins the hub lip towards the outside
    translate([0, 0, flange_t + hub_h - weld_bevel])
        difference() {
            cylinder(h = weld_bevel + 1, d = hub_top_d + 2);
            translate([0, 0, -eps])
                cylinder(h = weld_bevel + 1 + 2 * eps,
                         d1 = hub_top_d, d2 = hub_top_d - 2 * (weld_bevel + 1) * 0.77);
        }
    // bolt circle, holes straddling the centre lines as the standards ask
    for (i = [0 : bolts - 1])
        rotate([0, 0, (i + 0.5) * 360 / bolts])
            translate([bolt_circle_d / 2, 0, 0])
                bolt_hole();
}

// project_box.scad: an electronics project box with rounded corners, a lid ledge,
// four screw bosses for M3 self-tappers and a cable entry.  No hull(): the rounded outline is
// two cubes and four corner cylinders.
// Units: mm.  Export for clcsg: openscad -o project_box.csg project_box.scad

/* [Outside] */
length      = 100;
width       = 64;
height      = 36;
corner_r    = 6;

/* [Walls] */
wall        = 2.4;
floor_t     = 2;
ledge_w     = 1.2;   // lid sits on this ledge
ledge_h     = 2;

/* [Bosses] */
boss_d      = 7;
boss_hole_d = 2.5;   // M3 self-tapping pilot
boss_inset  = wall + boss_d / 2 - 0.5;  // boss axis from the outside walls
boss_gap    = ledge_h + 0.5;             // bosses stop below the lid

/* [Cable entry] */
cable_d     = 8;
cable_z     = 14;

$fn = 64;

eps = 0.01;

// rounded box, lower corner at the origin: two cubes and a cylinder at each corner
module rounded_box(size, r) {
    translate([r, 0, 0]) cube([size.x - 2 * r, size.y, size.z]);
    translate([0, r, 0]) cube([size.x, size.y - 2 * r, size.z]);
    for (x = [r, size.x - r], y = [r, size.y - r])
        translate([x, y, 0]) cylinder(h = size.z, r = r);
}

boss_xy = [for (x = [boss_inset, length - boss_inset], y = [boss_inset, width - boss_inset]) [x, y]];

difference() {
    union() {
        color("dimgray") difference() {
            rounded_box([length, width, height], corner_r);
            // cavity
            translate([wall, wall, floor_t])
                rounded_box([length - 2 * wall, width - 2 * wall, height], corner_r - wall);
            // lid ledge: the top of the wall is thinner
            translate([wall - ledge_w, wall - ledge_w, height - ledge_h])
                rounded_box([length - 2 * (wall - ledge_w), width - 2 * (wall - ledge_w), ledge_h + 1],
                            corner_r - (wall - ledge_w));
        }
        // screw bosses
        color("orange") for (p = boss_xy)
            translate([p.x, p.y, floor_t - eps])
                cylinder(h = height - floor_t - boss_gap + eps, d = boss_d);
    }
    // pilot holes in the bosses
    for (p = boss_xy)
        translate([p.x, p.y, floor_t + 1])
            cylinder(h = height, d = boss_hole_d);
    // cable entry through one end wall
    translate([-1, width / 2, cable_z])
        rotate([0, 90, 0]) cylinder(h = wall + 2, d = cable_d);
}

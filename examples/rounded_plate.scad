// rounded_plate.scad: a mounting plate, linear_extrude of a rounded rectangle (offset r) with 4 holes
w = 40; d = 24; r = 4; t = 3; hole = 1.6;
color("silver") linear_extrude(height = t)
    difference() {
        offset(r = r) square([w - 2 * r, d - 2 * r]);
        for (x = [0, w - 2 * r], y = [0, d - 2 * r]) translate([x, y]) circle(hole);
    }

// rounded_box.scad: the rounded-box idiom, hull() of 8 corner spheres (exact: planes, cylinders, spheres)
size = [30, 20, 10];
r = 3;
color("teal") hull()
    for (x = [r, size[0] - r], y = [r, size[1] - r], z = [r, size[2] - r])
        translate([x, y, z]) sphere(r);

// A pen stand and two small parts, all of them exact quadric CSG in clcsg:
// - the stand is the hull of a square base plate and a round top ring (a cube and a parallel
//   cylinder with other caps: planes and oblique cones), bored out;
// - the knob is the hull of three spheres of different radii (face planes, tangent cones, spheres);
// - the tab is a turned plate rounded across by a cylinder lying along y (the sum of a
//   polytope and a cylinder in another direction: offset planes and oblique cylinders).
difference() {
    hull() {
        cube([30, 30, 2], center = true);
        translate([0, 0, 40]) cylinder(h = 2, r = 10);
    }
    translate([0, 0, 5]) cylinder(h = 50, r = 8);
}
translate([40, 0, -1]) hull() {
    sphere(6);
    translate([0, 0, 14]) sphere(3);
    translate([8, 0, 6]) sphere(2);
}
translate([-10, -40, -1]) minkowski() {
    rotate([0, 0, 30]) cube([20, 8, 3]);
    rotate([90, 0, 0]) cylinder(h = 1, r = 2, center = true);
}

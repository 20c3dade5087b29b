// knob.scad: a turned knob, rotate_extrude of a polygon profile (cylinders and cones), with a bore
color("darkred") rotate_extrude()
    polygon([[1, 0], [6, 0], [6, 2], [4, 5], [1.5, 5], [1.5, 3], [1, 3]]);

(Arcs: G2/G3 with I J centre offsets, with R radius, and a full circle; XY table, no Z)
%
G17 G21 G90 G94 G64
F1500
G0 X0 Y0
G1 X20 Y0
G3 X40 Y20 I0 J20          (quarter circle, counter-clockwise, centre X20 Y20)
G2 X60 Y40 R20             (quarter circle, clockwise, radius form)
G3 X40 Y60 R-20            (three-quarter circle: negative R asks for the long way round)
G1 X20 Y60
G2 I0 J-10                 (full circle of radius 10 about X20 Y50, back to X20 Y60)
G90.1                      (absolute arc centres)
G3 X0 Y40 I20 J40          (centre at X20 Y40 given absolutely)
G91.1
G1 X0 Y0
M2
%

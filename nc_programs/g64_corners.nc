(G64 P: straight moves with sharp corners blended within a path tolerance; G61 exact stop)
G17 G21 G90
F3000
G0 X0 Y0
G64 P0.05                  (corners may be rounded by at most 0.05 mm)
G1 X50 Y0
G1 X50 Y30
G1 X80 Y30
G1 X80 Y-30
G1 X20 Y-40
G64 P0.01 Q0.005           (tighter tolerance, Q merges collinear short moves)
G1 X0 Y-20
G1 X-40 Y-20
G1 X-40 Y20
G61                        (exact stop: every corner is a full stop)
G1 X-10 Y40
G1 X0 Y0
M2

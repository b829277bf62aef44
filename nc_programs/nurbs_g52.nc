(LinuxCNC G5.2 NURBS: L = order, P = weight, the current position is the first control point)
G17 G21 G90
G0 X0 Y0
F2000
G5.2 P1 L4
    X10 Y30 P1
    X40 Y40 P2
    X60 Y-10 P1
    X90 Y20 P0.5
    X100 Y0 P1
G5.3
G1 X100 Y-20
G5.2 P1 L3                 (a quadratic with a heavy middle point)
    X50 Y-60 P4
    X0 Y-20 P1
G5.3
G1 X0 Y0
M2

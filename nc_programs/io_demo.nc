(io_demo.nc: machine I/O on the xyz_mill: spindle, coolant, outputs, a manual tool change,)
(tool lengths and a probe)
(tools: T1 and T2 must be in the tool table in force: cncctl tool set T1 Z... D...)
(check: cncctl check nc_programs/io_demo.nc --config xyz_mill --tools TBL; run it on the)
(sim card with --drive-option probe_workpiece_mm=-50,-50,-50,50,50,0: the top face at Z0)
G21 G90 G94 G17 G54
G0 Z20
T1 M6                     (to the change position, spindle off, wait for the operator)
G43                       (T1's length in force: it follows each change from here)
M3 S8000
M8
M64 P0                    (digital output P0 on at once: the dust extraction)
M68 E0 Q2.5               (analog output E0 at once: 2.5)
G0 X10 Y10
F300
G38.2 Z-30                (probe down onto the work: #5063 holds the top face)
G0 Z5
G1 X40 Y10 F600
G1 X40 Y40
G1 X10 Y40
G1 X10 Y10
G0 Z20
M5 M9
T2 M6                     (the spindle is off again; T2's length applies after it)
M3 S6000
G0 X25 Y25
G1 Z-2 F200
G0 Z20
M5
M65 P0                    (P0 off)
M2

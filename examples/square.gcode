; fivebar example: a square and a circle as a pen plotter's G-code (no M3/M4: every G1/G2/G3
; draws). Made for this project. fivebar plot examples/square.gcode --dry-run
G21
G90
G0 X0 Y0
G1 X30 Y0 F1800
G1 X30 Y30
G1 X0 Y30
G1 X0 Y0
G0 X15 Y5
G3 X15 Y5 I0 J10

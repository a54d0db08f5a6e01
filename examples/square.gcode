; fivebar example: a square and a circle as a pen plotter's G-code (no M3/M4: every G1/G2/G3
; draws), written in the default machine's coordinates (mm, motor M1 at the origin): a G-code
; file is drawn where it says. Made for this project. fivebar plot examples/square.gcode --dry-run
; (--fit or --origin X,Y place a file written for another frame).
G21
G90
G0 X5 Y95
G1 X35 Y95 F1800
G1 X35 Y125
G1 X5 Y125
G1 X5 Y95
G0 X20 Y100
G3 X20 Y100 I0 J10

; fivebar example: a laser job written in *machine* coordinates (mm, motor M1 at the origin),
; below and to the right of the motors. Made for this project. It is only reachable with the
; pen below the elbows (assembly "-"), so it needs a machine built that way:
;   fivebar plot examples/underside_machine_coords.gcode --origin 0,0 --mode auto --dry-run \
;     --config configs/underside.toml
; The profile's working mode "+-" cannot reach it within the joint limits; --mode auto finds a
; mode that can ("++") and says why the others fail. With the default profile (assembly "+")
; every mode refuses it, naming the assembly.
G21 G90 G17
G0 X75 Y-46
M3 S200
G1 X97 Y-46 F1200     ; frame
G1 X97 Y-34
G1 X75 Y-34
G1 X75 Y-46
M5
G0 X82 Y-40
M3 S255
G2 X82 Y-40 I3 J0     ; full circle, centre (85, -40)
M5
G0 X90 Y-43
M3 S255
G3 X94 Y-37 R5        ; quarter arc, counter-clockwise
M5
M2

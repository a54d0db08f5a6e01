; fivebar example: a pen drawing in *machine* coordinates (mm, motor M1 at the origin) that no
; single working mode of the default machine can draw. Made for this project. Run it as:
;   fivebar plot examples/mode_change.gcode --origin 0,0 --mode auto --dry-run
; The square (left) is safe only with both elbows outward ("+-"), the circle (right) only in
; "++"; the line along the top starts in "+-" territory and ends in "++" territory, so it is
; split where both are safe. --mode auto plans the pen-up changes: arm 2 swings through its
; stretched pose (a type-1 singularity the motor drives through) while the type-2 margin, the
; joint limits and the assembly mode are kept; the dry-run report lists every change.
G21 G90
G0 X14 Y71
G1 X24 Y71 F1200    ; square, "+-" only
G1 X24 Y81
G1 X14 Y81
G1 X14 Y71
G0 X12 Y84
G1 X64 Y84          ; top line: "+-" on the left, "++" on the right
G0 X74 Y60
G2 X74 Y60 I-6 J0   ; circle, centre (68, 60), "++" only

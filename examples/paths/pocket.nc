%
(Pocket 120 x 80 mm, 2 mm deep, on a workpiece whose origin is a corner of its top face.)
(Workpiece frame on the command line: --frame 370,-40,-150,0,0,0  [mm, deg].)
(Straight passes, then the finishing contour in incremental mode; G0 moves carry no force.)
N10 G21 G90 G17 G94      ; mm, absolute
N20 G0 X10 Y10 Z10       ; approach above the pocket
N30 G1 Z-2 F300          ; plunge
N40 G1 X110 F1200        ; first pass
N50 Y20
N60 X10
N70 Y30
N80 X110
N90 Y40
N100 X10
N110 Y50
N120 X110
N130 Y60
N140 X10
N150 Y70
N160 X110
(Finishing contour, incremental)
N170 G91
N180 G1 Y-60 F800
N190 X-100
N200 Y60
N210 X100
N220 G90
N230 G0 Z10
N240 M30
%

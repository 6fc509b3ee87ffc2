G20 G91
G0 X1 Y1 Z0.5
G1 X2 F10 (inch, relative)
G1 Y-1
M30

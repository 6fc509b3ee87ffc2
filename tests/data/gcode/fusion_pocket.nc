%
O01001 (POCKET 40X30)
(Written in the style of an Autodesk Fusion Haas/Fanuc post-processor output.)
(Machine)
(  vendor: generic)
(  description: 3-axis mill)
(T1 D=6. CR=0. TAPER=118deg - ZMIN=-1. - flat end mill)
N10 G90 G94 G17
N15 G21
N20 G53 G0 Z0.

(2D Pocket1)
N25 T1 M6
N30 S10000 M3
N35 G54
N40 M8
N45 G0 X20. Y15.
N50 G43 Z15. H1
N55 G0 Z5.
N60 G1 Z1. F1000.
N65 Z-1. F333.3
N70 G3 X23. Y15. I1.5 J0. F1000.
N75 G1 X30.
N80 G3 X35. Y20. I0. J5.
N85 G1 Y25.
N90 G3 X30. Y30. I-5. J0.
N95 G1 X10.
N100 G3 X5. Y25. I0. J-5.
N105 G1 Y20.
N110 G3 X10. Y15. I5. J0.
N115 G1 X20.
N120 G3 X20. Y15. I0. J5.
N125 G0 Z15.
N130 M9
N135 G53 G0 Z0.
N140 M30
%

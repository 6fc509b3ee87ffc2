/PROG  SLOT
/ATTR
COMMENT		= "60x60 pocket";
DEFAULT_GROUP	= 1,*,*,*,*;
/MN
   1:  UFRAME_NUM=1 ;
   2:  UTOOL_NUM=1 ;
   3:J P[1] 50% FINE    ;
   4:L P[2] 20mm/sec CNT50    ;
   5:L P[3] 20mm/sec CNT50    ;
   6:L P[4] 20mm/sec CNT50    ;
   7:L P[5] 20mm/sec CNT50    ;
   8:L P[6] 20mm/sec CNT50    ;
   9:L P[7] 20mm/sec CNT50    ;
   10:J P[8] 50% FINE    ;
/POS
P[1]{
   GP1:
	UF : 1, UT : 1,		CONFIG : 'F U T, 0, 0, 0',
	X =     0.000  mm,	Y =     0.000  mm,	Z =    60.000  mm,
	W =  180.000 deg,	P =   10.000 deg,	R =    0.000 deg
};
P[2]{
   GP1:
	UF : 1, UT : 1,		CONFIG : 'F U T, 0, 0, 0',
	X =     0.000  mm,	Y =     0.000  mm,	Z =     5.000  mm,
	W =  180.000 deg,	P =   10.000 deg,	R =    0.000 deg
};
P[3]{
   GP1:
	UF : 1, UT : 1,		CONFIG : 'F U T, 0, 0, 0',
	X =     0.000  mm,	Y =     0.000  mm,	Z =    -2.000  mm,
	W =  180.000 deg,	P =   10.000 deg,	R =    0.000 deg
};
P[4]{
   GP1:
	UF : 1, UT : 1,		CONFIG : 'F U T, 0, 0, 0',
	X =    60.000  mm,	Y =     0.000  mm,	Z =    -2.000  mm,
	W =  180.000 deg,	P =   10.000 deg,	R =    0.000 deg
};
P[5]{
   GP1:
	UF : 1, UT : 1,		CONFIG : 'F U T, 0, 0, 0',
	X =    60.000  mm,	Y =    60.000  mm,	Z =    -2.000  mm,
	W =  180.000 deg,	P =   10.000 deg,	R =    0.000 deg
};
P[6]{
   GP1:
	UF : 1, UT : 1,		CONFIG : 'F U T, 0, 0, 0',
	X =     0.000  mm,	Y =    60.000  mm,	Z =    -2.000  mm,
	W =  180.000 deg,	P =   10.000 deg,	R =    0.000 deg
};
P[7]{
   GP1:
	UF : 1, UT : 1,		CONFIG : 'F U T, 0, 0, 0',
	X =     0.000  mm,	Y =     0.000  mm,	Z =    -2.000  mm,
	W =  180.000 deg,	P =   10.000 deg,	R =    0.000 deg
};
P[8]{
   GP1:
	UF : 1, UT : 1,		CONFIG : 'F U T, 0, 0, 0',
	X =     0.000  mm,	Y =     0.000  mm,	Z =    60.000  mm,
	W =  180.000 deg,	P =   10.000 deg,	R =    0.000 deg
};
/END

MODULE Slot
  ! 60 x 60 mm pocket contour, 2 mm deep, 10 mm end mill on wobjPart
  PERS tooldata tSpindle:=[TRUE,[[0.0,0.0,120.0],[1,0,0,0]],[4.5,[0,0,60],[1,0,0,0],0,0,0]];
  PERS wobjdata wobjPart:=[FALSE,TRUE,"",[[420.0,-100.0,-180.0],[0.991445,0,0,0.130526]],[[0,0,0],[1,0,0,0]]];
  CONST speeddata vMill:=[20,500,5000,1000];
  CONST jointtarget jHome:=[[0,-10,-20,0,-60,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget p10:=[[0.000,0.000,60.000],[0.00000000,0.99619470,0.00000000,-0.08715574],[-1,-1,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget p20:=[[0.000,0.000,5.000],[0.00000000,0.99619470,0.00000000,-0.08715574],[-1,-1,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget p30:=[[0.000,0.000,-2.000],[0.00000000,0.99619470,0.00000000,-0.08715574],[-1,-1,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget p40:=[[60.000,0.000,-2.000],[0.00000000,0.99619470,0.00000000,-0.08715574],[-1,-1,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget p50:=[[60.000,60.000,-2.000],[0.00000000,0.99619470,0.00000000,-0.08715574],[-1,-1,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget p60:=[[0.000,60.000,-2.000],[0.00000000,0.99619470,0.00000000,-0.08715574],[-1,-1,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget p70:=[[0.000,0.000,-2.000],[0.00000000,0.99619470,0.00000000,-0.08715574],[-1,-1,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget p80:=[[0.000,0.000,60.000],[0.00000000,0.99619470,0.00000000,-0.08715574],[-1,-1,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];

  PROC main()
    MoveAbsJ jHome, v500, fine, tSpindle;
    MoveJ p10, v200, z5, tSpindle\WObj:=wobjPart;
    MoveL p20, vMill, z1, tSpindle\WObj:=wobjPart;  ! cut
    MoveL p30, vMill, z1, tSpindle\WObj:=wobjPart;  ! cut
    MoveL p40, vMill, z1, tSpindle\WObj:=wobjPart;  ! cut
    MoveL p50, vMill, z1, tSpindle\WObj:=wobjPart;  ! cut
    MoveL p60, vMill, z1, tSpindle\WObj:=wobjPart;  ! cut
    MoveL p70, vMill, z1, tSpindle\WObj:=wobjPart;  ! cut
    MoveJ p80, v200, z5, tSpindle\WObj:=wobjPart;
    MoveAbsJ jHome, v500, fine, tSpindle;
  ENDPROC
ENDMODULE

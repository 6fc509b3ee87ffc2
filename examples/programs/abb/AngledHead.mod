MODULE AngledHead
  ! 60 x 60 mm pocket contour with an angled spindle head on wobjPart
  PERS tooldata tAngled:=[TRUE,[[80.0,0.0,110.0],[0.96592583,0.00000000,0.25881905,0.00000000]],[6.0,[40,0,80],[1,0,0,0],0,0,0]];
  PERS wobjdata wobjPart:=[FALSE,TRUE,"",[[420.0,-100.0,-180.0],[0.991445,0,0,0.130526]],[[0,0,0],[1,0,0,0]]];
  CONST speeddata vMill:=[20,500,5000,1000];
  CONST robtarget p10:=[[0.000,0.000,60.000],[0.00000000,1.00000000,0.00000000,0.00000000],[-1,-1,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget p20:=[[0.000,0.000,5.000],[0.00000000,1.00000000,0.00000000,0.00000000],[-1,-1,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget p30:=[[0.000,0.000,-2.000],[0.00000000,1.00000000,0.00000000,0.00000000],[-1,-1,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget p40:=[[60.000,0.000,-2.000],[0.00000000,1.00000000,0.00000000,0.00000000],[-1,-1,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget p50:=[[60.000,60.000,-2.000],[0.00000000,1.00000000,0.00000000,0.00000000],[-1,-1,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget p60:=[[0.000,60.000,-2.000],[0.00000000,1.00000000,0.00000000,0.00000000],[-1,-1,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget p70:=[[0.000,0.000,-2.000],[0.00000000,1.00000000,0.00000000,0.00000000],[-1,-1,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  CONST robtarget p80:=[[0.000,0.000,60.000],[0.00000000,1.00000000,0.00000000,0.00000000],[-1,-1,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];

  PROC main()
    MoveJ p10, v200, z5, tAngled\WObj:=wobjPart;
    MoveL p20, vMill, z1, tAngled\WObj:=wobjPart;
    MoveL p30, vMill, z1, tAngled\WObj:=wobjPart;
    MoveL p40, vMill, z1, tAngled\WObj:=wobjPart;
    MoveL p50, vMill, z1, tAngled\WObj:=wobjPart;
    MoveL p60, vMill, z1, tAngled\WObj:=wobjPart;
    MoveL p70, vMill, z1, tAngled\WObj:=wobjPart;
    MoveJ p80, v200, z5, tAngled\WObj:=wobjPart;
  ENDPROC
ENDMODULE

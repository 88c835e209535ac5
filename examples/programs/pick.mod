MODULE Pick
    ! a small pick-and-place for an IRB 120 (mm, deg, quaternions), written against the nominal model
    PERS tooldata gripper:=[TRUE,[[0,0,0],[1,0,0,0]],[0.5,[0,0,50],[1,0,0,0],0,0,0]];
    CONST jointtarget jhome:=[[0,0,0,0,30,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
    CONST robtarget pApproach:=[[374.76,143.05,513.75],[0.311829,-0.025779,0.937437,0.152675],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
    CONST robtarget pPick:=[[374.76,143.05,463.75],[0.311829,-0.025779,0.937437,0.152675],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
    CONST robtarget pVia:=[[330.0,0.0,560.0],[0.5,0,0.866025,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];

    PROC main()
        MoveAbsJ jhome, v1000, fine, gripper;
        MoveJ pApproach, v1000, z50, gripper;
        MoveL pPick, v100, fine, gripper;
        SetDO do1, 1;
        MoveL pApproach, v100, z10, gripper;
        MoveL [[296.47,-87.76,517.93],[0.302252,-0.084369,0.933325,-0.174442],[-1,-1,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]], v200, z10, gripper;
        MoveC pVia, [[364.35,0.0,594.0],[0.5,0,0.866025,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]], v100, z10, gripper;
        MoveL Offs(pPick,0,0,50), v100, fine, gripper;
        MoveAbsJ [[20,10,10,10,30,10],[9E9,9E9,9E9,9E9,9E9,9E9]], v1000, fine, gripper;
    ENDPROC
ENDMODULE

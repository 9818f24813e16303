//! iceoryx2 planner / controller / plant processes (`DESIGN.md` §6).

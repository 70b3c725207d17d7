//! `mech-agent`: the robot side of MECH.

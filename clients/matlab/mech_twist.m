function body = mech_twist(vx, vy, vz, wz)
%MECH_TWIST  The body of a Twist command: body-frame velocity (m/s; x
%   forward, y left, z up) and yaw rate WZ (rad/s, counter-clockwise).
%   Use it as the BODY of mech_envelope with kind 5 (Command).
  body = {uint8(4), {double(vx), double(vy), double(vz), double(wz)}};
end

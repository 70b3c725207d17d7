function mech_controller(robot, channel, seconds, host, port)
%MECH_CONTROLLER  A MECH controller in MATLAB or GNU Octave: drives ROBOT
%   around a circle (0.2 m/s, 0.4 rad/s) for SECONDS by sending a Twist
%   command on CHANNEL every 50 ms to the router at HOST:PORT, over plain
%   UDP, unsigned (the loopback demo, or a station with auth.mode = "off").
%
%     mech_controller('robot_1', 'ext/matlab', 10, '127.0.0.1', 7400)
%
%   Route the robot to the channel in the ground station first
%   (:route robot_1 ext/matlab). Octave needs the instrument-control
%   package (Debian: octave-instrument-control) for udpport.
  if nargin < 2, channel = 'ext/matlab'; end
  if nargin < 3, seconds = 10; end
  if nargin < 4, host = '127.0.0.1'; end
  if nargin < 5, port = 7400; end
  if exist('OCTAVE_VERSION', 'builtin')
    pkg load instrument-control
    u = udpport();
  else
    u = udpport('datagram');
  end
  seq = 0;
  finish = now_us() + seconds * 1e6;
  while now_us() < finish
    seq = seq + 1;
    msg = mech_envelope(5, seq, now_us(), 'matlab', robot, channel, ...
                        mech_twist(0.2, 0, 0, 0.4));
    write(u, msg, 'uint8', host, port);
    pause(0.05);  % 20 Hz keeps the robot's failsafe (0.5 s) quiet
  end
  seq = seq + 1;
  stop = {uint8(6), {}};  % Command kind 6: Stop
  write(u, mech_envelope(5, seq, now_us(), 'matlab', robot, channel, stop), ...
        'uint8', host, port);
  fprintf('mech_controller: sent %d commands to %s on %s\n', seq, robot, channel);
end

function t = now_us()
  % Microseconds since the Unix epoch, as a double (exact to well below 1 us).
  if exist('OCTAVE_VERSION', 'builtin')
    t = floor(time() * 1e6);
  else
    t = floor(posixtime(datetime('now', 'TimeZone', 'UTC')) * 1e6);
  end
end

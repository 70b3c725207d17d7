% TEST_MECH_PACK  The MATLAB/Octave encoder against the golden messages of
% docs/protocol.md and proto/tests/golden.rs. Run from this folder:
%   octave-cli --eval test_mech_pack
% Errors on the first mismatch; prints the count when every case holds.
% (The Rust test clients_matlab checks these hex strings against mech-proto.)

cases = {
  % name, bytes made here, golden hex
  'twist', mech_envelope(5, 7, 1000000, 'gcs', 'robot_1', 'joy/0', mech_twist(0.5, 0, 0, -0.25)), ...
  '990105 07 ce000f4240 a3676373 a7726f626f745f31 a56a6f792f30 9204 94 cb3fe0000000000000 cb0000000000000000 cb0000000000000000 cbbfd0000000000000 c0';
  'heartbeat', mech_envelope(3, 7, 1000000, 'robot_1', 'router', '', {uint64(1500)}), ...
  '990103 07 ce000f4240 a7726f626f745f31 a6726f75746572 a0 91 cd05dc c0';
  'route', mech_envelope(9, 7, 1000000, 'gcs', 'robot_1', '', {'robot_1', 'joy/0', uint32(3)}), ...
  '990109 07 ce000f4240 a3676373 a7726f626f745f31 a0 93 a7726f626f745f31 a56a6f792f30 03 c0';
  'stop', mech_envelope(5, 300, 2^32 + 5, 'matlab', 'robot_2', 'ext/matlab', {uint8(6), {}}), ...
  '990105 cd012c cf0000000100000005 a66d61746c6162 a7726f626f745f32 aa6578742f6d61746c6162 920690 c0';
};
for i = 1:size(cases, 1)
  name = cases{i, 1};
  got = lower(reshape(dec2hex(cases{i, 2}, 2)', 1, []));
  want = strrep(cases{i, 3}, ' ', '');
  if ~strcmp(got, want)
    error('test_mech_pack:%s: got %s, want %s', name, got, want);
  end
end
assert(isequal(mech_pack(int32(-1)), uint8(255)));
assert(isequal(mech_pack(int32(-200)), uint8([209 255 56])));
assert(isequal(mech_pack(true), uint8(195)));
fprintf('%d passed, 0 failed\n', size(cases, 1) + 3);

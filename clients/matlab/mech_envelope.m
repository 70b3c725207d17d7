function bytes = mech_envelope(kind, seq, stamp_us, sender, destination, channel, body)
%MECH_ENVELOPE  An unsigned MECH message (docs/protocol.md, *The envelope*).
%   BYTES = MECH_ENVELOPE(KIND, SEQ, STAMP_US, SENDER, DESTINATION, CHANNEL,
%   BODY) encodes the nine-element envelope with a nil authentication tag:
%   KIND is the body kind (5 = Command), SEQ the sender's message counter,
%   STAMP_US microseconds since the Unix epoch, BODY a cell of the body's
%   fields (see mech_twist for a Command).
  bytes = mech_pack({uint8(1), uint8(kind), uint32(mod(seq, 2^32)), ...
                     uint64(stamp_us), sender, destination, channel, body, []});
end

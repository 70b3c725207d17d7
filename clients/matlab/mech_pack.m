function bytes = mech_pack(value)
%MECH_PACK  MessagePack bytes of a value, as the MECH protocol writes them.
%   BYTES = MECH_PACK(VALUE) returns a uint8 row vector. Types map as
%   docs/protocol.md needs them:
%     []  (empty double)          -> nil
%     true, false                 -> bool
%     int8..int64, uint8..uint64  -> integer, in its smallest form
%     double, single              -> float64 (every real number of MECH)
%     char row                    -> str (UTF-8)
%     cell array                  -> array, element by element
%   So an envelope is a cell: {uint8(1), uint8(kind), uint32(seq),
%   uint64(stamp_us), sender, destination, channel, body, []}.
%   Works in MATLAB and GNU Octave.
  if iscell(value)
    bytes = array_header(numel(value));
    for i = 1:numel(value)
      bytes = [bytes, mech_pack(value{i})]; %#ok<AGROW>
    end
  elseif ischar(value)
    utf8 = uint8(unicode2native(value, 'UTF-8'));
    bytes = [str_header(numel(utf8)), utf8];
  elseif isempty(value)
    bytes = uint8(hex2dec('c0'));
  elseif ~isscalar(value)
    error('mech_pack:shape', 'put arrays of numbers in a cell: num2cell(x)');
  elseif islogical(value)
    bytes = uint8(hex2dec('c2') + double(value));
  elseif isinteger(value)
    bytes = pack_integer(value);
  elseif isfloat(value)
    if ~isfinite(value)
      error('mech_pack:finite', 'MECH real numbers must be finite');
    end
    bytes = [uint8(hex2dec('cb')), big_endian(double(value))];
  else
    error('mech_pack:type', 'cannot encode a %s', class(value));
  end
end

function bytes = pack_integer(v)
  if v >= 0
    u = uint64(v);
    if u < 128
      bytes = uint8(u);
    elseif u <= intmax('uint8')
      bytes = [uint8(hex2dec('cc')), uint8(u)];
    elseif u <= intmax('uint16')
      bytes = [uint8(hex2dec('cd')), big_endian(uint16(u))];
    elseif u <= intmax('uint32')
      bytes = [uint8(hex2dec('ce')), big_endian(uint32(u))];
    else
      bytes = [uint8(hex2dec('cf')), big_endian(u)];
    end
  else
    s = int64(v);
    if s >= -32
      bytes = typecast(int8(s), 'uint8');
    elseif s >= intmin('int8')
      bytes = [uint8(hex2dec('d0')), typecast(int8(s), 'uint8')];
    elseif s >= intmin('int16')
      bytes = [uint8(hex2dec('d1')), big_endian(int16(s))];
    elseif s >= intmin('int32')
      bytes = [uint8(hex2dec('d2')), big_endian(int32(s))];
    else
      bytes = [uint8(hex2dec('d3')), big_endian(s)];
    end
  end
end

function bytes = array_header(n)
  if n < 16
    bytes = uint8(hex2dec('90') + n);
  elseif n <= 65535
    bytes = [uint8(hex2dec('dc')), big_endian(uint16(n))];
  else
    bytes = [uint8(hex2dec('dd')), big_endian(uint32(n))];
  end
end

function bytes = str_header(n)
  if n < 32
    bytes = uint8(hex2dec('a0') + n);
  elseif n <= 255
    bytes = [uint8(hex2dec('d9')), uint8(n)];
  elseif n <= 65535
    bytes = [uint8(hex2dec('da')), big_endian(uint16(n))];
  else
    bytes = [uint8(hex2dec('db')), big_endian(uint32(n))];
  end
end

function bytes = big_endian(v)
  % typecast gives the machine's (little-endian) order; MessagePack is big-endian.
  bytes = fliplr(typecast(v, 'uint8'));
end

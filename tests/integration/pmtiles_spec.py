"""The parts of the PMTiles v3 specification the test scripts share (pmtiles_hostile.py,
pmtiles_uncompressed.py): the header layout, internal compressions, varints and directory
decoding. Written from the specification, independently of vtstream's reader and writer."""
import gzip
import struct
import sys

HEADER = struct.Struct("<7sB11QBBBBBBiiiiBii")
assert HEADER.size == 127
NONE, GZIP = 1, 2


def varints(data, pos, n):
    out = []
    for _ in range(n):
        value = shift = 0
        while True:
            b = data[pos]
            pos += 1
            value |= (b & 0x7F) << shift
            shift += 7
            if b < 0x80:
                break
        out.append(value)
    return out, pos


def varint(value):
    out = bytearray()
    while value >= 0x80:
        out.append((value & 0x7F) | 0x80)
        value >>= 7
    out.append(value)
    return bytes(out)


def inflate(data, compression):
    if compression == NONE:
        return data
    if compression == GZIP:
        return gzip.decompress(data)
    sys.exit(f"internal compression {compression} is neither none nor gzip")


def parse_directory(data):
    (n,), pos = varints(data, 0, 1)
    ids, pos = varints(data, pos, n)
    runs, pos = varints(data, pos, n)
    lengths, pos = varints(data, pos, n)
    offsets, pos = varints(data, pos, n)
    entries, tile_id = [], 0
    for i in range(n):
        tile_id += ids[i]
        if offsets[i] == 0 and i > 0:
            offset = entries[-1][3] + entries[-1][2]
        else:
            offset = offsets[i] - 1
        entries.append((tile_id, runs[i], lengths[i], offset))
    return entries

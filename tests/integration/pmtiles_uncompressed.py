#!/usr/bin/env python3
"""Rewrites a PMTiles v3 archive with uncompressed directories and metadata (internal compression
"none", 0x01), its tile entries spread over leaf directories of at most LEAF entries each.

Written from the PMTiles v3 specification, independently of vtstream's reader and writer, so a
test can hold vtstream against an archive laid out as another writer may lay it out: the tile
data section is copied byte for byte (same offsets), the directories are decoded (gzip or none)
and encoded again with explicit offsets.

usage: pmtiles_uncompressed.py IN.pmtiles OUT.pmtiles [LEAF]
"""
import gzip
import struct
import sys

from pmtiles_spec import GZIP, HEADER, NONE, inflate, parse_directory, varint, varints  # noqa: F401


def encode_directory(entries):
    out = [varint(len(entries))]
    last = 0
    for tile_id, _, _, _ in entries:
        out.append(varint(tile_id - last))
        last = tile_id
    out += [varint(e[1]) for e in entries]
    out += [varint(e[2]) for e in entries]
    out += [varint(e[3] + 1) for e in entries]  # explicit offsets throughout
    return b"".join(out)


def main():
    if len(sys.argv) not in (3, 4):
        sys.exit(__doc__)
    leaf_size = int(sys.argv[3]) if len(sys.argv) == 4 else 16
    blob = open(sys.argv[1], "rb").read()
    h = list(HEADER.unpack_from(blob))
    if h[0] != b"PMTiles" or h[1] != 3:
        sys.exit(f"{sys.argv[1]} is not a PMTiles v3 archive")
    root_off, root_len, meta_off, meta_len, leaf_off, _, data_off, data_len = h[2:10]
    compression = h[14]

    def tiles(offset, length):
        for e in parse_directory(inflate(blob[offset:offset + length], compression)):
            if e[1] == 0:  # a leaf directory
                yield from tiles(leaf_off + e[3], e[2])
            else:
                yield e

    entries = sorted(tiles(root_off, root_len))
    leaves, root_entries = b"", []
    for i in range(0, len(entries), leaf_size):
        leaf = encode_directory(entries[i:i + leaf_size])
        root_entries.append((entries[i][0], 0, len(leaf), len(leaves)))
        leaves += leaf
    root = encode_directory(root_entries)
    metadata = inflate(blob[meta_off:meta_off + meta_len], compression)

    h[2], h[3] = 127, len(root)
    h[4], h[5] = 127 + len(root), len(metadata)
    h[6], h[7] = h[4] + len(metadata), len(leaves)
    h[8], h[9] = h[6] + len(leaves), data_len
    h[14] = NONE
    with open(sys.argv[2], "wb") as out:
        out.write(HEADER.pack(*h) + root + metadata + leaves + blob[data_off:data_off + data_len])
    print(f"{len(entries)} tile entries in {len(root_entries)} uncompressed leaf directories")


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Rewrites a PMTiles v3 archive into a hostile one: same header fields, metadata and tile data,
new directories (or a new header byte). Written from the PMTiles v3 specification, independently
of vtstream's reader and writer (like pmtiles_uncompressed.py).

usage: pmtiles_hostile.py KIND IN.pmtiles OUT.pmtiles [N [ENTRIES]]

KIND:
  runs N          a root of N entries, entry i addressing tile ids [i * 2^32, i * 2^32 + 2^32 - 1)
                  (run length 2^32 - 1, the most a run can be), all with IN's first payload.
  root-bomb N     a root of N one-tile entries (ids 0..N-1) with IN's first payload, gzip: a
                  few KiB that decode to N directory entries.
  leaf-bombs N E  a root of N leaf pointers; leaf k (gzip, stored once each) holds E one-tile
                  entries from the k-th tile id of IN onwards, all with IN's first payload. Prints
                  the z/x/y of each leaf's first tile, one a line, so a test can touch every leaf.
  tile-compression N   header field tile_compression (byte 98) set to N; nothing else changes.
"""
import gzip
import struct
import sys

from pmtiles_spec import GZIP, HEADER, NONE, inflate, parse_directory, varint, varints  # noqa: F401


def uniform_directory(first_id, count, run, length, offset, step=1):
    """count entries: ids first_id, first_id + step, ...; each (run, length, offset). Built from
    repeated bytes, so a million entries cost milliseconds."""
    return (varint(count) + varint(first_id) + varint(step) * (count - 1) + varint(run) * count +
            varint(length) * count + varint(offset + 1) * count)


def tile_id_to_zxy(tile_id):
    """The spec's Hilbert tile id to (z, x, y)."""
    acc, z = 0, 0
    while acc + (1 << (2 * z)) <= tile_id:
        acc += 1 << (2 * z)
        z += 1
    t, x, y, s = tile_id - acc, 0, 0, 1
    while s < (1 << z):
        rx = 1 & (t // 2)
        ry = 1 & (t ^ rx)
        if ry == 0:
            if rx == 1:
                x, y = s - 1 - x, s - 1 - y
            x, y = y, x
        x, y = x + s * rx, y + s * ry
        t //= 4
        s *= 2
    return z, x, y


def main():
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    kind, src, dst = sys.argv[1:4]
    args = [int(a) for a in sys.argv[4:]]
    blob = open(src, "rb").read()
    h = list(HEADER.unpack_from(blob))
    if h[0] != b"PMTiles" or h[1] != 3:
        sys.exit(f"{src} is not a PMTiles v3 archive")
    root_off, root_len, meta_off, meta_len, leaf_off, _, data_off, data_len = h[2:10]
    compression = h[14]

    if kind == "tile-compression":
        h[15] = args[0]
        with open(dst, "wb") as out:
            out.write(HEADER.pack(*h) + blob[127:])
        return

    def tiles(offset, length):
        for e in parse_directory(inflate(blob[offset:offset + length], compression)):
            if e[1] == 0:  # a leaf directory
                yield from tiles(leaf_off + e[3], e[2])
            else:
                yield e

    entries = sorted(tiles(root_off, root_len))
    _, _, length, offset = entries[0]
    leaves = b""
    if kind == "runs":
        root = uniform_directory(0, args[0], 2**32 - 1, length, offset, step=2**32)
    elif kind == "root-bomb":
        root = uniform_directory(0, args[0], 1, length, offset)
    elif kind == "leaf-bombs":
        count, per_leaf = args
        ids = [i for e in entries for i in range(e[0], e[0] + e[1])][:count]
        if len(ids) < count:
            sys.exit(f"{src} has only {len(ids)} tiles")
        pointers = []
        for tile_id in ids:
            leaf = gzip.compress(uniform_directory(tile_id, per_leaf, 1, length, offset), 6)
            pointers.append((tile_id, len(leaf), len(leaves)))
            leaves += leaf
            print("%d/%d/%d" % tile_id_to_zxy(tile_id))
        root = varint(len(pointers)) + varint(pointers[0][0])
        root += b"".join(varint(b[0] - a[0]) for a, b in zip(pointers, pointers[1:]))
        root += varint(0) * len(pointers)  # run length 0: leaf pointers
        root += b"".join(varint(p[1]) for p in pointers)
        root += b"".join(varint(p[2] + 1) for p in pointers)
    else:
        sys.exit(f"unknown KIND {kind}\n{__doc__}")
    root = gzip.compress(root, 9)
    metadata = gzip.compress(inflate(blob[meta_off:meta_off + meta_len], compression), 9)

    h[2], h[3] = 127, len(root)
    h[4], h[5] = 127 + len(root), len(metadata)
    h[6], h[7] = h[4] + len(metadata), len(leaves)
    h[8], h[9] = h[6] + len(leaves), data_len
    h[14] = GZIP
    with open(dst, "wb") as out:
        out.write(HEADER.pack(*h) + root + metadata + leaves + blob[data_off:data_off + data_len])


if __name__ == "__main__":
    main()

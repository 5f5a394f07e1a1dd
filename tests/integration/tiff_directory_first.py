#!/usr/bin/env python3
"""tiff_directory_first.py IN.ppm OUT.tif strip|tiled [deflate]

Writes the RGB8 image IN.ppm (binary P6, maxval 255) as a baseline TIFF whose directory comes
before the pixel data, the layout GDAL and many cameras write (OpenImageIO's oiiotool puts the
directory at the end, where any cut removes it and the file fails to open at all). A cut anywhere
past the first kilobytes of OUT.tif therefore cuts pixel data: strips of 16 rows or 64x64 tiles,
uncompressed or deflate-compressed. Standard library only.
"""
import struct
import sys
import zlib


def read_ppm(path):
    data = open(path, "rb").read()
    fields, pos = [], 0
    while len(fields) < 4:  # P6, width, height, maxval, each ended by one whitespace byte
        while data[pos:pos + 1].isspace():
            pos += 1
        end = pos
        while not data[end:end + 1].isspace():
            end += 1
        fields.append(data[pos:end])
        pos = end
    w, h = int(fields[1]), int(fields[2])
    pix = data[pos + 1:]
    if fields[0] != b"P6" or int(fields[3]) != 255 or len(pix) != w * h * 3:
        sys.exit("%s: not an 8-bit binary PPM" % path)
    return w, h, pix


def chunks_of(w, h, pix, layout):
    if layout == "strip":
        return [pix[y * w * 3:min(h, y + 16) * w * 3] for y in range(0, h, 16)]
    tiles = []
    for ty in range(0, h, 64):
        for tx in range(0, w, 64):
            t = bytearray(64 * 64 * 3)
            for r in range(min(64, h - ty)):
                n = min(64, w - tx) * 3
                o = ((ty + r) * w + tx) * 3
                t[r * 64 * 3:r * 64 * 3 + n] = pix[o:o + n]
            tiles.append(bytes(t))
    return tiles


def main():
    src, dst, layout = sys.argv[1:4]
    deflate = sys.argv[4:5] == ["deflate"]
    w, h, pix = read_ppm(src)
    chunks = chunks_of(w, h, pix, layout)
    if deflate:
        chunks = [zlib.compress(c) for c in chunks]
    n = len(chunks)
    # (tag, type: 3 SHORT / 4 LONG, count, value or None for an out-of-line array)
    tags = [(256, 4, 1, w), (257, 4, 1, h), (258, 3, 3, None), (259, 3, 1, 8 if deflate else 1),
            (262, 3, 1, 2), (277, 3, 1, 3), (284, 3, 1, 1)]
    if layout == "strip":
        tags += [(273, 4, n, None), (278, 4, 1, 16), (279, 4, n, None)]
    else:
        tags += [(322, 4, 1, 64), (323, 4, 1, 64), (324, 4, n, None), (325, 4, n, None)]
    tags.sort()
    bps_at = 8 + 2 + 12 * len(tags) + 4  # out-of-line values follow the directory
    offsets_at = bps_at + 6
    counts_at = offsets_at + 4 * n
    offsets, at = [], counts_at + 4 * n
    for c in chunks:
        offsets.append(at)
        at += len(c)
    out = bytearray(b"II*\0" + struct.pack("<IH", 8, len(tags)))
    for tag, typ, count, val in tags:
        if tag == 258:
            val = bps_at
        elif tag in (273, 324):
            val = offsets_at
        elif tag in (279, 325):
            val = counts_at
        packed = struct.pack("<HH", val, 0) if typ == 3 and count == 1 else struct.pack("<I", val)
        out += struct.pack("<HHI", tag, typ, count) + packed
    out += struct.pack("<I", 0) + struct.pack("<3H", 8, 8, 8)
    out += struct.pack("<%dI" % n, *offsets) + struct.pack("<%dI" % n, *map(len, chunks))
    for c in chunks:
        out += c
    open(dst, "wb").write(out)


if __name__ == "__main__":
    main()

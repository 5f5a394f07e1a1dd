#!/usr/bin/env python3
"""footprint_count.py MAXZ T W,S,E,N [WebMercatorQuad]: the tile count of a sparse archive of the
footprint W,S,E,N (degrees) on WorldCRS84Quad (default) or WebMercatorQuad with finest level MAXZ
and tile size T, computed independently of the C++ code from docs/FORMAT.md section 6."""
import math, sys
maxz, T = int(sys.argv[1]), int(sys.argv[2])
w, s, e, n = map(float, sys.argv[3].split(","))
mercator = len(sys.argv) > 4 and sys.argv[4] == "WebMercatorQuad"
N = T * 2 ** maxz
W, H = N, (N if mercator else N // 2)
def snap(v, f):
    r = round(v)
    return r if abs(v - r) <= 1e-6 else f(v)
def ty(lat):
    if not mercator:
        return (90 - lat) / 360 * N
    return (1 - math.log(math.tan(math.pi / 4 + math.radians(lat) / 2)) / math.pi) / 2 * N
x0, y0 = snap((w + 180) / 360 * N, math.floor), snap(ty(n), math.floor)
x1, y1 = min(snap((e + 180) / 360 * N, math.ceil), W), min(snap(ty(s), math.ceil), H)
count = 0
for z in range(maxz + 1):
    d = maxz - z
    lx0, ly0, lx1, ly1 = x0 >> d, y0 >> d, -(-x1 // 2 ** d), -(-y1 // 2 ** d)
    count += (-(-lx1 // T) - lx0 // T) * (-(-ly1 // T) - ly0 // T)
print(count)

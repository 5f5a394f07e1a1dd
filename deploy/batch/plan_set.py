"""A plan's output as the batch engines see it: how many shards, and for a plan of a set of
archives (`vts plan --archive-level K`) how many archives and the largest one's estimate.

The plan file does not hold the archive count: vts computes it (builder/src/set_merge.cpp,
set_archive_roots: the top, then each level-K tile that the image covers and some shard
reaches), and `vts plan --json` prints it as "archives". The batch engines need it before any
vts runs (a Slurm array's size, a Kubernetes Job's completions), on a machine where vts need not
be, so this is vts's rule again, in Python; tests/integration/k8s_render.sh checks that the two
agree (plain, sparse and georeferenced plans). Likewise archive_max is vts's
estimate_set_archive_max (builder/src/shard_size.cpp).

Used by deploy/batch/lib.sh (submit.sh, run-shards.sh) and deploy/batch/k8s/render.sh. As a
program:

    python3 plan_set.py PROG PLAN   prints "SHARDS ARCHIVE_LEVEL ARCHIVES" (0 0 for one archive);
                                    exits 2 with "PROG: ..." naming the plan when it is not one
"""
import json
import math
import sys


class PlanError(Exception):
    pass


def load(path):
    """The plan at path as a dict, with the fields read here checked; PlanError otherwise."""
    try:
        with open(path, encoding="utf-8") as f:
            plan = json.load(f)
    except OSError as e:
        raise PlanError(f"cannot read the plan {path}: {e.strerror}")
    except ValueError as e:
        raise PlanError(f"{path} is not JSON: {e}")
    if not isinstance(plan, dict) or not isinstance(plan.get("shards"), list):
        raise PlanError(f'{path} is not a vts plan (no "shards" array)')
    if not plan["shards"]:
        raise PlanError(f"{path}: the plan has no shards (nothing to build)")
    level = plan.get("archive_level", 0)
    if not isinstance(level, int) or isinstance(level, bool) or level < 0:
        raise PlanError(f"{path}: archive_level {level!r} is not a level")
    return plan


def _ceil_shift(v, s):
    return -(-v >> s)


def _level_size(plan, z):
    """Level z's texels across and down."""
    g = plan["geometry"]
    s = g["max_zoom"] - z
    return _ceil_shift(g["width"], s), _ceil_shift(g["height"], s)


def _map_rect(plan, rect, z):
    """Geometry::map_rect from the finest level to level z (z <= max zoom)."""
    s = plan["geometry"]["max_zoom"] - z
    w, h = _level_size(plan, z)
    x1, y1 = min(_ceil_shift(rect[2], s), w), min(_ceil_shift(rect[3], s), h)
    return min(rect[0] >> s, x1), min(rect[1] >> s, y1), x1, y1


def _snap(v):
    r = float(round(v))
    return r if abs(v - r) < 1e-6 else v


def _clamp_to(v, top):
    if not v > 0:
        return 0
    return top if v >= top else int(v)


def _footprint_texels(plan, bounds, tiling):
    """protocol/src/tiling.cpp, footprint_texels: the bounds' texels at the finest level."""
    g = plan["geometry"]
    n = math.ldexp(float(plan["options"]["tile_size"]), g["max_zoom"])

    def texel(lon, lat):
        x = (lon + 180.0) / 360.0 * n
        if tiling == "WorldCRS84Quad":
            return x, (90.0 - lat) / 360.0 * n
        merc = math.asinh(math.tan(lat * (math.pi / 180.0)))
        return x, (1.0 - merc / math.pi) / 2.0 * n

    west, south, east, north = bounds
    nw, se = texel(west, north), texel(east, south)
    W, H = g["width"], g["height"]
    x0, y0 = _clamp_to(math.floor(_snap(nw[0])), W), _clamp_to(math.floor(_snap(nw[1])), H)
    x1, y1 = _clamp_to(math.ceil(_snap(se[0])), W), _clamp_to(math.ceil(_snap(se[1])), H)
    if x1 <= x0:
        x0 = min(x0, W - 1)
        x1 = x0 + 1
    if y1 <= y0:
        y0 = min(y0, H - 1)
        y1 = y0 + 1
    return x0, y0, x1, y1


def emit_rect(plan, z):
    """The level-z tiles the build writes, [x0, x1) x [y0, y1): builder.cpp, build_emit_rects."""
    T = plan["options"]["tile_size"]
    w, h = _level_size(plan, z)
    full = (0, 0, -(-w // T), -(-h // T))
    syn = plan["options"].get("synthetic")
    geo = plan.get("georeference")
    if isinstance(syn, dict) and syn.get("region"):
        if z < syn.get("region_level", 0):
            return full
        r = _map_rect(plan, syn["region"], z)
    elif isinstance(geo, dict) and geo.get("bounds"):  # a georeferenced build: its footprint
        r = _map_rect(plan, _footprint_texels(plan, geo["bounds"], geo.get("tiling")), z)
    else:
        return full
    x0, y0 = r[0] // T, r[1] // T
    return x0, y0, max(x0, -(-r[2] // T)), max(y0, -(-r[3] // T))


def archive_count(plan):
    """The archives of the plan's set, the top included; 0 for a plan of one archive."""
    k, L = plan.get("archive_level", 0), plan["split_level"]
    if k < 1 or k > plan["geometry"]["max_zoom"]:
        return 0
    x0, y0, x1, y1 = emit_rect(plan, k)
    roots = set()
    for sx, sy in plan["shards"]:
        if L >= k:  # one archive holds the whole shard
            roots.add((sx >> (L - k), sy >> (L - k)))
            continue
        d = k - L  # the shard spans several archives: its level-k tiles the image covers
        for y in range(max(sy << d, y0), min((sy + 1) << d, y1)):
            for x in range(max(sx << d, x0), min((sx + 1) << d, x1)):
                roots.add((x, y))
    return 1 + sum(1 for x, y in roots if x0 <= x < x1 and y0 <= y < y1)


# Bytes per stored tile of S x S texels: builder/src/shard_size.cpp (and render.sh's copy).
LOSSLESS_FILTERED, LOSSLESS_UNFILTERED, MEASURED_S = 34_478, 66_475, 264


def tile_bytes(plan):
    o = plan["options"]
    S = o["tile_size"] + 2 * o["border"]
    if o.get("codec") == "bc1":
        return S * S // 2
    per_tile = LOSSLESS_UNFILTERED if o.get("filter") == "none" else LOSSLESS_FILTERED
    return math.ceil(per_tile * S * S / MEASURED_S**2)


def archive_max(plan, k=None):
    """The largest archive of the set cut at level k (the plan's by default), estimated:
    estimate_set_archive_max (dense: the top's levels, or the sub-pyramid of level-k tile 0,0)."""
    k = plan.get("archive_level", 0) if k is None else k
    maxz, T = plan["geometry"]["max_zoom"], plan["options"]["tile_size"]
    if k < 1 or k > maxz:
        return 0
    tiles = lambda z: tuple(-(-d // T) for d in _level_size(plan, z))
    top = sum(w * h for w, h in (tiles(z) for z in range(k)))
    first = sum(min(2 ** (z - k), w) * min(2 ** (z - k), h)
                for w, h, z in ((*tiles(z), z) for z in range(k, maxz + 1)))
    return max(top, first) * tile_bytes(plan)


def main(argv):
    if len(argv) != 3:
        sys.exit("usage: plan_set.py PROG PLAN")
    prog, path = argv[1], argv[2]
    try:
        plan = load(path)
        print(len(plan["shards"]), plan.get("archive_level", 0), archive_count(plan))
    except PlanError as e:
        print(f"{prog}: {e}", file=sys.stderr)
        sys.exit(2)
    except (KeyError, TypeError, ValueError) as e:
        print(f"{prog}: {path}: a plan this script cannot read ({e!r})", file=sys.stderr)
        sys.exit(2)


if __name__ == "__main__":
    main(sys.argv)

"""Texel-exact comparisons for export_gis.sh, through GDAL's own readers.

  level TIFF X0 Y0 REF0 [REF1 ...]   the TIFF's full resolution equals REF0 (a whole level
      extracted by `vts extract --level`) from texel (X0, Y0); its overview k equals REFk from
      (X0 >> k, Y0 >> k). Fails when an overview is missing or extra.
  mbtiles FILE XYZDIR MAXZ           each zoom GDAL reads from the MBTiles (full resolution =
      MAXZ, overview k = MAXZ - 1 - k) equals the xyz folder's PNG tiles of that zoom, mosaicked.
  xyzregion IMAGE XYZDIR Z X0 Y0     IMAGE equals the mosaic of zoom Z from texel (X0, Y0).
Texels whose alpha is 0 are compared by alpha only (their colour is no texel's).
Prints what it compared; exits 1 on the first difference, naming where.
"""
import os
import sys

import numpy as np
from osgeo import gdal

gdal.UseExceptions()


def rgba(ds_or_band_list):
    a = np.stack([b.ReadAsArray() for b in ds_or_band_list])
    if a.shape[0] == 3:
        a = np.concatenate([a, np.full((1,) + a.shape[1:], 255, a.dtype)])
    return a


def bands(ds):
    return [ds.GetRasterBand(i + 1) for i in range(ds.RasterCount)]


def read(path):
    """All bands of a file as RGBA (the dataset must outlive its bands: read here, at once)."""
    ds = gdal.Open(path)
    return rgba(bands(ds))


def same(got, want, what):
    if got.shape != want.shape:
        sys.exit(f"{what}: shape {got.shape}, expected {want.shape}")
    alpha_ok = got[3] == want[3]
    colour_ok = (got[:3] == want[:3]).all(axis=0) | (want[3] == 0)
    bad = ~(alpha_ok & colour_ok)
    if bad.any():
        y, x = np.argwhere(bad)[0]
        sys.exit(f"{what}: {int(bad.sum())} texels differ, first at ({x}, {y}): "
                 f"{got[:, y, x].tolist()} vs {want[:, y, x].tolist()}")
    print(f"{what}: {got.shape[2]}x{got.shape[1]} equal")


def level(tif, x0, y0, refs):
    ds = gdal.Open(tif)
    first = ds.GetRasterBand(1)
    if first.GetOverviewCount() != len(refs) - 1:
        sys.exit(f"{tif}: {first.GetOverviewCount()} overviews, expected {len(refs) - 1}")
    for k, ref in enumerate(refs):
        src = bands(ds) if k == 0 else [b.GetOverview(k - 1) for b in bands(ds)]
        got = rgba(src)
        h, w = got.shape[1:]
        want = read(ref)[:, (y0 >> k):(y0 >> k) + h, (x0 >> k):(x0 >> k) + w]
        same(got, want, f"{os.path.basename(tif)} level -{k} vs {os.path.basename(ref)}")


def mosaic(xyz, z):
    n = 1 << z
    tiles = {}
    size = None
    for x in range(n):
        for y in range(n):
            p = os.path.join(xyz, str(z), str(x), f"{y}.png")
            if os.path.exists(p):
                tiles[(x, y)] = read(p)
                size = tiles[(x, y)].shape[1]
    out = np.zeros((4, n * size, n * size), np.uint8)
    for (x, y), t in tiles.items():
        out[:, y * size:(y + 1) * size, x * size:(x + 1) * size] = t
    return out


def mbtiles(path, xyz, maxz):
    ds = gdal.Open(path)
    for z in range(maxz, -1, -1):
        k = maxz - 1 - z
        src = bands(ds) if z == maxz else [b.GetOverview(k) for b in bands(ds)]
        same(rgba(src), mosaic(xyz, z), f"MBTiles zoom {z}")


def xyzregion(image, xyz, z, x0, y0):
    got = read(image)
    h, w = got.shape[1:]
    same(got, mosaic(xyz, z)[:, y0:y0 + h, x0:x0 + w], f"{os.path.basename(image)} vs zoom {z}")


def main(argv):
    mode = argv[1]
    if mode == "level":
        level(argv[2], int(argv[3]), int(argv[4]), argv[5:])
    elif mode == "mbtiles":
        mbtiles(argv[2], argv[3], int(argv[4]))
    elif mode == "xyzregion":
        xyzregion(argv[2], argv[3], int(argv[4]), int(argv[5]), int(argv[6]))
    else:
        sys.exit(f"unknown mode {mode}")


if __name__ == "__main__":
    main(sys.argv)

"""gis_compare.py OUT REF X Y (--exact | --min-psnr DB): the raster a GIS client wrote (OUT, read
with GDAL's bindings: RGB or RGBA) against the window of REF (`vts extract --level` as PNG, RGBA)
at texel (X, Y) of OUT's size. --exact: every channel OUT has equals REF's. --min-psnr: the PSNR of
the colour channels is at least DB (a lossy codec), and where OUT has alpha it equals REF's.
Exit 1 with what differs."""
import sys

import numpy as np
from osgeo import gdal

out_path, ref_path, x, y, mode = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), sys.argv[5]
out = gdal.Open(out_path).ReadAsArray().astype(np.int32)
ref = gdal.Open(ref_path).ReadAsArray().astype(np.int32)
bands, h, w = out.shape
if y + h > ref.shape[1] or x + w > ref.shape[2]:
    sys.exit(f"{out_path} is {w}x{h}: the window at {x},{y} leaves {ref_path} ({ref.shape[2]}x{ref.shape[1]})")
win = ref[:bands, y:y + h, x:x + w]
if mode == "--exact":
    diff = np.abs(out - win)
    if diff.max() != 0:
        where = np.argwhere(diff.max(axis=0) > 0)[0]
        sys.exit(f"{out_path} differs from {ref_path} at {x},{y}: max {diff.max()}, first at row,col {tuple(where)}")
else:
    floor = float(sys.argv[6])
    mse = np.mean((out[:3] - win[:3]) ** 2)
    psnr = float("inf") if mse == 0 else 10 * np.log10(255.0 ** 2 / mse)
    if psnr < floor:
        sys.exit(f"{out_path} PSNR {psnr:.2f} dB < {floor} against {ref_path} at {x},{y}")
    if bands == 4 and np.any(out[3] != win[3]):
        sys.exit(f"{out_path}: alpha differs from {ref_path}")
    print(f"PSNR {psnr:.2f} dB")

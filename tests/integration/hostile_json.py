#!/usr/bin/env python3
"""Hostile JSON for vtstream's readers: documents nested far deeper than any we write (200 KB of
brackets for 100,000 levels, far inside every size limit), and load-test reports whose counts sum
past 2^64 or whose arrays run to millions of rows. Used by hostile_json.sh and to make the fuzz
corpora's samples (tests/fuzz/corpus/).

  archive IN.pmtiles OUT.pmtiles WHERE [LEVELS]
      IN with its metadata's "vtstream" object (WHERE=vtstream) or its "vtstream.georeference"
      object (WHERE=georeference) given an unknown key "future_key" holding LEVELS (100000) nested
      arrays. Written from the PMTiles v3 specification, independently of vtstream's writer: the
      header's offsets are rewritten, directories and tile data copied byte for byte, the metadata
      compressed as the header says (gzip or none).
  metadata IN.pmtiles OUT.json WHERE [LEVELS]
      The same metadata, as JSON text.
  tilejson IN.json OUT.json WHERE [LEVELS]
      A TileJSON document (IN) with "future_key" holding LEVELS nested arrays in its "vtstream"
      object (WHERE=vtstream), its "vtstream.georeference" object (georeference), or TileJSON's
      own top level (top).
  report-rows IN.json OUT.json ROWS
      A `vts loadtest --json` report (IN) whose "seconds" array holds ROWS rows (zeros: small to
      write, as many entries as a parser must hold).
  report-overflow IN.json OUT.json FIELD
      The report with counts that wrap 64 bits: FIELD=requests sets totals.requests to 2^63 (two
      such reports merged sum past 2^64); FIELD=buckets sets the first two buckets of the first
      histogram that has two (latency_ns.total, ...; its name is printed) to 2^63 each, and its
      count to what the wrapped sum of its buckets gives.
"""
import gzip
import json
import struct
import sys

HEADER = struct.Struct("<7sB11QBBBBBBiiiiBii")
assert HEADER.size == 127
NONE, GZIP = 1, 2
PLACEHOLDER = "__vts_hostile_json__"


def nested(levels):
    return "[" * levels + "]" * levels


def with_deep_value(text, where, levels):
    """`text` (a JSON object) with "future_key": <levels nested arrays> in the object `where`."""
    doc = json.loads(text)
    if where == "top":
        target = doc
    else:
        target = doc.get("vtstream")
        if not isinstance(target, dict):
            sys.exit("the document has no \"vtstream\" object")
        if where == "georeference":
            target = target.get("georeference")
            if not isinstance(target, dict):
                sys.exit("the document has no \"vtstream.georeference\" object (build a "
                         "georeferenced archive)")
        elif where != "vtstream":
            sys.exit(f"WHERE is vtstream, georeference or top, not {where}")
    # First, so that a reader meets it before the keys it knows.
    items = [("future_key", PLACEHOLDER)] + list(target.items())
    target.clear()
    target.update(items)
    out = json.dumps(doc, separators=(",", ":"))
    return out.replace(json.dumps(PLACEHOLDER), nested(levels), 1)


def read_archive(path):
    blob = open(path, "rb").read()
    h = list(HEADER.unpack_from(blob))
    if h[0] != b"PMTiles" or h[1] != 3:
        sys.exit(f"{path} is not a PMTiles v3 archive")
    return blob, h


def metadata_of(blob, h):
    data = blob[h[4]:h[4] + h[5]]
    if h[14] == GZIP:
        return gzip.decompress(data)
    if h[14] == NONE:
        return data
    sys.exit(f"internal compression {h[14]} is neither none nor gzip")


def rewrite_archive(blob, h, metadata):
    """The archive with `metadata` (bytes, uncompressed) in place of its own."""
    if h[14] == GZIP:
        metadata = gzip.compress(metadata, mtime=0)
    # Sections (offset index, length index), laid out again in their order in the file.
    sections = sorted([(2, 3), (4, 5), (6, 7), (8, 9)], key=lambda s: h[s[0]])
    body, at = b"", 127
    new = list(h)
    for off, length in sections:
        data = metadata if off == 4 else blob[h[off]:h[off] + h[length]]
        new[off], new[length] = at, len(data)
        body += data
        at += len(data)
    return HEADER.pack(*new) + body


def levels_arg(i):
    return int(sys.argv[i]) if len(sys.argv) > i else 100000


def main():
    if len(sys.argv) < 5:
        sys.exit(__doc__)
    cmd, src, dst = sys.argv[1:4]
    if cmd in ("archive", "metadata"):
        blob, h = read_archive(src)
        meta = with_deep_value(metadata_of(blob, h).decode("utf-8"), sys.argv[4], levels_arg(5))
        with open(dst, "wb") as out:
            out.write(rewrite_archive(blob, h, meta.encode()) if cmd == "archive" else meta.encode())
    elif cmd == "tilejson":
        doc = with_deep_value(open(src, encoding="utf-8").read(), sys.argv[4], levels_arg(5))
        open(dst, "w", encoding="utf-8").write(doc)
    elif cmd == "report-rows":
        report = json.load(open(src, encoding="utf-8"))
        report["seconds"] = [0] * int(sys.argv[4])
        json.dump(report, open(dst, "w", encoding="utf-8"), separators=(",", ":"))
    elif cmd == "report-overflow":
        report = json.load(open(src, encoding="utf-8"))
        if sys.argv[4] == "requests":
            report["totals"]["requests"] = 2**63
        elif sys.argv[4] == "buckets":
            # The first histogram with two buckets; its key is printed.
            hists = report["latency_ns"]
            key = next((k for k in ("total", "ttfb", "queue_time", "first_visible",
                                    "full_resolution") if len(hists[k]["buckets"]) >= 2), None)
            if key is None:
                sys.exit("no histogram of the report has two buckets")
            buckets = hists[key]["buckets"]
            buckets[0]["count"] = buckets[1]["count"] = 2**63
            hists[key]["count"] = sum(b["count"] for b in buckets) % 2**64
            print(f"latency_ns.{key}")
        else:
            sys.exit(f"FIELD is requests or buckets, not {sys.argv[4]}")
        json.dump(report, open(dst, "w", encoding="utf-8"))
    else:
        sys.exit(__doc__)


if __name__ == "__main__":
    main()

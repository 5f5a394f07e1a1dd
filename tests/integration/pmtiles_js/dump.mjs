// Reads a PMTiles archive from a local file through the npm `pmtiles` library (a real, independent
// PMTiles v3 reader) and prints the same lines as tests/integration/pmtiles_dump.cpp, so the
// integration tests can compare our reader and writer against it byte for byte.
//
//   node dump.mjs tiles  ARCHIVE   "tile_id z x y length fnv1a64-hex" per addressed tile id
//   node dump.mjs header ARCHIVE   "key=value" header fields, then "metadata_keys=..."
//
// Tiles are found twice, independently: by walking the directories with the library's own parser
// (root and leaves, run lengths expanded) and, when the pyramid is small enough, by asking getZxy()
// for every slot of every level. Both must agree; each tile's bytes come from getZxy().
// Exit status: 0 on success, 1 on any error or disagreement (message on stderr), 2 on bad usage.
import { gunzipSync } from "node:zlib";
import { Compression, PMTiles, SharedPromiseCache, tileIdToZxy } from "pmtiles";
import { NodeFileSource, probeAllSlots, runMain, walkDirectories } from "./archive.mjs";

const toArrayBuffer = (b) => b.buffer.slice(b.byteOffset, b.byteOffset + b.byteLength);

// Tile payloads are zstd streams that we want to hash raw, so Zstd passes through unchanged;
// directories and metadata are gzip.
async function decompress(buf, compression) {
  switch (compression) {
    case Compression.None:
    case Compression.Zstd:
      return buf;
    case Compression.Gzip:
      return toArrayBuffer(gunzipSync(Buffer.from(buf)));
    default:
      throw new Error(`unsupported compression ${compression}`);
  }
}

// FNV-1a 64 over 32-bit halves (exact; no BigInt in the hot loop). Prime = 2^40 + 0x1b3.
function fnv1a64(bytes) {
  let hi = 0xcbf29ce4;
  let lo = 0x84222325;
  for (let i = 0; i < bytes.length; i++) {
    lo = (lo ^ bytes[i]) >>> 0;
    const t = lo * 0x1b3; // < 2^41, exact in a double
    const carry = Math.floor(t / 4294967296);
    hi = (Math.imul(hi, 0x1b3) + carry + (lo << 8)) >>> 0; // (lo << 40) lands in hi as lo << 8
    lo = t >>> 0;
  }
  return hi.toString(16).padStart(8, "0") + lo.toString(16).padStart(8, "0");
}

const kMaxProbedSlots = 1 << 20;

async function dumpTiles(pm) {
  const header = await pm.getHeader();
  const ids = await walkDirectories(pm, header);
  const probed = await probeAllSlots(pm, header, kMaxProbedSlots);
  if (probed !== null) {
    const a = new Set(ids);
    const b = new Set(probed);
    const onlyDir = ids.filter((id) => !b.has(id));
    const onlyProbe = probed.filter((id) => !a.has(id));
    if (onlyDir.length || onlyProbe.length) {
      throw new Error(
        `directory walk and getZxy() disagree: in directories only ${onlyDir.slice(0, 5)}, ` +
          `found by getZxy() only ${onlyProbe.slice(0, 5)}`,
      );
    }
  }
  const lines = [];
  for (const id of ids) {
    const [z, x, y] = tileIdToZxy(id);
    const resp = await pm.getZxy(z, x, y);
    if (resp === undefined) throw new Error(`getZxy(${z}, ${x}, ${y}) found no tile`);
    const bytes = new Uint8Array(resp.data);
    lines.push(`${id} ${z} ${x} ${y} ${bytes.length} ${fnv1a64(bytes)}`);
  }
  return lines;
}

async function dumpHeader(pm) {
  const h = await pm.getHeader();
  const e7 = (deg) => Math.round(deg * 1e7);
  const meta = await pm.getMetadata();
  const keys =
    meta !== null && typeof meta === "object" && !Array.isArray(meta)
      ? Object.keys(meta).sort().join(",")
      : "<not a JSON object>";
  return [
    `spec_version=${h.specVersion}`,
    `min_zoom=${h.minZoom}`,
    `max_zoom=${h.maxZoom}`,
    `tile_compression=${h.tileCompression}`,
    `internal_compression=${h.internalCompression}`,
    `tile_type=${h.tileType}`,
    `clustered=${h.clustered}`,
    `addressed_tiles=${h.numAddressedTiles}`,
    `tile_entries=${h.numTileEntries}`,
    `tile_contents=${h.numTileContents}`,
    `root_dir_offset=${h.rootDirectoryOffset}`,
    `root_dir_length=${h.rootDirectoryLength}`,
    `metadata_offset=${h.jsonMetadataOffset}`,
    `metadata_length=${h.jsonMetadataLength}`,
    `leaf_dirs_offset=${h.leafDirectoryOffset}`,
    `leaf_dirs_length=${h.leafDirectoryLength}`,
    `tile_data_offset=${h.tileDataOffset}`,
    `tile_data_length=${h.tileDataLength}`,
    `min_lon_e7=${e7(h.minLon)}`,
    `min_lat_e7=${e7(h.minLat)}`,
    `max_lon_e7=${e7(h.maxLon)}`,
    `max_lat_e7=${e7(h.maxLat)}`,
    `center_zoom=${h.centerZoom}`,
    `center_lon_e7=${e7(h.centerLon)}`,
    `center_lat_e7=${e7(h.centerLat)}`,
    `metadata_keys=${keys}`,
  ];
}

async function main(argv) {
  const [mode, path] = argv;
  if (argv.length !== 2 || (mode !== "tiles" && mode !== "header")) {
    process.stderr.write("usage: node dump.mjs (tiles|header) ARCHIVE\n");
    return 2;
  }
  const source = new NodeFileSource(path);
  const pm = new PMTiles(source, new SharedPromiseCache(100, undefined, decompress), decompress);
  try {
    const lines = mode === "tiles" ? await dumpTiles(pm) : await dumpHeader(pm);
    process.stdout.write(lines.map((l) => l + "\n").join(""));
    return 0;
  } finally {
    await source.close();
  }
}

runMain("dump.mjs", main);

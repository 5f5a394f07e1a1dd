// Reads an exported web-tile archive (vts export) the way a web map does: through the npm `pmtiles`
// library with its default decompressor (no custom one), so only what stock readers support works.
//
//   node read_export.mjs ARCHIVE OUTDIR
// Prints the header and metadata as one JSON object on stdout and writes every tile to
// OUTDIR/z/x/y.EXT (EXT from the header's tile type). Tiles are found twice, independently: by
// walking the directories with the library's parser and, when the pyramid is small enough, by
// asking getZxy() for every slot of every level; both must agree.
// Exit status: 0 on success, 1 on any error or disagreement (message on stderr), 2 on bad usage.
import { mkdir, writeFile } from "node:fs/promises";
import { PMTiles, TileType, tileIdToZxy } from "pmtiles";
import { NodeFileSource, probeAllSlots, runMain, walkDirectories } from "./archive.mjs";

const kExtension = { [TileType.Png]: "png", [TileType.Jpeg]: "jpg", [TileType.Webp]: "webp" };

async function main(argv) {
  if (argv.length !== 2) {
    process.stderr.write("usage: node read_export.mjs ARCHIVE OUTDIR\n");
    return 2;
  }
  const [path, outdir] = argv;
  const source = new NodeFileSource(path);
  const pm = new PMTiles(source); // the library's default decompressor
  try {
    const header = await pm.getHeader();
    const metadata = await pm.getMetadata();
    const ext = kExtension[header.tileType];
    if (ext === undefined) throw new Error(`tile type ${header.tileType} is not a web image`);
    const ids = await walkDirectories(pm, header);
    const probed = await probeAllSlots(pm, header, 1 << 18);
    if (probed !== null) {
      const a = [...ids].sort((x, y) => x - y).join(",");
      const b = [...probed].sort((x, y) => x - y).join(",");
      if (a !== b) throw new Error("directory walk and getZxy() disagree on the tile set");
    }
    for (const id of ids) {
      const [z, x, y] = tileIdToZxy(id);
      const resp = await pm.getZxy(z, x, y);
      if (resp === undefined) throw new Error(`getZxy(${z}, ${x}, ${y}) found no tile`);
      await mkdir(`${outdir}/${z}/${x}`, { recursive: true });
      await writeFile(`${outdir}/${z}/${x}/${y}.${ext}`, new Uint8Array(resp.data));
    }
    const out = { ...header, etag: undefined, metadata, tiles_read: ids.length };
    process.stdout.write(JSON.stringify(out) + "\n");
    return 0;
  } finally {
    await source.close();
  }
}

runMain("read_export.mjs", main);

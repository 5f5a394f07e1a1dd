// What dump.mjs and read_export.mjs share: a local archive opened for the npm `pmtiles` library,
// and its tiles found twice, independently (the directories walked with the library's own parser,
// and getZxy() asked for every slot of every level).
import { open } from "node:fs/promises";
import { zxyToTileId } from "pmtiles";

// Source over a local file (the library ships only browser File and fetch sources).
export class NodeFileSource {
  constructor(path) {
    this.path = path;
    this.handle = null;
  }
  getKey() {
    return this.path;
  }
  async getBytes(offset, length) {
    this.handle ??= await open(this.path, "r");
    const buf = Buffer.alloc(length);
    let done = 0;
    while (done < length) {
      const { bytesRead } = await this.handle.read(buf, done, length - done, offset + done);
      if (bytesRead === 0) break; // end of file: return what exists, as an HTTP range would
      done += bytesRead;
    }
    return { data: buf.buffer.slice(buf.byteOffset, buf.byteOffset + done) };
  }
  async close() {
    await this.handle?.close();
    this.handle = null;
  }
}

// Every addressed tile id, from the root and leaf directories (run lengths expanded); throws on
// nesting deeper than 4 or ids that do not increase.
export async function walkDirectories(pm, header) {
  const ids = [];
  const visit = async (offset, length, depth) => {
    if (depth > 4) throw new Error("directory nesting deeper than 4");
    const entries = await pm.cache.getDirectory(pm.source, offset, length, header);
    for (const e of entries) {
      if (e.runLength === 0) {
        await visit(header.leafDirectoryOffset + e.offset, e.length, depth + 1);
      } else {
        for (let i = 0; i < e.runLength; i++) ids.push(e.tileId + i);
      }
    }
  };
  await visit(header.rootDirectoryOffset, header.rootDirectoryLength, 0);
  for (let i = 1; i < ids.length; i++) {
    if (ids[i] <= ids[i - 1]) throw new Error(`tile ids not increasing at ${ids[i]}`);
  }
  return ids;
}

// The ids of the slots where getZxy() finds a tile, sorted; null when the pyramid has more than
// maxSlots slots (too many to ask one by one; the walk still counts).
export async function probeAllSlots(pm, header, maxSlots) {
  let slots = 0;
  for (let z = header.minZoom; z <= header.maxZoom; z++) slots += 4 ** z;
  if (slots > maxSlots) return null;
  const found = [];
  for (let z = header.minZoom; z <= header.maxZoom; z++) {
    const n = 2 ** z;
    for (let y = 0; y < n; y++) {
      for (let x = 0; x < n; x++) {
        if ((await pm.getZxy(z, x, y)) !== undefined) found.push(zxyToTileId(z, x, y));
      }
    }
  }
  return found.sort((a, b) => a - b);
}

// Runs main(argv) with the command line's arguments: its result is the exit status; a throw is
// status 1, with "NAME: " and the stack on stderr.
export function runMain(name, main) {
  main(process.argv.slice(2)).then(
    (code) => {
      process.exitCode = code;
    },
    (err) => {
      process.stderr.write(`${name}: ${err?.stack ?? err}\n`);
      process.exitCode = 1;
    },
  );
}

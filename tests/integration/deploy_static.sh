#!/usr/bin/env bash
# deploy/nginx/vts-static.conf.template, as checked in: nginx serves the .pmtiles archive as a
# static file with Range (no tile server at all). Checked on loopback:
#   - Range answers (206, Content-Range, ETag, CORS, preflight), nothing but archives served;
#   - our client's range-reading source reads every tile correctly: `vts warm URL.pmtiles` caches
#     all of them (each verified against its checksum), and `vts cache serve --upstream
#     URL.pmtiles` hands out every tile byte for byte as stored in the archive;
#   - the npm `pmtiles` reader (FetchSource: HTTP range requests) reads the header and every
#     tile exactly as our reader (pmtiles_dump) reads the local file.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
# shellcheck source=serve_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/serve_lib.sh"
# shellcheck source=deploy_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/deploy_lib.sh"
: "${PMTILES_DUMP:?PMTILES_DUMP must name the pmtiles_dump tool}"
: "${PMTILES_JS:?PMTILES_JS must name tests/integration/pmtiles_js}"
require_tool "$NODE"
[[ -f $PMTILES_JS/node_modules/pmtiles/package.json ]] ||
  fail "npm package pmtiles is not installed in $PMTILES_JS (run scripts/setup.sh)"
t_start=$(date +%s%N)

note "archives: earth (43 tiles) and a synthetic one with thousands of tiles"
mkdir -p "$WORK/srv"
build_earth "$WORK/srv/earth.pmtiles"
expect_ok "$VTS" build --synthetic 16384x8192 -o "$WORK/srv/synth.pmtiles"
echo "not an archive" >"$WORK/srv/notes.txt"

note "nginx from deploy/nginx/vts-static.conf.template"
start_static_nginx "$WORK/srv"
wait_http "$S/earth.pmtiles"

note "Range, ETag, CORS; only archives are served"
A="$WORK/srv/earth.pmtiles"
size=$(stat -c %s "$A")
cmp -s <(curl -sf -r 0-126 "$S/earth.pmtiles") <(archive_bytes "$A" 0 127) || fail "header range differs"
expect_status 206 -r 1000-1999 "$S/earth.pmtiles"
[[ $(header_of Content-Range -r 1000-1999 "$S/earth.pmtiles") == "bytes 1000-1999/$size" ]] ||
  fail "Content-Range: $(header_of Content-Range -r 1000-1999 "$S/earth.pmtiles")"
cmp -s <(curl -sf -r -100 "$S/earth.pmtiles") <(tail -c 100 "$A") || fail "suffix range differs"
expect_status 416 -r "$size-" "$S/earth.pmtiles"
[[ $(header_of Accept-Ranges "$S/earth.pmtiles") == bytes ]] || fail "no Accept-Ranges: bytes"
[[ $(header_of Content-Type "$S/earth.pmtiles") == application/vnd.pmtiles ]] || fail "Content-Type"
[[ $(header_of Access-Control-Allow-Origin -r 0-9 "$S/earth.pmtiles") == "*" ]] || fail "no CORS"
[[ $(header_of Access-Control-Expose-Headers -r 0-9 "$S/earth.pmtiles") == *Content-Range* ]] ||
  fail "Content-Range not exposed to scripts"
etag=$(header_of ETag "$S/earth.pmtiles")
[[ -n $etag ]] || fail "no ETag"
expect_status 206 -r 0-9 -H "If-Range: $etag" "$S/earth.pmtiles"
expect_status 200 -r 0-9 -H 'If-Range: "stale"' "$S/earth.pmtiles"
expect_status 204 -X OPTIONS -H 'Origin: https://example.org' -H 'Access-Control-Request-Method: GET' \
  -H 'Access-Control-Request-Headers: range' "$S/earth.pmtiles"
[[ $(header_of Access-Control-Allow-Headers -X OPTIONS -H 'Access-Control-Request-Method: GET' \
  "$S/earth.pmtiles") == *Range* ]] || fail "preflight does not allow Range"
expect_status 404 "$S/notes.txt"
expect_status 404 "$S/"
expect_status 403 -X POST "$S/earth.pmtiles"
h2=$(curl -s --cacert "$N/tls/cert.pem" --http2 -r 0-126 -o "$WORK/h2.bin" \
  -w '%{http_code} %{http_version}' "https://127.0.0.1:$HTTPS_PORT/earth.pmtiles")
[[ $h2 == "206 2" ]] || fail "https with HTTP/2 answered '$h2', expected '206 2'"
cmp -s "$WORK/h2.bin" <(archive_bytes "$A" 0 127) || fail "range over HTTP/2 differs"

for name in earth synth; do
  A="$WORK/srv/$name.pmtiles"
  "$PMTILES_DUMP" offsets "$A" >"$WORK/$name.offsets" || fail "pmtiles_dump offsets $name"
  "$PMTILES_DUMP" tiles "$A" >"$WORK/$name.cpp_tiles" || fail "pmtiles_dump tiles $name"
  "$PMTILES_DUMP" header "$A" >"$WORK/$name.cpp_header" || fail "pmtiles_dump header $name"
  ntiles=$(wc -l <"$WORK/$name.offsets")

  note "$name: vts warm $S/$name.pmtiles (our range-reading source; every tile checksummed)"
  expect_ok "$VTS" warm "$S/$name.pmtiles" --cache-dir "$WORK/warm_$name" --json
  cp "$OUT" "$WORK/warm_$name.json"
  json_check "$WORK/warm_$name.json" \
    "j.complete === true && j.failed === 0 && j.tiles_total === $ntiles && j.from_network === $ntiles && j.cache.pinned_tiles === $ntiles" \
    "warm: complete, all $ntiles tiles from the network, none failed, all pinned"

  note "$name: vts cache serve --upstream $S/$name.pmtiles, every tile byte for byte"
  start_daemon cache "$VTS" cache serve --upstream "$S/$name.pmtiles" --cache-dir "$WORK/daemon_$name" \
    --listen 127.0.0.1:0 --no-admin
  REPLICA_PIDS[9]=$DAEMON_PID
  mkdir -p "$WORK/daemon_tiles_$name" "$WORK/ref_$name"
  : >"$LOGS/daemon.cfg"
  while read -r _ z x y off len; do
    dd if="$A" of="$WORK/ref_$name/${z}_${x}_$y" iflag=skip_bytes,count_bytes skip="$off" \
      count="$len" status=none
    printf 'url = "%s/%s/%s/%s/%s"\noutput = "%s/%s_%s_%s"\n' "$D" "$name" "$z" "$x" "$y" \
      "$WORK/daemon_tiles_$name" "$z" "$x" "$y" >>"$LOGS/daemon.cfg"
  done <"$WORK/$name.offsets"
  curl -s --parallel --parallel-max 16 -K "$LOGS/daemon.cfg" -w '%{http_code}\n' \
    >"$LOGS/daemon.codes" 2>"$LOGS/daemon.err" || fail "curl through the cache daemon failed"
  [[ $(grep -c '^200$' "$LOGS/daemon.codes") == "$ntiles" ]] ||
    fail "cache daemon: $(sort "$LOGS/daemon.codes" | uniq -c | tr '\n' ' ')"
  diff -rq "$WORK/ref_$name" "$WORK/daemon_tiles_$name" >"$LOGS/daemon.diff" ||
    { head "$LOGS/daemon.diff" >&2; fail "tiles read through nginx + cache daemon differ from the archive"; }
  { kill -TERM "${REPLICA_PIDS[9]}" && wait "${REPLICA_PIDS[9]}"; } 2>/dev/null || true
  REPLICA_PIDS[9]=""

  note "$name: npm pmtiles over HTTP (FetchSource) reads what our reader reads from the file"
  # The library's own HTTP source; zstd tile payloads pass through raw (hashed, not decoded),
  # directories and metadata are gzip. Prints pmtiles_dump's lines for the header fields and for
  # every tile it finds by walking the directories.
  "$NODE" --input-type=module - "$PMTILES_JS/node_modules/pmtiles/dist/esm/index.js" \
    "$S/$name.pmtiles" >"$WORK/$name.js_out" 2>"$LOGS/node.err" <<'JS' ||
import { gunzipSync } from "node:zlib";
const [lib, url] = process.argv.slice(2);
const { Compression, FetchSource, PMTiles, SharedPromiseCache, tileIdToZxy } = await import(lib);
const decompress = async (buf, c) => {
  if (c === Compression.None || c === Compression.Zstd) return buf;
  if (c === Compression.Gzip) {
    const b = gunzipSync(Buffer.from(buf));
    return b.buffer.slice(b.byteOffset, b.byteOffset + b.byteLength);
  }
  throw new Error(`unsupported compression ${c}`);
};
function fnv1a64(bytes) { // as tests/integration/pmtiles_js/dump.mjs
  let hi = 0xcbf29ce4, lo = 0x84222325;
  for (let i = 0; i < bytes.length; i++) {
    lo = (lo ^ bytes[i]) >>> 0;
    const t = lo * 0x1b3;
    hi = (Math.imul(hi, 0x1b3) + Math.floor(t / 4294967296) + (lo << 8)) >>> 0;
    lo = t >>> 0;
  }
  return hi.toString(16).padStart(8, "0") + lo.toString(16).padStart(8, "0");
}
const source = new FetchSource(url);
const pm = new PMTiles(source, new SharedPromiseCache(100, undefined, decompress), decompress);
const h = await pm.getHeader();
const out = [`H addressed_tiles=${h.numAddressedTiles}`, `H tile_contents=${h.numTileContents}`,
  `H max_zoom=${h.maxZoom}`, `H tile_compression=${h.tileCompression}`];
const ids = [];
const visit = async (offset, length, depth) => {
  if (depth > 4) throw new Error("directories nested deeper than 4");
  for (const e of await pm.cache.getDirectory(source, offset, length, h)) {
    if (e.runLength === 0) await visit(h.leafDirectoryOffset + e.offset, e.length, depth + 1);
    else for (let i = 0; i < e.runLength; i++) ids.push(e.tileId + i);
  }
};
await visit(h.rootDirectoryOffset, h.rootDirectoryLength, 0);
for (const id of ids) {
  const [z, x, y] = tileIdToZxy(id);
  const r = await pm.getZxy(z, x, y);
  if (r === undefined) throw new Error(`getZxy(${z}, ${x}, ${y}) found no tile`);
  const b = new Uint8Array(r.data);
  out.push(`${id} ${z} ${x} ${y} ${b.length} ${fnv1a64(b)}`);
}
process.stdout.write(out.map((l) => l + "\n").join(""));
JS
    { cat "$LOGS/node.err" >&2; fail "npm pmtiles could not read $S/$name.pmtiles"; }
  grep -v '^H ' "$WORK/$name.js_out" >"$WORK/$name.js_tiles"
  if ! cmp -s "$WORK/$name.cpp_tiles" "$WORK/$name.js_tiles"; then
    diff -u --label "ours (file)" --label "npm pmtiles (HTTP)" "$WORK/$name.cpp_tiles" \
      "$WORK/$name.js_tiles" | head -n 40 >&2 || true
    fail "$name: npm pmtiles over nginx and our reader disagree"
  fi
  for f in addressed_tiles tile_contents max_zoom tile_compression; do
    want=$(sed -n "s/^$f=//p" "$WORK/$name.cpp_header")
    got=$(sed -n "s/^H $f=//p" "$WORK/$name.js_out")
    [[ $want == "$got" ]] || fail "$name: header $f: ours $want, npm pmtiles over HTTP $got"
  done
  note "$name: $ntiles tiles read identically (warm, cache daemon, npm pmtiles)"
done

note "PASS in $(elapsed_ms) ms"

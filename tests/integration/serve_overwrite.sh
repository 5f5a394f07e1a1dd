#!/usr/bin/env bash
# A served archive overwritten, truncated and rewritten in place, 20 times, while four clients
# fetch its tiles: `vts serve` never dies, every 200 is a whole tile of the old archive or of the
# new one (never a mix), the only other answer is 503 while the file is being replaced, and after
# each round the server serves the archive that was written.
source "$(dirname "$0")/lib.sh"
source "$(dirname "$0")/serve_lib.sh"
require_tool python3
require_tool sha256sum

mkdir -p "$WORK/serve"
# Two archives of one geometry with different bytes in every tile.
build_earth "$WORK/serve/a.pmtiles"
build_earth "$WORK/serve/b.pmtiles" --codec bc1
cp "$WORK/serve/a.pmtiles" "$WORK/serve/served.pmtiles"
echo '{"reload_interval_ms": 200, "threads": 2}' >"$WORK/config.json"
start_server "$WORK/serve" --config "$WORK/config.json"

version() { curl -sf "$BASE/$1.json" | sed -nE 's/.*"version" *: *"([0-9a-f]+)".*/\1/p'; }
va=$(version a)
vb=$(version b)
[[ -n $va && -n $vb && $va != "$vb" ]] || fail "versions of a and b: '$va' '$vb'"

note "reference tiles: every address of the 2048x1024 pyramid in a and in b"
refs="{"
for z in 0 1 2 3; do
  for ((y = 0; y < (1 << z) / 2 + (z == 0); y++)); do
    for ((x = 0; x < (1 << z); x++)); do
      ha=$(curl -sf "$BASE/a/$z/$x/$y" | sha256sum | cut -d' ' -f1) || fail "no tile a/$z/$x/$y"
      hb=$(curl -sf "$BASE/b/$z/$x/$y" | sha256sum | cut -d' ' -f1) || fail "no tile b/$z/$x/$y"
      [[ $ha != "$hb" ]] || fail "tile $z/$x/$y is the same in a and b"
      refs+="\"$z/$x/$y\": [\"$ha\", \"$hb\"],"
    done
  done
done
echo "${refs%,}}" >"$WORK/refs.json"

# wait_for_version V: until /served.json reports version V (at most 20 s).
wait_for_version() {
  local i
  for ((i = 0; i < 200; i++)); do
    [[ $(version served) == "$1" ]] && return 0
    kill -0 "$SERVER_PID" 2>/dev/null || fail "vts serve died: $(tail -5 "$LOGS/serve.err")"
    sleep 0.1
  done
  fail "the server did not switch to version $1 within 20 s (it reports $(version served))"
}

python3 "$(dirname "$0")/overwrite_load.py" "$BASE" served "$WORK/refs.json" "$WORK/stop" \
  "$WORK/load.json" 4 &
load=$!
# A failure below must not leave the clients running.
trap 'kill "$load" 2>/dev/null || true; serve_cleanup' EXIT

served="$WORK/serve/served.pmtiles"
for ((round = 0; round < 20; round++)); do
  if ((round % 2 == 0)); then next=b want=$vb; else next=a want=$va; fi
  src="$WORK/serve/$next.pmtiles"
  case $((round % 4)) in
    0) cp "$src" "$served" ;;                                           # truncate, then write
    1) truncate -s $(($(stat -c %s "$served") / 2)) "$served" && cp "$src" "$served" ;;
    2) dd if="$src" of="$served" bs=64k conv=notrunc status=none && # rewrite in place
      truncate -s "$(stat -c %s "$src")" "$served" ;;
    3) truncate -s 0 "$served" && cat "$src" >>"$served" ;;            # empty, then append
  esac
  wait_for_version "$want"
done
touch "$WORK/stop"
wait "$load" || fail "the load client failed"
kill -0 "$SERVER_PID" 2>/dev/null || fail "vts serve died: $(tail -5 "$LOGS/serve.err")"

whole=$(json_get "$WORK/load.json" 'j.whole')
note "answers: $(json_get "$WORK/load.json" 'JSON.stringify(j)')"
json_check "$WORK/load.json" 'j.mixed == 0' "no 200 mixed two archives"
json_check "$WORK/load.json" 'j.other == 0 && j.dropped == 0' "nothing but 200 and 503 answered"
((whole >= 200)) || fail "only $whole whole tiles were served during 20 rounds"
# It ends serving the last archive written (a), tile for tile.
for zxy in 0/0/0 3/5/2; do
  cmp -s <(curl -sf "$BASE/served/$zxy") <(curl -sf "$BASE/a/$zxy") ||
    fail "served/$zxy is not a's after the last round"
done
grep -q 'reloaded 1 tileset' "$LOGS/serve.err" || fail "no reload logged"
stop_server

#!/usr/bin/env bash
# Numeric and text options out of range: every command refuses them at once with exit 2 and a
# message naming the option, instead of crashing (SIGABRT on 100000 threads), wrapping (-5 read
# as 2^64-5), reading /dev/zero until memory runs out, or printing a URL that cannot work.
source "$(dirname "$0")/lib.sh"

"$VTS" build --synthetic 512x512 -o "$WORK/s.pmtiles" >/dev/null 2>&1 || fail "cannot build s.pmtiles"
big=9223372036854775807

# expect_refused WHAT ARGS...: exit 2, and stderr mentions WHAT.
expect_refused() {
  local what=$1
  shift
  run "$@"
  ((RC == 2)) || { show_output; fail "vts ${*:1:4} exited $RC, expected 2"; }
  grep -qiF -- "$what" "$ERR" || { show_output; fail "vts ${*:1:4}: the error does not mention '$what'"; }
}

note "vts build"
expect_refused --threads "$VTS" build --synthetic 512x512 -o "$WORK/x.pmtiles" --threads 100000
expect_refused --grid "$VTS" build "$EARTH" "$EARTH" -o "$WORK/x.pmtiles" --grid 99999999999x1
expect_refused --grid "$VTS" build "$EARTH" "$EARTH" -o "$WORK/x.pmtiles" --grid -2x1
expect_refused --synthetic "$VTS" build --synthetic -5x5 -o "$WORK/x.pmtiles"
expect_refused --synthetic "$VTS" build --synthetic 5x99999999999999999999 -o "$WORK/x.pmtiles"
expect_refused --region "$VTS" build --synthetic 512x512 --region -1,0,5,5 -o "$WORK/x.pmtiles"
expect_refused --region-level "$VTS" build --synthetic 512x512 --region-level 100 -o "$WORK/x.pmtiles"
expect_refused --zstd-level "$VTS" build --synthetic 512x512 --zstd-level -7 -o "$WORK/x.pmtiles"
expect_refused --zstd-level "$VTS" build --synthetic 512x512 --zstd-level 22 -o "$WORK/x.pmtiles"
expect_refused --name "$VTS" build --synthetic 512x512 --name '' -o "$WORK/x.pmtiles"
[[ ! -e $WORK/x.pmtiles ]] || fail "a refused build wrote its output"

note "vts serve"
# CR/LF in the Access-Control-Allow-Origin value would end the header and forge the rest.
expect_refused "cors_origin holds a control character" "$VTS" serve "$WORK/s.pmtiles" \
  --listen 127.0.0.1:0 --no-admin --cors-origin $'https://a.example\r\nSet-Cookie: x=1'

note "vts verify"
expect_refused --threads "$VTS" verify "$WORK/s.pmtiles" --threads 100000

note "vts loadtest"
expect_refused --threads "$VTS" loadtest http://127.0.0.1:1/t --threads 100000
expect_refused --threads "$VTS" loadtest http://127.0.0.1:1/t --threads -5

note "mistyped subcommands: named, with the nearest one"
# expect_unknown LINE ARGS...: exit 2 and LINE (fixed string) on stderr.
expect_unknown() {
  local line=$1
  shift
  run "$VTS" "$@"
  ((RC == 2)) || { show_output; fail "vts $* exited $RC, expected 2"; }
  grep -qxF -- "vts: error: $line" "$ERR" || { show_output; fail "vts $*: expected '$line'"; }
}
expect_unknown "unknown command 'buidl'; did you mean 'build'?" buidl --synthetic 8x8 -o "$WORK/x.pmtiles"
expect_unknown "unknown command 'sevre'; did you mean 'serve'?" sevre "$WORK/s.pmtiles"
expect_unknown "unknown command 'loadtest compaer'; did you mean 'loadtest compare'?" \
  loadtest compaer a.json b.json
expect_unknown "unknown command 'loadtest merg'; did you mean 'loadtest merge'?" loadtest merg a.json
expect_unknown "unknown command 'xyzzy'" xyzzy
[[ ! -e $WORK/x.pmtiles ]] || fail "a mistyped build wrote its output"
# A word that is far from every subcommand below the top level stays a positional argument.
run "$VTS" loadtest earth --duration 0.1 --quiet
grep -qF 'unknown command' "$ERR" && { show_output; fail "loadtest took its URL for a command"; }
# A mistyped option: the command it was given to and its nearest option.
expect_unknown "unknown option '--viewer' of 'vts loadtest'; did you mean '--viewers'?" \
  loadtest http://127.0.0.1:9/t --viewer 3
expect_unknown "unknown option '--lisen' of 'vts serve'; did you mean '--listen'?" \
  serve --lisen 127.0.0.1:0 "$WORK/s.pmtiles"
expect_unknown "unknown option '--threshhold' of 'vts loadtest compare'; did you mean '--threshold'?" \
  loadtest compare a.json b.json --threshhold=3
expect_unknown "unknown option '--zzzzzzzz' of 'vts warm'" warm http://127.0.0.1:9/t --zzzzzzzz \
  --cache-dir "$WORK/c"
# ... and before the required option it may have been meant to be.
expect_unknown "unknown option '--cache-dri' of 'vts warm'; did you mean '--cache-dir'?" \
  warm http://127.0.0.1:9/t --cache-dri "$WORK/c"

note "vts sign"
expect_refused --ttl "$VTS" sign /t/0/0/0 --key k --ttl "$big"
expect_refused --ttl "$VTS" sign /t/0/0/0 --key k --ttl -100
expect_refused --ttl "$VTS" sign /t/0/0/0 --key k --ttl 0
expect_refused --expires "$VTS" sign /t/0/0/0 --key k --expires -5
expect_refused --expires "$VTS" sign /t/0/0/0 --key k --expires 1000
expect_refused path "$VTS" sign '/t/0 0/0' --key k
expect_refused path "$VTS" sign $'/t/0/0/0\nX-Evil: 1' --key k
expect_refused 'key file' "$VTS" sign /t/0/0/0 --key-file /dev/zero
head -c 100000 /dev/urandom >"$WORK/huge.key"
expect_refused 'key file' "$VTS" sign /t/0/0/0 --key-file "$WORK/huge.key"
# The accepted forms still work: a path and a key give path?expires=...&sig=...
out=$("$VTS" sign /t/0/0/0 --key k --ttl 60) || fail "vts sign refused a valid request"
[[ $out =~ ^/t/0/0/0\?expires=[0-9]+\&sig=[0-9a-f]{64}$ ]] || fail "vts sign printed '$out'"

note "vts cache serve and vts view"
expect_refused --cache-size "$VTS" cache serve --upstream "$WORK/s.pmtiles" --cache-dir "$WORK/c" \
  --listen 127.0.0.1:0 --no-admin --cache-size -5
expect_refused --ram-size "$VTS" cache serve --upstream "$WORK/s.pmtiles" --cache-dir "$WORK/c" \
  --listen 127.0.0.1:0 --no-admin --ram-size 12Q
expect_refused --upstream-deadline "$VTS" cache serve --upstream "$WORK/s.pmtiles" \
  --cache-dir "$WORK/c" --listen 127.0.0.1:0 --no-admin --upstream-deadline 0
expect_refused --upstream-region-cap "$VTS" cache serve --upstream "$WORK/s.pmtiles" \
  --cache-dir "$WORK/c" --listen 127.0.0.1:0 --no-admin --upstream-region-cap -1
note "an array job's index that is not one"
expect_ok "$VTS" plan --synthetic 1000x500 --shards 4 -o "$WORK/p.json" -q
JOB_COMPLETION_INDEX=x expect_refused "JOB_COMPLETION_INDEX='x' is not a shard index" \
  "$VTS" build --plan "$WORK/p.json" --out-dir "$WORK/parts"
SLURM_ARRAY_TASK_ID=-1 expect_refused "SLURM_ARRAY_TASK_ID='-1' is not a generator index" \
  "$VTS" loadtest "http://127.0.0.1:1/x" --generators 2 --duration 1
note "a shard offset that is not one, or that takes an array's index past the plan's shards"
n=$(python3 -c 'import json,sys; print(len(json.load(open(sys.argv[1]))["shards"]))' "$WORK/p.json")
SLURM_ARRAY_TASK_ID=0 VTS_SHARD_OFFSET=x expect_refused "VTS_SHARD_OFFSET='x' is not a shard offset" \
  "$VTS" build --plan "$WORK/p.json" --out-dir "$WORK/parts"
SLURM_ARRAY_TASK_ID=0 VTS_SHARD_OFFSET=-3 expect_refused "VTS_SHARD_OFFSET='-3' is not a shard offset" \
  "$VTS" build --plan "$WORK/p.json" --out-dir "$WORK/parts"
SLURM_ARRAY_TASK_ID=0 expect_refused "--shard-offset '-1' is not a shard offset" \
  "$VTS" build --plan "$WORK/p.json" --out-dir "$WORK/parts" --shard-offset -1
SLURM_ARRAY_TASK_ID=1 VTS_SHARD_OFFSET=$((n - 1)) expect_refused \
  "shard index \$SLURM_ARRAY_TASK_ID=1 + \$VTS_SHARD_OFFSET=$((n - 1)) is out of range: the plan has $n shards" \
  "$VTS" build --plan "$WORK/p.json" --out-dir "$WORK/parts"
AWS_BATCH_JOB_ARRAY_INDEX=2 expect_refused \
  "shard index \$AWS_BATCH_JOB_ARRAY_INDEX=2 + --shard-offset 9999999999999999999 is out of range" \
  "$VTS" build --plan "$WORK/p.json" --out-dir "$WORK/parts" --shard-offset 9999999999999999999
expect_refused "give --shard or --shard-offset, not both" \
  "$VTS" build --plan "$WORK/p.json" --out-dir "$WORK/parts" --shard 0 --shard-offset 1
expect_refused "--shard-offset" "$VTS" build --synthetic 512x512 -o "$WORK/x.pmtiles" --shard-offset 1
[[ ! -e $WORK/parts ]] || fail "a refused shard wrote into --out-dir"
# The offset is added to the array's index: task 1 of an array from shard n-2 is shard n-1.
SLURM_ARRAY_TASK_ID=1 VTS_SHARD_OFFSET=$((n - 2)) expect_ok \
  "$VTS" build --plan "$WORK/p.json" --out-dir "$WORK/parts" --json
json_check "$OUT" "j.shard === $((n - 1))"
# The defaults PROTOCOL.md §11 states.
"$VTS" cache serve --help >"$OUT" 2>&1 || true
grep -qE -- '--upstream-deadline .*=20$' "$OUT" || fail "--upstream-deadline default is not 20"
grep -qE -- '--upstream-region-cap .*=8$' "$OUT" || fail "--upstream-region-cap default is not 8"
if "$VTS" view --help >/dev/null 2>&1; then
  expect_refused --slots "$VTS" view "$WORK/s.pmtiles" --headless --slots 4294967295
fi

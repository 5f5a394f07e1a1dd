#!/usr/bin/env bash
# What `vts serve` answers before routing, over a raw socket (python3): a request that does not
# parse or is too large carries Cache-Control: no-store and the CORS headers as every error does;
# an HTTP/1.1 request without Host, two Host fields and a Transfer-Encoding not ending with chunked
# are 400 with Connection: close; HTTP/1.0 without Host and OPTIONS * are served.
# shellcheck source=lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/lib.sh"
# shellcheck source=serve_lib.sh
source "$(dirname "${BASH_SOURCE[0]}")/serve_lib.sh"
require_tool python3

mkdir -p "$WORK/serve"
build_earth "$WORK/serve/earth.pmtiles"
start_server "$WORK/serve"

# raw NAME REQUEST: sends REQUEST (printf escapes) on a fresh connection; the reply's header
# lines go to $WORK/NAME.txt, and a last line "closed" or "open" says whether the server closed
# the connection within 3 s.
raw() {
  python3 - "$PORT" "$2" >"$WORK/$1.txt" <<'EOF'
import socket, sys
s = socket.create_connection(("127.0.0.1", int(sys.argv[1])))
s.settimeout(3)
s.sendall(sys.argv[2].encode().decode("unicode_escape").encode("latin-1"))
data, closed = b"", False
try:
    while True:
        b = s.recv(65536)
        if not b:
            closed = True
            break
        data += b
except socket.timeout:
    pass
except ConnectionResetError:
    closed = True
print(data.split(b"\r\n\r\n")[0].decode("latin-1").replace("\r", ""))
print("closed" if closed else "open")
EOF
}

# expect NAME STATUS HEADER...: the reply's status line starts with "HTTP/1.1 STATUS" and each
# HEADER ("Name: value", case-insensitive) is one of its lines.
expect() {
  local name=$1 status=$2 h
  shift 2
  head -1 "$WORK/$name.txt" | grep -q "^HTTP/1.1 $status" || fail "$name: $(head -1 "$WORK/$name.txt")"
  for h in "$@"; do
    grep -qix "$h" "$WORK/$name.txt" || fail "$name: no '$h' in $(cat "$WORK/$name.txt")"
  done
}

error_headers=("Cache-Control: no-store" "Access-Control-Allow-Origin: \\*"
  "Access-Control-Expose-Headers: ETag, Content-Range, Content-Length" "Connection: close" "closed")

note "network-layer errors carry no-store and CORS"
raw garbage 'NOT HTTP AT ALL\r\n\r\n'
expect garbage 400 "${error_headers[@]}"
raw big "GET /earth/0/0/0 HTTP/1.1\\r\\nHost: a\\r\\nX-Big: $(head -c 10000 /dev/zero | tr '\0' a)\\r\\n\\r\\n"
expect big 431 "${error_headers[@]}"
raw body 'GET /earth/0/0/0 HTTP/1.1\r\nHost: a\r\nContent-Length: 4\r\n\r\nxxxx'
expect body 413 "${error_headers[@]}"

note "Host: required once on HTTP/1.1, at most once before"
raw nohost 'GET /earth/0/0/0 HTTP/1.1\r\n\r\n'
expect nohost 400 "${error_headers[@]}"
raw twohosts 'GET /earth/0/0/0 HTTP/1.1\r\nHost: a\r\nHost: b\r\n\r\n'
expect twohosts 400 "${error_headers[@]}"
raw http10 'GET /earth/0/0/0 HTTP/1.0\r\n\r\n'
expect http10 200

note "Transfer-Encoding must end with chunked"
raw gzip 'GET /earth/0/0/0 HTTP/1.1\r\nHost: a\r\nTransfer-Encoding: gzip\r\n\r\n'
expect gzip 400 "${error_headers[@]}"

note "OPTIONS * is 204"
raw asterisk 'OPTIONS * HTTP/1.1\r\nHost: a\r\nConnection: close\r\n\r\n'
expect asterisk 204 "Allow: GET, HEAD, OPTIONS"

stop_server
note "PASS"

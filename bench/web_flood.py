#!/usr/bin/env python3
"""Floods a `vts serve` with cold web-image requests and measures what it costs another user.

Two attacks on the encode workers (issue 29, item 2), each against a victim that fetches one cold
PNG at a time (a new tile each time, one connection per request, as a web map's image loader):
  abandon  CONNECTIONS connections each pipeline PER distinct cold images, then close at once
           (a flood that sends ~600 KB and leaves): how much of that work the server still does
           for nobody, and the victim's latency meanwhile;
  heavy    HEAVY connections each pipeline PER distinct cold images and read every answer (one
           greedy client): the victim's latency while it is served.
Latencies are compared with the victim's at rest (same server, before the attacks). The work done
is read from the admin listener's /metrics (vts_web_encodes_total and friends). With --peer-port,
the abandon burst is also sent to a peer serving the same images as files (nginx over
`vts export --layout xyz`, paths /NAME/Z/X/Y.png), with the same victim before and during it:
what the burst costs at the network layer alone, where no image is encoded.

  web_flood.py --port P --admin-port A --tileset NAME --zoom Z --cols C --rows R
               [--peer-port N] [--json]

Tiles are taken from level Z (C x R tiles, all present) in disjoint sets, so every request is a
cold miss. Prints a JSON object with --json, else a short report.
"""
import argparse
import json
import selectors
import socket
import statistics
import sys
import time
import urllib.request


def metrics(admin_port):
    with urllib.request.urlopen(f"http://127.0.0.1:{admin_port}/metrics", timeout=30) as r:
        text = r.read().decode()
    out = {}
    for line in text.splitlines():
        if line and not line.startswith("#") and "{" not in line:
            name, _, value = line.partition(" ")
            out[name] = float(value)
    return out


class Tiles:
    """Hands out distinct tiles of one level, each once."""

    def __init__(self, tileset, zoom, cols, rows):
        self.tileset, self.zoom = tileset, zoom
        self.it = ((x, y) for y in range(rows) for x in range(cols))

    def next_path(self):
        x, y = next(self.it)
        return f"/{self.tileset}/{self.zoom}/{x}/{y}.png"


def request(path, close=False):
    conn = "Connection: close\r\n" if close else ""
    return f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1\r\n{conn}\r\n".encode()


def fetch_once(port, path, timeout=120):
    """One GET on a new connection; returns (status, seconds to the whole response)."""
    t0 = time.perf_counter()
    s = socket.create_connection(("127.0.0.1", port), timeout=timeout)
    s.sendall(request(path, close=True))
    data = b""
    while True:
        chunk = s.recv(65536)
        if not chunk:
            break
        data += chunk
    s.close()
    status = int(data.split(b" ", 2)[1]) if data.startswith(b"HTTP/1.1 ") else 0
    return status, time.perf_counter() - t0


def victim(port, tiles, runs):
    lat, statuses = [], []
    for _ in range(runs):
        status, secs = fetch_once(port, tiles.next_path())
        statuses.append(status)
        lat.append(secs)
    return lat, statuses


def open_pipelined(port, n, per, tiles):
    """n connections, each with `per` pipelined requests sent; returns the sockets and bytes sent."""
    socks, sent = [], 0
    for _ in range(n):
        s = socket.create_connection(("127.0.0.1", port))
        payload = b"".join(request(tiles.next_path()) for _ in range(per))
        s.sendall(payload)
        sent += len(payload)
        socks.append(s)
    return socks, sent


def complete_responses(buf, counts):
    """Counts the whole responses at the front of `buf` by status; returns (how many, the rest)."""
    done, pos = 0, 0
    while True:
        end = buf.find(b"\r\n\r\n", pos)
        if end < 0:
            break
        head = buf[pos:end].decode("latin-1")
        length = 0
        for line in head.split("\r\n")[1:]:
            k, _, v = line.partition(":")
            if k.strip().lower() == "content-length":
                length = int(v)
        if len(buf) < end + 4 + length:
            break
        status = int(head.split(" ", 2)[1])
        counts[status] = counts.get(status, 0) + 1
        pos = end + 4 + length
        done += 1
    return done, buf[pos:]


def read_all_responses(socks, per, timeout=300):
    """Reads each socket until `per` responses arrived (or it closed); returns status counts."""
    sel = selectors.DefaultSelector()
    left = {}  # socket -> [unparsed bytes, responses still owed]
    for s in socks:
        s.setblocking(False)
        sel.register(s, selectors.EVENT_READ)
        left[s] = [b"", per]
    counts = {}
    deadline = time.time() + timeout
    while left and time.time() < deadline:
        for key, _ in sel.select(timeout=1):
            s = key.fileobj
            try:
                chunk = s.recv(1 << 20)
            except BlockingIOError:
                continue
            state = left[s]
            done, state[0] = complete_responses(state[0] + chunk, counts)
            state[1] -= done
            if not chunk or state[1] <= 0:
                sel.unregister(s)
                s.close()
                del left[s]
    return counts


def drained(admin_port, timeout=600):
    end = time.time() + timeout
    while time.time() < end:
        m = metrics(admin_port)
        if m.get("vts_web_encode_queue_length", 0) == 0:
            return m
        time.sleep(0.05)
    raise SystemExit("the server's encode queue did not drain")


def summary(lat):
    return {"p50_ms": round(statistics.median(lat) * 1000, 1), "max_ms": round(max(lat) * 1000, 1)}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--port", type=int, required=True)
    ap.add_argument("--admin-port", type=int, required=True)
    ap.add_argument("--tileset", required=True)
    ap.add_argument("--zoom", type=int, required=True)
    ap.add_argument("--cols", type=int, required=True)
    ap.add_argument("--rows", type=int, required=True)
    ap.add_argument("--connections", type=int, default=500)
    ap.add_argument("--per", type=int, default=16)
    ap.add_argument("--heavy", type=int, default=32)
    ap.add_argument("--victim-runs", type=int, default=20)
    ap.add_argument("--peer-port", type=int)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    need = a.connections * a.per + a.heavy * a.per + 4 * a.victim_runs
    if a.cols * a.rows < need:
        sys.exit(f"level {a.zoom} has {a.cols * a.rows} tiles; the runs need {need}")
    tiles = Tiles(a.tileset, a.zoom, a.cols, a.rows)
    out = {}

    rest, _ = victim(a.port, tiles, a.victim_runs)
    out["victim_at_rest"] = summary(rest)

    # abandon: send, close, then the victim asks while the server digests the flood.
    before = drained(a.admin_port)
    t0 = time.perf_counter()
    socks, sent = open_pipelined(a.port, a.connections, a.per, tiles)
    for s in socks:
        s.close()
    flood_secs = time.perf_counter() - t0
    during, statuses = victim(a.port, tiles, a.victim_runs)
    after = drained(a.admin_port)
    delta = {k: after.get(k, 0) - before.get(k, 0) for k in
             ("vts_web_encodes_total", "vts_web_encodes_dropped_total",
              "vts_web_encodes_shed_total", "vts_http_abandoned_connections_total")}
    requests = a.connections * a.per
    flood_encodes = delta["vts_web_encodes_total"] - sum(1 for s in statuses if s == 200)
    out["abandon"] = {
        "connections": a.connections, "requests": requests, "bytes_sent": sent,
        "send_seconds": round(flood_secs, 3),
        "encodes_for_nobody": int(flood_encodes),
        "abandoned_work_percent": round(100.0 * flood_encodes / requests, 2),
        "dropped": int(delta["vts_web_encodes_dropped_total"]),
        "shed_503": int(delta["vts_web_encodes_shed_total"]),
        "abandoned_connections": int(delta["vts_http_abandoned_connections_total"]),
        "victim": summary(during), "victim_statuses": sorted(set(statuses)),
        "victim_ratio_p50": round(statistics.median(during) / statistics.median(rest), 2),
        "victim_ratio_max": round(max(during) / statistics.median(rest), 2),
    }

    # heavy: a greedy client that reads its answers; the victim asks meanwhile.
    socks, _ = open_pipelined(a.port, a.heavy, a.per, tiles)
    during, statuses = victim(a.port, tiles, a.victim_runs)
    counts = read_all_responses(socks, a.per)
    drained(a.admin_port)
    out["heavy"] = {
        "connections": a.heavy, "requests": a.heavy * a.per,
        "statuses": {str(k): v for k, v in sorted(counts.items())},
        "victim": summary(during), "victim_statuses": sorted(set(statuses)),
        "victim_ratio_p50": round(statistics.median(during) / statistics.median(rest), 2),
        "victim_ratio_max": round(max(during) / statistics.median(rest), 2),
    }
    if a.peer_port:
        peer_tiles = Tiles(a.tileset, a.zoom, a.cols, a.rows)
        peer_rest, _ = victim(a.peer_port, peer_tiles, a.victim_runs)
        socks, _ = open_pipelined(a.peer_port, a.connections, a.per, peer_tiles)
        for s in socks:
            s.close()
        peer_during, statuses = victim(a.peer_port, peer_tiles, a.victim_runs)
        out["peer_abandon"] = {
            "victim_at_rest": summary(peer_rest), "victim": summary(peer_during),
            "victim_statuses": sorted(set(statuses)),
            "victim_ratio_p50": round(statistics.median(peer_during) / statistics.median(peer_rest), 2),
            "victim_ratio_max": round(max(peer_during) / statistics.median(peer_rest), 2),
        }
    if a.json:
        print(json.dumps(out, indent=2))
    else:
        print(json.dumps(out))


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Concurrent tile load against `vts serve` while another process rewrites a served archive.

    overwrite_load.py BASE TILESET REFERENCES STOP_FILE OUT_JSON [THREADS]

REFERENCES is a JSON object {"z/x/y": ["<sha256 of archive A's tile>", "<B's>"], ...}. Each
thread requests the listed tiles of BASE/TILESET round-robin over one keep-alive connection until
STOP_FILE exists (or its folder is gone, or 300 s have passed), and classifies every answer: 200 whose body is A's or B's tile for that address
("whole"), 200 with any other body ("mixed": the failure this test exists for), 503 (the archive
is being replaced: allowed), anything else ("other"), and connections the server dropped
("dropped"). Writes the counts to OUT_JSON.
"""
import hashlib
import http.client
import json
import os
import sys
import threading
import time


def main():
    base, tileset, refs_path, stop_file, out = sys.argv[1:6]
    threads = int(sys.argv[6]) if len(sys.argv) > 6 else 4
    with open(refs_path) as f:
        refs = json.load(f)
    host, port = base.removeprefix("http://").split(":")
    addresses = sorted(refs)
    counts = {"whole": 0, "mixed": 0, "503": 0, "other": 0, "dropped": 0}
    examples = []
    lock = threading.Lock()

    def count(kind, detail=None):
        with lock:
            counts[kind] += 1
            if detail and len(examples) < 10:
                examples.append(detail)

    deadline = time.monotonic() + 300
    stop_dir = os.path.dirname(stop_file)

    def stopped():
        return (os.path.exists(stop_file) or not os.path.isdir(stop_dir)
                or time.monotonic() > deadline)

    def worker(offset):
        conn = http.client.HTTPConnection(host, int(port), timeout=10)
        i = offset
        while not stopped():
            zxy = addresses[i % len(addresses)]
            i += 1
            try:
                conn.request("GET", f"/{tileset}/{zxy}")
                r = conn.getresponse()
                body = r.read()
            except (OSError, http.client.HTTPException) as e:
                count("dropped")
                conn.close()
                conn = http.client.HTTPConnection(host, int(port), timeout=10)
                if isinstance(e, ConnectionRefusedError):
                    count("other", f"{zxy}: connection refused (server gone?)")
                continue
            if r.status == 200:
                if hashlib.sha256(body).hexdigest() in refs[zxy]:
                    count("whole")
                else:
                    count("mixed", f"{zxy}: 200 with {len(body)} bytes that are neither tile")
            elif r.status == 503:
                count("503")
            else:
                count("other", f"{zxy}: {r.status} {body[:200]!r}")
        conn.close()

    pool = [threading.Thread(target=worker, args=(k * 7,)) for k in range(threads)]
    for t in pool:
        t.start()
    for t in pool:
        t.join()
    counts["examples"] = examples
    with open(out, "w") as f:
        json.dump(counts, f)


if __name__ == "__main__":
    main()

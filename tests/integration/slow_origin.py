#!/usr/bin/env python3
"""A slow region in front of a real `vts serve`: an HTTP/1.1 proxy on 127.0.0.1 that forwards
every request to the upstream, but first holds requests for the tiles of one level whose x is at
least --slow-x-min for --delay seconds. While it holds one, it watches the socket: a client that
closes it (libcurl removing the transfer) ends the hold at once and is counted as aborted.
GET /__stats answers {"slow": started, "aborted": closed by the client while held, "done": ...}.
Prints "listening on PORT" once ready; stops on SIGTERM."""
import argparse, http.client, json, re, select, signal, socket, sys, threading, time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

p = argparse.ArgumentParser()
p.add_argument("--upstream", required=True)  # host:port of vts serve
p.add_argument("--slow-z", type=int, required=True)
p.add_argument("--slow-x-min", type=int, required=True)
p.add_argument("--delay", type=float, required=True)
a = p.parse_args()
host, port = a.upstream.rsplit(":", 1)
lock = threading.Lock()
stats = {"slow": 0, "aborted": 0, "done": 0}
TILE = re.compile(r"^/[^/]+/(\d+)/(\d+)/(\d+)$")


def bump(k):
    with lock:
        stats[k] += 1


class H(BaseHTTPRequestHandler):
    protocol_version = "HTTP/1.1"

    def log_message(self, *args):
        pass

    def held_until_gone(self):
        """Holds for --delay s; True when the client closed the connection meanwhile."""
        end = time.monotonic() + a.delay
        while (left := end - time.monotonic()) > 0:
            r, _, _ = select.select([self.connection], [], [], min(left, 0.05))
            if r:
                try:
                    if self.connection.recv(1, socket.MSG_PEEK) == b"":
                        return True
                except OSError:
                    return True
        return False

    def do_GET(self):
        if self.path == "/__stats":
            with lock:
                body = json.dumps(stats).encode()
            return self.reply(200, body, [("Content-Type", "application/json")])
        m = TILE.match(self.path.split("?")[0])
        if m and int(m[1]) == a.slow_z and int(m[2]) >= a.slow_x_min:
            bump("slow")
            if self.held_until_gone():
                bump("aborted")
                self.close_connection = True
                return
        c = http.client.HTTPConnection(host, int(port), timeout=30)
        headers = {k: v for k, v in self.headers.items() if k.lower() in ("host", "if-none-match", "range")}
        c.request("GET", self.path, headers=headers)
        r = c.getresponse()
        body = r.read()
        keep = [(k, v) for k, v in r.getheaders()
                if k.lower() not in ("content-length", "connection", "transfer-encoding")]
        c.close()
        self.reply(r.status, body, keep)
        bump("done")

    def reply(self, status, body, headers):
        try:
            self.send_response(status)
            for k, v in headers:
                self.send_header(k, v)
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)
        except OSError:
            self.close_connection = True


class S(ThreadingHTTPServer):
    daemon_threads = True
    request_queue_size = 128


srv = S(("127.0.0.1", 0), H)
signal.signal(signal.SIGTERM, lambda *_: threading.Thread(target=srv.shutdown).start())
print("listening on", srv.server_address[1], flush=True)
srv.serve_forever()

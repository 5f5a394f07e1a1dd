#!/usr/bin/env python3
"""A recording proxy that checks every request's SigV4 signature with botocore.

s3rver checks the access key id but not the signature, so store_s3.sh puts this in front of it:
each request's Authorization header is recomputed by botocore's S3SigV4Auth (an independent
implementation: AWS's own SDK core) from the method, the URL, the headers the request says it
signed and its X-Amz-Date, then the request is forwarded to s3rver and the answer relayed.

    s3_sigv4_proxy.py UPSTREAM_PORT ACCESS_KEY_ID SECRET LOG

Prints "port N" once listening on 127.0.0.1. Appends one line per request to LOG:
    ok|mismatch|unsigned METHOD PATH signed=HEADER;HEADER;...
"""
import http.client
import http.server
import re
import sys
import threading

from botocore.auth import S3SigV4Auth
from botocore.awsrequest import AWSRequest
from botocore.credentials import Credentials

UPSTREAM, KEY_ID, SECRET, LOG = int(sys.argv[1]), sys.argv[2], sys.argv[3], sys.argv[4]
AUTH = re.compile(r"AWS4-HMAC-SHA256 Credential=([^/]+)/(\d{8})/([^/]+)/s3/aws4_request, "
                  r"SignedHeaders=([^,]+), Signature=([0-9a-f]{64})$")
log_lock = threading.Lock()


def verdict(method, path, headers):
    """ok/mismatch/unsigned and the signed header names of one request."""
    m = AUTH.match(headers.get("Authorization", ""))
    if not m:
        return "unsigned", ""
    key_id, _, region, signed, signature = m.groups()
    if key_id != KEY_ID:
        return "mismatch", signed
    names = signed.split(";")
    req = AWSRequest(method=method, url="http://" + headers["Host"] + path,
                     headers={n: headers[n] for n in names if n != "host"})
    req.headers["Host"] = headers["Host"]
    req.context["timestamp"] = headers["X-Amz-Date"]
    token = headers.get("X-Amz-Security-Token")
    auth = S3SigV4Auth(Credentials(key_id, SECRET, token), "s3", region)
    canonical = auth.canonical_request(req)
    # botocore signs exactly the headers handed to it: they must be the ones named.
    if auth.signed_headers(auth.headers_to_sign(req)) != signed:
        return "mismatch", signed
    expected = auth.signature(auth.string_to_sign(req, canonical), req)
    return ("ok" if expected == signature else "mismatch"), signed


class Handler(http.server.BaseHTTPRequestHandler):
    protocol_version = "HTTP/1.1"

    def relay(self):
        result, signed = verdict(self.command, self.path, self.headers)
        with log_lock, open(LOG, "a") as f:
            f.write(f"{result} {self.command} {self.path} signed={signed}\n")
        length = int(self.headers.get("Content-Length", 0) or 0)
        body = self.rfile.read(length) if length else None
        up = http.client.HTTPConnection("127.0.0.1", UPSTREAM, timeout=30)
        try:
            up.request(self.command, self.path, body=body,
                       headers={k: v for k, v in self.headers.items()})
            r = up.getresponse()
            data = r.read()
        except OSError as e:
            self.send_error(502, str(e))
            return
        finally:
            up.close()
        self.send_response_only(r.status, r.reason)
        for k, v in r.getheaders():
            if k.lower() not in ("connection", "keep-alive", "transfer-encoding", "content-length"):
                self.send_header(k, v)
        self.send_header("Content-Length", str(len(data) if self.command != "HEAD" else
                                                r.getheader("Content-Length", "0")))
        self.end_headers()
        if self.command != "HEAD":
            self.wfile.write(data)

    do_GET = do_HEAD = do_PUT = relay

    def log_message(self, *args):
        pass


server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
print(f"port {server.server_address[1]}", flush=True)
server.serve_forever()

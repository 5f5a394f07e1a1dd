// s3rver (a real S3-protocol server) on a free loopback port, for tests/integration/store_s3.sh.
//
//   node serve.js DIR BUCKET...   serves the buckets (created empty unless DIR holds them) from
//                                 DIR; prints "port N" once listening; logs one line per request
//                                 on stdout ("info: ... METHOD /path STATUS ..."); stops on SIGTERM.
// Credentials: access key id S3RVER, secret S3RVER (s3rver's; it refuses other key ids and, for a
// known key id, mismatched signatures).
"use strict";
const S3rver = require("s3rver");

const [dir, ...buckets] = process.argv.slice(2);
if (!dir || buckets.length === 0) {
  console.error("usage: node serve.js DIR BUCKET...");
  process.exit(2);
}
const server = new S3rver({
  address: "127.0.0.1",
  port: 0,
  directory: dir,
  silent: false,
  configureBuckets: buckets.map((name) => ({ name })),
});
server.run().then(
  (address) => {
    process.stdout.write(`port ${address.port}\n`);
  },
  (err) => {
    console.error(`s3rver: ${err.stack || err}`);
    process.exit(1);
  },
);
process.on("SIGTERM", () => {
  server.close().then(() => process.exit(0), () => process.exit(1));
});

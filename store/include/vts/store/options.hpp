// How the store reaches S3 and HTTP(S) servers: endpoint, region, credentials, timeouts and
// retries, resolved from the AWS environment the way the AWS CLI does (a subset: static keys from
// variables or the shared files; no SSO, no credential_process, no instance metadata).
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>

#include "vts/base/result.hpp"

namespace vts::store {

// What the store has done, for metrics and for tests that count requests. Every member only
// grows; all are atomics, so any thread may read them while requests run.
struct Counters {
  std::atomic<std::uint64_t> requests{0};   // HTTP requests sent, every retry and page included
  std::atomic<std::uint64_t> bytes{0};      // body bytes of successful (2xx) answers
  std::atomic<std::uint64_t> retries{0};    // requests repeated after a 5xx, a drop or a timeout
  std::atomic<std::uint64_t> coalesced{0};  // reads that waited for another thread's equal GET
  std::atomic<std::uint64_t> first_block_hits{0};  // reads served from the block read at open

  struct Snapshot {
    std::uint64_t requests = 0, bytes = 0, retries = 0, coalesced = 0, first_block_hits = 0;
  };
  Snapshot snapshot() const noexcept;
};

// Static AWS credentials. An empty session_token means long-term keys.
struct Credentials {
  std::string access_key_id, secret_access_key, session_token;
};

// How a bucket appears in request URLs.
enum class Addressing : std::uint8_t {
  automatic,     // virtual-host on AWS's own endpoint (path-style for bucket names with dots or
                 // not valid in a host name), path-style on a custom endpoint
  path,          // ENDPOINT/bucket/key
  virtual_host,  // bucket.ENDPOINT-HOST/key
};

struct StoreOptions {
  // S3 endpoint as scheme://host[:port] (e.g. http://127.0.0.1:4568 for an S3-compatible store);
  // empty: AWS, https://s3.<region>.amazonaws.com.
  std::string s3_endpoint;
  std::string region = "us-east-1";  // SigV4 scope and AWS's endpoint
  std::string profile = "default";   // the profile the credentials and region came from
  Addressing addressing = Addressing::automatic;
  // Unset: requests are not signed (public buckets, plain HTTP(S) servers).
  std::optional<Credentials> credentials;
  std::chrono::milliseconds connect_timeout{5000};
  // Whole-request limit (connect, wait, body); a transfer slower than 1 KiB/s for
  // min(timeout, 10 s) is abandoned earlier.
  std::chrono::milliseconds timeout{30000};
  // A request that meets a 5xx/429, a dropped connection or a timeout is repeated this many
  // times, after retry_backoff, then twice that, ...; then the call fails with unavailable.
  int retries = 2;
  std::chrono::milliseconds retry_backoff{200};
  // Bytes read by open_object()'s single GET and kept: a PMTiles header and root directory (and
  // usually the metadata) lie within the first 16 KiB, so opening an archive costs one request.
  std::size_t first_block = 16384;
  std::string ca_file;  // CA bundle for https (empty: the system's)
  // Where requests are counted; share one between objects to count them together. Never null
  // for the store's functions (they count nothing when it is).
  std::shared_ptr<Counters> counters = std::make_shared<Counters>();

  // Looks up an environment variable: nullopt when unset.
  using Environment = std::function<std::optional<std::string>(const std::string&)>;

  // Options from the process environment: see from_lookup().
  static Result<StoreOptions> from_environment(const std::string& profile = {});
  // Options from `env` (tests pass a map), resolved as the AWS CLI does:
  //   profile      the argument, else AWS_PROFILE, else AWS_DEFAULT_PROFILE, else "default"
  //   credentials  AWS_ACCESS_KEY_ID + AWS_SECRET_ACCESS_KEY (+ AWS_SESSION_TOKEN), else the
  //                profile's aws_access_key_id/aws_secret_access_key/aws_session_token in the
  //                credentials file ([name]), else in the config file ([profile name], or
  //                [default]); else none (unsigned requests)
  //   region       AWS_REGION, else AWS_DEFAULT_REGION, else the profile's `region` in the
  //                config file, else us-east-1
  //   s3_endpoint  AWS_ENDPOINT_URL_S3, else AWS_ENDPOINT_URL, else the profile's
  //                `endpoint_url` (top level, or nested under `s3 =`) in the config file
  //   addressing   the profile's nested `s3 =` / `addressing_style = auto|path|virtual`
  // Files: AWS_SHARED_CREDENTIALS_FILE (else $HOME/.aws/credentials) and AWS_CONFIG_FILE (else
  // $HOME/.aws/config); a missing file is no error. Errors: invalid_argument for a profile named
  // explicitly (argument or variable) that neither file has, a key id without a secret (or the
  // reverse) or an unknown addressing style; io for a file that exists but cannot be read;
  // too_large for one over 1 MiB.
  static Result<StoreOptions> from_lookup(const Environment& env, const std::string& profile = {});
};

}  // namespace vts::store

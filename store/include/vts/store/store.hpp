// Remote archives and objects: PMTiles archives read from S3 (s3://bucket/key) and HTTP(S)
// servers (https://host/name.pmtiles) with ranged GETs, as archive::Reader reads local files.
//
// Every call is synchronous and bounded in time: connect and whole-request timeouts, a low-speed
// limit, and a fixed number of retries (StoreOptions); nothing waits for a server forever. All
// functions are thread-safe. libcurl easy handles are pooled process-wide so that connections are
// kept alive between requests. Messages name the location (s3://... or the URL).
//
// Errors, the same for every call:
//   not_found    404: the object, or the bucket (NoSuchBucket), does not exist
//   io           401/403 (credentials refused or none given: S3's Code and Message quoted),
//                other 4xx, TLS and protocol failures
//   unavailable  5xx or 429, refused or dropped connections, timeouts, after every retry
//   invalid_argument  a location that does not parse
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "vts/archive/pmtiles.hpp"
#include "vts/base/result.hpp"
#include "vts/store/location.hpp"
#include "vts/store/options.hpp"

namespace vts::store {

// Opens an object for ranged reads with one GET of its first options.first_block bytes (kept:
// reads within them cost no request), which gives its size (Content-Range) and ETag (or, from a
// server that sends none, its Last-Modified). The source's reads:
//   - one `Range: bytes=a-b` GET each, with `If-Match: <ETag at open>` (else
//     `If-Unmodified-Since: <Last-Modified at open>`); concurrent reads of the same bytes share
//     one GET (counted in Counters::coalesced);
//   - changed, from then on (sticky), when the object is no longer the one opened: 412, 404 or
//     416, another ETag, another total size in Content-Range. Bytes of another object are never
//     returned, nor fewer bytes than asked (a short or misplaced 206 is corrupt);
//   - unavailable after the retries (5xx, drops, timeouts); unsupported from a server that
//     ignores Range.
// Open errors: as above, and unsupported when the server ignores Range for an object larger than
// the first block. name() is the location as given.
Result<std::unique_ptr<archive::ByteSource>> open_object(const std::string& location,
                                                         const StoreOptions& options);

// The whole object (a set's manifest), one GET: too_large, before reading the body where the
// server declares its length, when it has more than max_bytes bytes.
Result<std::string> get_object(const std::string& location, const StoreOptions& options,
                               std::size_t max_bytes);

// The object's ETag now (one HEAD), quotes included as the server sends it; for a server that
// sends no ETag, "last-modified: <Last-Modified>"; unsupported when it sends neither. For reload
// checks: a different value means a different object.
Result<std::string> object_etag(const std::string& location, const StoreOptions& options);

struct ObjectInfo {
  std::string url;  // s3://bucket/key
  std::string key;
  std::uint64_t size = 0;
  std::string etag;
  bool operator==(const ObjectInfo&) const = default;
};

// The objects directly under an s3:// prefix, like a folder listing: ListObjectsV2 with delimiter
// "/", every page followed by its continuation token; deeper "folders" are not descended into.
// A prefix not ending in "/" has one added (s3://b/tiles lists s3://b/tiles/...; s3://b lists
// the bucket's top level). In key order; an object named like the prefix itself (a "folder"
// marker) is left out. unsupported for http(s):// (HTTP has no listing);
// corrupt for an answer that is not a ListBucketResult or pages that do not end.
Result<std::vector<ObjectInfo>> list_objects(const std::string& prefix_location,
                                             const StoreOptions& options);

// list_objects() with the "folders" one level down too (S3's CommonPrefixes: the prefixes that
// key names continue with a "/" after, each as s3://bucket/prefix/sub/), sorted: where a served
// prefix's sets live (s3://bucket/prefix/planet/tileset.json).
struct Listing {
  std::vector<ObjectInfo> objects;
  std::vector<std::string> folders;
};
Result<Listing> list_folder(const std::string& prefix_location, const StoreOptions& options);

}  // namespace vts::store

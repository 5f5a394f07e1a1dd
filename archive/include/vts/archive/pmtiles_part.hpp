// Parts of a PMTiles archive built on many machines, and their merge into one archive.
//
// A sharded build (`vts plan`, `vts build --plan --shard`, `vts merge`; docs/PLANET.md) writes
// each shard's tiles to one part file; `merge_parts` streams the parts' indexes in tile-id order
// and writes the archive that archive::Writer writes from the same tiles, byte for byte: both lay
// it out with the same rule (docs/FORMAT.md §2, "Layout"):
//   - tiles in tile-id order; a tile whose payload equals the previous tile's shares its bytes
//     (and extends its run-length entry when their ids are consecutive);
//   - a payload of at most kSmallPayloadBytes equal to one of the first kSmallPayloadTable
//     distinct small payloads (in tile-id order) shares that one's bytes (uniform tiles, oceans);
//   - any other payload is stored where it first appears: the data is clustered.
//   - directories: all entries in the root when there are at most kLeafEntries and they fit in
//     the first 16 KiB; otherwise leaves of kLeafEntries entries, and leaves of kLeafEntries
//     pointers to those, as many levels as the root's 16 KiB needs.
// So the archive depends only on the set of (tile, payload) pairs, never on how it was cut.
//
// A part file is written under a temporary name, fsynced and renamed: it exists complete or not
// at all, and writing the same part twice (an engine's retry, or two at once) leaves the same
// bytes. Layout: payloads (each distinct payload of the part once, in order of first appearance by
// tile id), the index (one fixed-size record per tile, in tile-id order), the attachment (opaque
// bytes for the caller), the manifest (the caller's JSON), then a 64-byte footer naming the
// sections with XXH3-64 checksums of the index, attachment and manifest. Payloads are checked
// against their XXH3-128 in the index when the merge copies them.
#pragma once

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "vts/archive/pmtiles.hpp"

namespace vts::archive {

inline constexpr std::uint32_t kSmallPayloadBytes = 1024;
inline constexpr std::size_t kSmallPayloadTable = std::size_t{1} << 20;
inline constexpr std::size_t kLeafEntries = 4096;
// The message of merge_parts()'s not_found when no tile of the parts lies in MergeOptions::ranges
// (a set's archive with no data), so a caller tells it from a missing part.
inline constexpr std::string_view kNoTileInRanges = "no tile of the parts lies in the ranges asked";

struct PartStats {
  std::uint64_t tiles = 0;        // add_tile() calls
  std::uint64_t payloads = 0;     // distinct payloads stored in the part
  std::uint64_t data_bytes = 0;   // bytes of those payloads
  std::uint64_t file_bytes = 0;   // size of the part file
  std::uint64_t content_sum = 0;  // see PartInfo::content_sum
};

// Writes one part. Payloads are spooled as they arrive (any order, any thread), as Writer does.
class PartWriter : public TileSink {
 public:
  static Result<std::unique_ptr<PartWriter>> create(std::filesystem::path path);
  ~PartWriter() override = default;
  // Thread-safe. The same tile twice, an empty payload or one over 4 GiB is invalid_argument.
  Status add_tile(TileId id, std::span<const std::uint8_t> payload) override = 0;
  // Writes the part (a part without tiles is allowed) and renames it into place.
  virtual Result<PartStats> finish(std::span<const std::uint8_t> attachment,
                                   const std::string& manifest_json) = 0;
  virtual void abort() noexcept = 0;
};

// One record of a part's index.
struct PartRecord {
  std::uint64_t tile_id = 0;
  std::uint64_t offset = 0;  // within the part's payload section
  std::uint32_t length = 0;
  std::uint64_t hash_low = 0, hash_high = 0;  // XXH3-128 of the payload
};

// What a part says about itself, checked when it is opened (footer magic, section bounds within
// the file, index/attachment/manifest checksums, records sorted, inside the payload section).
struct PartInfo {
  std::filesystem::path path;
  std::uint64_t tiles = 0;
  std::uint64_t first_tile_id = 0, last_tile_id = 0;  // meaningless when tiles == 0
  std::uint64_t data_bytes = 0;
  // The part's tiles of each level present: one contiguous stretch of its index each.
  struct Segment {
    std::uint8_t z = 0;
    std::uint64_t first_tile_id = 0, last_tile_id = 0;
    std::uint64_t first_record = 0, records = 0;
  };
  std::vector<Segment> segments;  // in tile-id order
  // Sum (mod 2^64) over the part's tiles of XXH3-64 of {tile id, the checksum in the payload's
  // tile header (codec.hpp)}; tiles without a tile header add nothing. What build_pyramid sums
  // for TilesetInfo::content_hash, so parts' sums add up to the whole archive's.
  std::uint64_t content_sum = 0;
  std::string manifest_json;
  std::vector<std::uint8_t> attachment;
};
Result<PartInfo> read_part_info(const std::filesystem::path& path);

// Reads the index of an opened part sequentially (a bounded buffer) and its payloads.
class PartReader {
 public:
  static Result<std::unique_ptr<PartReader>> open(const std::filesystem::path& path);
  virtual ~PartReader() = default;
  virtual const PartInfo& info() const = 0;
  // Visits the records with tile_id in [first, last] in order; stops early when visit returns
  // false.
  virtual Status for_each_record(std::uint64_t first, std::uint64_t last,
                                 const std::function<bool(const PartRecord&)>& visit) const = 0;
  virtual Status read_payload(const PartRecord& r, std::vector<std::uint8_t>& out) const = 0;
};

struct MergeProgress {
  std::uint64_t tiles_done = 0, tiles_total = 0;
  std::uint64_t bytes_copied = 0, bytes_total = 0;
  bool copying = false;  // second pass: writing the archive
  double seconds = 0;
  // Index records read to find and walk the tiles merged: the binary searches that clip the
  // parts to MergeOptions::ranges, then each merged tile's record once per pass (two passes). So
  // about twice the tiles merged, whatever the number of parts.
  std::uint64_t records_read = 0;
  // Index records read to check the parts' checksums when they are opened: every part's whole
  // index (one checksum covers a part's index with its manifest), but those of the parts
  // MergeOptions::index_needed leaves out.
  std::uint64_t records_checked = 0;
};

struct MergeOptions {
  // Paths of the parts, in any order; their tiles must not overlap. Text, not
  // std::filesystem::path (which keeps its parsed components, ~10 times the size): a planet's
  // merge has ~10^5 of them.
  std::vector<std::string> parts;
  WriterOptions archive;  // as for Writer (path, compression, zooms, bounds)
  std::string metadata_json;
  // Check each copied payload against its XXH3-128 (reading it through memory). Off: payloads are
  // copied in the kernel (copy_file_range; extents shared on XFS/Btrfs with reflink), and only
  // the parts' indexes and manifests are checked.
  bool verify = true;
  // The tiles to merge: inclusive tile-id ranges, sorted and disjoint (else invalid_argument);
  // empty: every tile of the parts. The merge writes the archive Writer writes from the parts'
  // tiles in the ranges, so an archive of a set (one per tile R of level K with data, holding
  // subtree_ranges(R, maxz), and one of levels_above(K)) is made from the same parts as the
  // one-file archive, and its tiles are that archive's. Each part is clipped by binary search
  // over its index, so a merge of 1/P of the tiles reads about 1/P of the index records and
  // payloads (beyond the checksum of each part's index: MergeProgress::records_checked; see
  // index_needed). When
  // no tile of the parts lies in the ranges: not_found, and nothing is written.
  std::vector<TileIdRange> ranges;
  // With ranges: which parts (by position in `parts`) may hold tiles in them, as the caller knows
  // from where each part's tiles lie (a shard's sub-pyramid); empty: all. A part not needed is
  // opened for its manifest and attachment only (check_part sees them), its index neither read
  // nor checked: so a merge of one of P archives reads only its parts' indexes, not all of them.
  // Its checksum is checked by the merges that take its tiles, so a damaged part still fails the
  // set. A part that was needed after all is corrupt input the other merges report.
  std::vector<bool> index_needed;
  std::function<void(const MergeProgress&)> on_progress;  // about ten times a second
  const std::atomic<bool>* cancel = nullptr;
  // Called for each part once it is checked, with its manifest and attachment (which the merge
  // does not keep), then once all are, with the metadata to write (which may depend on what the
  // parts said); an error from either stops the merge before it writes. The caller's own checks
  // of the parts thus cost no second read of their indexes.
  std::function<Status(const PartInfo&)> check_part;
  std::function<Status(std::string& metadata_json)> check_parts;
};

// Writes the archive Writer would write from the parts' tiles (those in options.ranges, when
// given; WriterStats and MergeProgress count only those), in bounded memory (about 64 MiB
// for the small-payload table plus 4 MiB buffers, whatever the number of tiles and parts), using
// temporary files beside the output for the directories. A missing, truncated or corrupt part, or
// two parts holding the same tile, is an error naming the part; the output is then untouched.
Result<WriterStats> merge_parts(const MergeOptions& options);

}  // namespace vts::archive

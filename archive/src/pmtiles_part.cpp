// Parts of an archive and their merge (pmtiles_part.hpp). Part file layout (little-endian):
//   payloads                      data_bytes
//   index                         records x 36: tile id u64, offset u64, length u32, XXH3-128 (2 x
//   u64) segments                      segments x 40: z, first tile id, last tile id, first record,
//   records attachment, manifest          as given footer (64 bytes)             "VTSPART1",
//   data_bytes, records, segments, attachment length,
//                                 manifest length, content sum, XXH3-64 of everything from the
//                                 index up to this field
#include "vts/archive/pmtiles_part.hpp"

#include <xxhash.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <list>
#include <unordered_map>
#include <utility>

#include "pmtiles_io.hpp"
#include "vts/protocol/codec.hpp"

namespace vts::archive {
namespace {

using namespace detail;  // NOLINT(google-build-using-namespace): the archive internals

constexpr char kMagic[8] = {'V', 'T', 'S', 'P', 'A', 'R', 'T', '1'};
constexpr std::size_t kRecordBytes = 36, kSegmentBytes = 40, kFooterBytes = 64;
constexpr std::uint64_t kUnset = std::numeric_limits<std::uint64_t>::max();

PartRecord decode_record(const std::uint8_t* p) {
  return PartRecord{get_u64(p), get_u64(p + 8), get_u32(p + 16), get_u64(p + 20), get_u64(p + 28)};
}

Error corrupt(const std::filesystem::path& path, const std::string& what) {
  return make_error(ErrorCode::corrupt, "part " + path.string() + " is damaged: " + what);
}

std::uint8_t level_of(std::uint64_t tile_id) {
  Result<TileId> id = tile_id_to_zxy(tile_id);
  return id ? id->z : 0;
}

// Writes sections after the payloads, hashing them for the footer.
class HashedOut {
 public:
  explicit HashedOut(BufferedOut& out) : out_(out) { XXH3_64bits_reset(state_.get()); }
  Status write(std::span<const std::uint8_t> bytes) {
    XXH3_64bits_update(state_.get(), bytes.data(), bytes.size());
    return out_.write(bytes);
  }
  std::uint64_t digest() const { return XXH3_64bits_digest(state_.get()); }

 private:
  struct Free {
    void operator()(XXH3_state_t* s) const { XXH3_freeState(s); }
  };
  BufferedOut& out_;
  std::unique_ptr<XXH3_state_t, Free> state_{XXH3_createState()};
};

class PartWriterImpl final : public PartWriter {
 public:
  PartWriterImpl(std::filesystem::path path, std::unique_ptr<TileSpool> spool)
      : path_(std::move(path)), spool_(std::move(spool)) {}
  ~PartWriterImpl() override { abort(); }

  Status add_tile(TileId id, std::span<const std::uint8_t> payload) override {
    if (Status s = spool_->add(id, payload); !s) return s;
    // The sum build_pyramid keeps for TilesetInfo::content_hash.
    if (auto header = parse_tile_header(payload)) {
      const std::uint64_t key[2] = {zxy_to_tile_id(id.z, id.x, id.y), header->checksum};
      content_sum_ += XXH3_64bits(key, sizeof key);
    }
    return {};
  }

  Result<PartStats> finish(std::span<const std::uint8_t> attachment,
                           const std::string& manifest_json) override {
    if (!spool_->close())
      return make_error(ErrorCode::invalid_argument, "finish() after finish() or abort()");
    Result<PartStats> r = write(attachment, manifest_json);
    spool_->release();
    return r;
  }

  void abort() noexcept override { spool_->release(); }

 private:
  Result<PartStats> write(std::span<const std::uint8_t> attachment,
                          const std::string& manifest_json) {
    const auto& records = spool_->records();
    PartStats stats;
    stats.tiles = records.size();
    stats.content_sum = content_sum_;
    Result<std::uint64_t> size = write_archive_file(path_, [&](BufferedOut& w) -> Status {
      // Payloads: each distinct one at its first appearance in tile-id order.
      std::unordered_map<std::uint64_t, std::uint64_t> offset_of;
      std::vector<std::uint64_t> offsets(records.size());
      for (std::size_t i = 0; i < records.size(); ++i) {
        const TileSpool::Blob& b = spool_->blob(records[i].blob);
        auto [it, fresh] = offset_of.try_emplace(records[i].blob, w.position());
        if (fresh) {
          if (Status s = w.copy_from(spool_->fd(), spool_->path(), b.spool_offset, b.length); !s)
            return s;
          ++stats.payloads;
          stats.data_bytes += b.length;
        }
        offsets[i] = it->second;
      }
      HashedOut h(w);
      std::vector<std::uint8_t> seg_bytes;
      std::uint64_t segments = 0;
      for (std::size_t i = 0; i < records.size(); ++i) {
        const TileSpool::Blob& b = spool_->blob(records[i].blob);
        std::uint8_t rec[kRecordBytes];
        put_u64(rec, records[i].tile_id);
        put_u64(rec + 8, offsets[i]);
        put_u32(rec + 16, b.length);
        put_u64(rec + 20, b.hash_low);
        put_u64(rec + 28, b.hash_high);
        if (Status s = h.write(rec); !s) return s;
        const std::uint8_t z = level_of(records[i].tile_id);
        if (i == 0 || z != seg_bytes[seg_bytes.size() - kSegmentBytes]) {
          seg_bytes.resize(seg_bytes.size() + kSegmentBytes);
          std::uint8_t* sp = seg_bytes.data() + seg_bytes.size() - kSegmentBytes;
          put_u64(sp, z);
          put_u64(sp + 8, records[i].tile_id);
          put_u64(sp + 24, i);
          ++segments;
        }
        std::uint8_t* sp = seg_bytes.data() + seg_bytes.size() - kSegmentBytes;
        put_u64(sp + 16, records[i].tile_id);
        put_u64(sp + 32, get_u64(sp + 32) + 1);
      }
      const std::span<const std::uint8_t> manifest(
          reinterpret_cast<const std::uint8_t*>(manifest_json.data()), manifest_json.size());
      for (std::span<const std::uint8_t> part :
           {std::span<const std::uint8_t>(seg_bytes), attachment, manifest}) {
        if (Status s = h.write(part); !s) return s;
      }
      std::uint8_t footer[kFooterBytes];
      std::memcpy(footer, kMagic, 8);
      put_u64(footer + 8, stats.data_bytes);
      put_u64(footer + 16, records.size());
      put_u64(footer + 24, segments);
      put_u64(footer + 32, attachment.size());
      put_u64(footer + 40, manifest.size());
      put_u64(footer + 48, content_sum_);
      if (Status s = h.write(std::span(footer, 56)); !s) return s;
      put_u64(footer + 56, h.digest());
      if (Status s = w.write(std::span(footer + 56, 8)); !s) return s;
      return {};
    });
    if (!size) return size.error();
    stats.file_bytes = *size;
    return stats;
  }

  std::filesystem::path path_;
  std::unique_ptr<TileSpool> spool_;
  std::atomic<std::uint64_t> content_sum_{0};
};

// A part's footer and sections, checked: what the merge keeps of each part.
struct PartLayout {
  PartInfo info;
  std::uint64_t records = 0;
  std::uint64_t index_offset = 0;
};

// Reads and checks a part's footer and every section after its payloads (streamed: the index may
// be large). Keeps the attachment only when asked. Without `check_index`, reads only the footer,
// the attachment and the manifest, unchecked (their checksum covers the index): for a part a
// ranged merge does not take tiles from (MergeOptions::index_needed), which the merges that do
// take its tiles check whole.
Result<PartLayout> scan_part(int fd, const std::filesystem::path& path, bool keep_attachment,
                             bool check_index = true) {
  struct stat st {};
  if (::fstat(fd, &st) != 0) return io_error("cannot stat", path, errno);
  const auto size = static_cast<std::uint64_t>(st.st_size);
  if (size < kFooterBytes) return corrupt(path, "shorter than its footer");
  std::uint8_t footer[kFooterBytes];
  if (Status s = pread_all(fd, footer, kFooterBytes, size - kFooterBytes, path); !s)
    return s.error();
  if (std::memcmp(footer, kMagic, 8) != 0) return corrupt(path, "no part footer at its end");
  PartLayout l;
  l.info.path = path;
  l.info.data_bytes = get_u64(footer + 8);
  l.records = get_u64(footer + 16);
  const std::uint64_t segments = get_u64(footer + 24), att = get_u64(footer + 32),
                      man = get_u64(footer + 40);
  l.info.content_sum = get_u64(footer + 48);
  const std::uint64_t limit = size - kFooterBytes;
  // Each term is checked against what is left, so no sum can overflow.
  std::uint64_t left = limit;
  for (const auto& [count, unit] : {std::pair{l.info.data_bytes, std::uint64_t{1}},
                                    {l.records, std::uint64_t{kRecordBytes}},
                                    {segments, std::uint64_t{kSegmentBytes}},
                                    {att, std::uint64_t{1}},
                                    {man, std::uint64_t{1}}}) {
    if (count > left / unit) return corrupt(path, "its sections do not fit its size");
    left -= count * unit;
  }
  if (left != 0) return corrupt(path, "its sections do not add up to its size");
  if (man > (16u << 20)) return corrupt(path, "a manifest over 16 MiB");
  if (att > (1u << 30)) return corrupt(path, "an attachment over 1 GiB");
  l.index_offset = l.info.data_bytes;
  l.info.tiles = l.records;

  const std::uint64_t seg_offset = l.index_offset + l.records * kRecordBytes;
  const std::uint64_t att_offset = seg_offset + segments * kSegmentBytes;
  if (!check_index) {
    std::vector<std::uint8_t> tail(static_cast<std::size_t>(limit - att_offset));
    if (Status s = pread_all(fd, tail.data(), tail.size(), att_offset, path); !s) return s.error();
    if (keep_attachment)
      l.info.attachment.assign(tail.begin(), tail.begin() + static_cast<std::ptrdiff_t>(att));
    l.info.manifest_json.assign(tail.begin() + static_cast<std::ptrdiff_t>(att), tail.end());
    return l;
  }
  XXH3_state_t* state = XXH3_createState();
  std::unique_ptr<XXH3_state_t, decltype(&XXH3_freeState)> guard(state, XXH3_freeState);
  XXH3_64bits_reset(state);
  // No larger than what is to read: a merge scans every part, most of them small, and a ranged
  // merge (one of many over the same parts) would otherwise spend its scan zeroing buffers.
  std::vector<std::uint8_t> buf(
      static_cast<std::size_t>(std::min<std::uint64_t>(1u << 20, limit - l.index_offset))),
      tail;
  std::uint64_t previous = 0;
  for (std::uint64_t at = l.index_offset; at < limit;) {
    const std::size_t n = static_cast<std::size_t>(std::min<std::uint64_t>(
        at < seg_offset
            ? std::min<std::uint64_t>(buf.size() / kRecordBytes * kRecordBytes, seg_offset - at)
            : buf.size(),
        limit - at));
    if (Status s = pread_all(fd, buf.data(), n, at, path); !s) return s.error();
    XXH3_64bits_update(state, buf.data(), n);
    if (at < seg_offset) {
      for (std::size_t k = 0; k < n; k += kRecordBytes) {
        const PartRecord r = decode_record(buf.data() + k);
        const bool first = at + k == l.index_offset;
        if (!first && r.tile_id <= previous) return corrupt(path, "its index is not in order");
        if (r.length == 0 || r.offset > l.info.data_bytes ||
            r.length > l.info.data_bytes - r.offset)
          return corrupt(path, "an index record points outside its payloads");
        if (first) l.info.first_tile_id = r.tile_id;
        previous = l.info.last_tile_id = r.tile_id;
      }
    } else {
      tail.insert(tail.end(), buf.begin(), buf.begin() + static_cast<std::ptrdiff_t>(n));
    }
    at += n;
  }
  XXH3_64bits_update(state, footer, 56);
  if (XXH3_64bits_digest(state) != get_u64(footer + 56))
    return corrupt(path, "the checksum of its index and manifest does not match");
  std::uint64_t expect_record = 0;
  for (std::uint64_t i = 0; i < segments; ++i) {
    const std::uint8_t* p = tail.data() + i * kSegmentBytes;
    PartInfo::Segment s{static_cast<std::uint8_t>(get_u64(p)), get_u64(p + 8), get_u64(p + 16),
                        get_u64(p + 24), get_u64(p + 32)};
    if (s.first_record != expect_record || s.records == 0 || s.records > l.records - expect_record)
      return corrupt(path, "its segment table does not match its index");
    expect_record += s.records;
    l.info.segments.push_back(s);
  }
  if (expect_record != l.records) return corrupt(path, "its segments do not cover its index");
  const std::size_t att_at = static_cast<std::size_t>(att_offset - seg_offset);
  if (keep_attachment)
    l.info.attachment.assign(tail.begin() + static_cast<std::ptrdiff_t>(att_at),
                             tail.begin() + static_cast<std::ptrdiff_t>(att_at + att));
  l.info.manifest_json.assign(tail.begin() + static_cast<std::ptrdiff_t>(att_at + att), tail.end());
  return l;
}

Result<Fd> open_part(const std::filesystem::path& path) {
  Fd fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC));
  if (fd.get() < 0) {
    if (errno == ENOENT)
      return make_error(ErrorCode::not_found, "part " + path.string() + " is missing");
    return io_error("cannot open part", path, errno);
  }
  return fd;
}

// Reads records [first, first + count) of a part's index in chunks.
Status read_records(int fd, const std::filesystem::path& path, std::uint64_t index_offset,
                    std::uint64_t first, std::uint64_t count,
                    const std::function<bool(const PartRecord&)>& visit) {
  // Sized to the stretch: a merge calls this for every segment of every part, most of them short.
  std::vector<std::uint8_t> buf(kRecordBytes *
                                static_cast<std::size_t>(std::min<std::uint64_t>(count, 8192)));
  for (std::uint64_t done = 0; done < count;) {
    const std::uint64_t n = std::min<std::uint64_t>(count - done, 8192);
    if (Status s = pread_all(fd, buf.data(), n * kRecordBytes,
                             index_offset + (first + done) * kRecordBytes, path);
        !s)
      return s;
    for (std::uint64_t k = 0; k < n; ++k)
      if (!visit(decode_record(buf.data() + k * kRecordBytes))) return {};
    done += n;
  }
  return {};
}

class PartReaderImpl final : public PartReader {
 public:
  PartReaderImpl(Fd fd, PartLayout layout) : fd_(std::move(fd)), layout_(std::move(layout)) {}
  const PartInfo& info() const override { return layout_.info; }
  Status for_each_record(std::uint64_t first, std::uint64_t last,
                         const std::function<bool(const PartRecord&)>& visit) const override {
    bool go_on = true;
    for (const PartInfo::Segment& s : layout_.info.segments) {
      if (s.last_tile_id < first || s.first_tile_id > last || !go_on) continue;
      Status st = read_records(fd_.get(), layout_.info.path, layout_.index_offset, s.first_record,
                               s.records, [&](const PartRecord& r) {
                                 if (r.tile_id < first) return true;
                                 if (r.tile_id > last) return go_on = false;
                                 return go_on = visit(r);
                               });
      if (!st) return st;
    }
    return {};
  }
  Status read_payload(const PartRecord& r, std::vector<std::uint8_t>& out) const override {
    out.resize(r.length);
    return pread_all(fd_.get(), out.data(), r.length, r.offset, layout_.info.path);
  }

 private:
  Fd fd_;
  PartLayout layout_;
};

// ---- merge
// ---------------------------------------------------------------------------------------

// What the merge keeps of each part once it is checked: a planet has ~10^5 parts, so no more
// (a std::filesystem::path with its parsed components is ~10 times the size of its text).
struct MergePart {
  std::string path;
  std::uint64_t index_offset = 0;
};

// Descriptors of the parts the merge reads, opened on demand and kept in a small LRU (a planet
// has far more parts than a process may open), each with its path for reads and messages.
class PartFiles {
 public:
  struct Open {
    int fd = -1;
    const std::filesystem::path* path = nullptr;  // valid until the next open()
  };
  explicit PartFiles(const std::vector<MergePart>& parts) : parts_(parts) {}
  Result<Open> open(std::uint32_t part) {
    if (auto it = open_.find(part); it != open_.end()) {
      lru_.splice(lru_.begin(), lru_, it->second.lru);
      return Open{it->second.fd.get(), &it->second.path};
    }
    if (open_.size() >= kMaxOpen) {
      open_.erase(lru_.back());
      lru_.pop_back();
    }
    std::filesystem::path path = parts_[part].path;
    Result<Fd> f = open_part(path);
    if (!f) return std::move(f).error();
    lru_.push_front(part);
    auto [it, _] = open_.emplace(part, Entry{std::move(*f), std::move(path), lru_.begin()});
    return Open{it->second.fd.get(), &it->second.path};
  }
  const std::string& name(std::uint32_t part) const { return parts_[part].path; }

 private:
  struct Entry {
    Fd fd;
    std::filesystem::path path;
    std::list<std::uint32_t>::iterator lru;
  };
  static constexpr std::size_t kMaxOpen = 64;
  const std::vector<MergePart>& parts_;
  std::list<std::uint32_t> lru_;
  std::unordered_map<std::uint32_t, Entry> open_;
};

struct PayloadRef {
  std::uint32_t part = 0;
  std::uint64_t offset = 0;
};

struct SegmentRef {
  std::uint32_t part = 0;
  PartInfo::Segment segment;
};

// One bit per tile in merge order (whether its payload is copied), spooled to an unlinked file.
class BitSpool {
 public:
  static Result<BitSpool> create(const std::filesystem::path& beside) {
    const std::filesystem::path dir =
        beside.has_parent_path() ? beside.parent_path() : std::filesystem::path(".");
    auto tmp = create_unique(dir, "." + beside.filename().string() + ".bits-", 0600);
    if (!tmp) return std::move(tmp).error();
    if (::unlink(tmp->second.c_str()) != 0) return io_error("cannot unlink", tmp->second, errno);
    return BitSpool(std::move(tmp->first), std::move(tmp->second));
  }
  Status put(bool bit) {
    if (bit)
      buf_[static_cast<std::size_t>(pos_ / 8 % (buf_.size()))] |= std::uint8_t(1u << (pos_ % 8));
    ++pos_;
    if (pos_ % (buf_.size() * 8) == 0) return flush();
    return {};
  }
  Status flush() {
    const std::uint64_t start = written_ * buf_.size();
    const std::uint64_t bytes = (pos_ - start * 8 + 7) / 8;
    if (bytes == 0) return {};
    if (Status s = pwrite_all(fd_.get(), buf_.data(), bytes, start, path_); !s) return s;
    if (pos_ % (buf_.size() * 8) == 0) {
      ++written_;
      std::fill(buf_.begin(), buf_.end(), 0);
    }
    return {};
  }
  // Reading back, in the same order, after flush().
  Result<bool> get() {
    const std::uint64_t block = read_ / (buf_.size() * 8);
    if (read_ % (buf_.size() * 8) == 0) {
      const std::uint64_t bytes = std::min<std::uint64_t>(buf_.size(), (pos_ - read_ + 7) / 8);
      if (Status s = pread_all(fd_.get(), buf_.data(), bytes, block * buf_.size(), path_); !s)
        return s.error();
    }
    const bool bit = (buf_[static_cast<std::size_t>(read_ / 8 % buf_.size())] >> (read_ % 8)) & 1u;
    ++read_;
    return bit;
  }

 private:
  BitSpool(Fd fd, std::filesystem::path path) : fd_(std::move(fd)), path_(std::move(path)) {
    buf_.assign(1u << 20, 0);
  }
  Fd fd_;
  std::filesystem::path path_;
  std::vector<std::uint8_t> buf_;
  std::uint64_t pos_ = 0, written_ = 0, read_ = 0;
};

// Serves payloads of one part at a time through a 4 MiB window (a part's fresh payloads are
// nearly always in increasing order).
class PayloadWindow {
 public:
  Status read(int fd, std::uint32_t part, const std::filesystem::path& path, std::uint64_t offset,
              std::uint32_t length, std::span<const std::uint8_t>& out) {
    if (part != part_ || offset < start_ || offset + length > start_ + size_) {
      const std::uint64_t want = std::max<std::uint64_t>(length, kWindow);
      buf_.resize(static_cast<std::size_t>(want));
      struct stat st {};
      if (::fstat(fd, &st) != 0) return io_error("cannot stat", path, errno);
      const std::uint64_t n =
          std::min<std::uint64_t>(want, static_cast<std::uint64_t>(st.st_size) - offset);
      if (n < length) return corrupt(path, "a payload runs past its end");
      if (Status s = pread_all(fd, buf_.data(), static_cast<std::size_t>(n), offset, path); !s)
        return s;
      part_ = part;
      start_ = offset;
      size_ = n;
    }
    out = std::span<const std::uint8_t>(buf_).subspan(static_cast<std::size_t>(offset - start_),
                                                      length);
    return {};
  }

 private:
  static constexpr std::uint64_t kWindow = 4u << 20;
  std::vector<std::uint8_t> buf_;
  std::uint32_t part_ = std::numeric_limits<std::uint32_t>::max();
  std::uint64_t start_ = 0, size_ = 0;
};

class Merger {
 public:
  explicit Merger(const MergeOptions& o)
      : o_(o), metadata_json_(o.metadata_json), files_(parts_), t0_(Clock::now()) {}

  Result<WriterStats> run() {
    if (Status s = scan(); !s) return s.error();
    Result<DirectoryBuilder> dirs = DirectoryBuilder::create(
        o_.archive.path, o_.archive.internal_compression, o_.archive.leaf_entries);
    if (!dirs) return std::move(dirs).error();
    Result<BitSpool> bits = BitSpool::create(o_.archive.path);
    if (!bits) return std::move(bits).error();
    WriterStats stats;
    if (Status s = lay_out(*dirs, *bits, stats); !s) return s.error();
    Result<std::vector<std::uint8_t>> root = dirs->finish();
    if (!root) return std::move(root).error();
    stats.tile_entries = dirs->entries();
    progress_.copying = true;
    progress_.bytes_total = stats.tile_bytes;
    Status written = write_archive(o_.archive, metadata_json_, *root, *dirs, stats,
                                   [&](BufferedOut& w) { return copy(w, *bits); });
    if (!written) return written.error();
    tick(true);
    return stats;
  }

 private:
  using Clock = std::chrono::steady_clock;

  Status scan() {
    if (o_.parts.empty()) return make_error(ErrorCode::invalid_argument, "no parts to merge");
    if (Status s = check_ranges(); !s) return s;
    std::uint64_t held = 0;  // the parts' tiles, in the ranges or not
    if (!o_.index_needed.empty() && o_.index_needed.size() != o_.parts.size())
      return make_error(ErrorCode::invalid_argument,
                        "index_needed names " + std::to_string(o_.index_needed.size()) +
                            " parts, the merge has " + std::to_string(o_.parts.size()));
    for (std::size_t i = 0; i < o_.parts.size(); ++i) {
      const std::string& name = o_.parts[i];
      const std::filesystem::path p = name;
      Result<Fd> fd = open_part(p);
      if (!fd) return fd.error();
      const bool needed = o_.index_needed.empty() || o_.index_needed[i];
      Result<PartLayout> l = scan_part(fd->get(), p, static_cast<bool>(o_.check_part), needed);
      if (!l) return l.error();
      if (o_.check_part)
        if (Status s = o_.check_part(l->info); !s) return s;
      if (!needed) continue;  // its manifest checked, its tiles in none of the ranges
      const auto index = static_cast<std::uint32_t>(parts_.size());
      held += l->records;
      progress_.records_checked += l->records;
      for (const PartInfo::Segment& s : l->info.segments) {
        if (o_.ranges.empty()) {
          segments_.push_back({index, s});
          progress_.tiles_total += s.records;
        } else if (Status st = clip(fd->get(), p, l->index_offset, index, s); !st) {
          return st;
        }
      }
      parts_.push_back({name, l->index_offset});
      if (cancelled()) return make_error(ErrorCode::cancelled, "merge cancelled");
    }
    segments_.shrink_to_fit();
    std::sort(segments_.begin(), segments_.end(), [](const SegmentRef& a, const SegmentRef& b) {
      return a.segment.first_tile_id < b.segment.first_tile_id;
    });
    for (std::size_t i = 1; i < segments_.size(); ++i)
      if (segments_[i].segment.first_tile_id <= segments_[i - 1].segment.last_tile_id)
        return make_error(ErrorCode::invalid_argument,
                          "parts " + files_.name(segments_[i - 1].part) + " and " +
                              files_.name(segments_[i].part) +
                              " hold overlapping tiles (tile ids " +
                              std::to_string(segments_[i].segment.first_tile_id) + "..)");
    if (held == 0) return make_error(ErrorCode::invalid_argument, "the parts hold no tiles");
    // Not an error of the parts: an archive of a set whose tiles have no data, which the caller
    // skips.
    if (progress_.tiles_total == 0)
      return make_error(ErrorCode::not_found, std::string(kNoTileInRanges));
    if (o_.check_parts) return o_.check_parts(metadata_json_);
    return {};
  }

  Status check_ranges() const {
    const std::vector<TileIdRange>& r = o_.ranges;
    for (std::size_t i = 0; i < r.size(); ++i) {
      if (r[i].first > r[i].last)
        return make_error(ErrorCode::invalid_argument,
                          "tile id range " + std::to_string(r[i].first) + ".." +
                              std::to_string(r[i].last) + " ends before it starts");
      if (i > 0 && r[i].first <= r[i - 1].last)
        return make_error(
            ErrorCode::invalid_argument,
            "tile id ranges must be sorted and disjoint: " + std::to_string(r[i].first) + ".." +
                std::to_string(r[i].last) + " follows " + std::to_string(r[i - 1].first) + ".." +
                std::to_string(r[i - 1].last));
    }
    return {};
  }

  // Index of the first record in [lo, hi) of a part whose tile id exceeds `id` (hi if none), by
  // binary search: one pread of a record per probe, never the whole index.
  Result<std::uint64_t> first_record_after(int fd, const std::filesystem::path& path,
                                           std::uint64_t index_offset, std::uint64_t lo,
                                           std::uint64_t hi, std::uint64_t id) {
    while (lo < hi) {
      const std::uint64_t mid = lo + (hi - lo) / 2;
      Result<PartRecord> r = record_at(fd, path, index_offset, mid);
      if (!r) return std::move(r).error();
      if (r->tile_id > id)
        hi = mid;
      else
        lo = mid + 1;
    }
    return lo;
  }

  Result<PartRecord> record_at(int fd, const std::filesystem::path& path,
                               std::uint64_t index_offset, std::uint64_t i) {
    std::uint8_t rec[kRecordBytes];
    if (Status s = pread_all(fd, rec, kRecordBytes, index_offset + i * kRecordBytes, path); !s)
      return s.error();
    ++progress_.records_read;
    return decode_record(rec);
  }

  // Adds the stretches of one segment of a part that lie in the ranges. A range that holds the
  // whole segment (a shard inside the archive's sub-pyramid) costs no read.
  Status clip(int fd, const std::filesystem::path& path, std::uint64_t index_offset,
              std::uint32_t part, const PartInfo::Segment& seg) {
    const std::uint64_t end = seg.first_record + seg.records;
    // The first range that does not end before the segment starts.
    auto r = std::lower_bound(
        o_.ranges.begin(), o_.ranges.end(), seg.first_tile_id,
        [](const TileIdRange& range, std::uint64_t id) { return range.last < id; });
    // Records before `from` lie before the current range (the ranges are sorted).
    for (std::uint64_t from = seg.first_record;
         r != o_.ranges.end() && r->first <= seg.last_tile_id; ++r) {
      std::uint64_t lo = from, hi = end;
      if (r->first > seg.first_tile_id) {
        Result<std::uint64_t> at = first_record_after(fd, path, index_offset, lo, hi, r->first - 1);
        if (!at) return at.error();
        lo = *at;
      }
      if (r->last < seg.last_tile_id) {
        Result<std::uint64_t> at = first_record_after(fd, path, index_offset, lo, hi, r->last);
        if (!at) return at.error();
        hi = *at;
      }
      from = hi;
      if (lo == hi) continue;
      PartInfo::Segment piece = seg;
      piece.first_record = lo;
      piece.records = hi - lo;
      if (lo != seg.first_record) {
        Result<PartRecord> first = record_at(fd, path, index_offset, lo);
        if (!first) return first.error();
        piece.first_tile_id = first->tile_id;
      }
      if (hi != end) {
        Result<PartRecord> last = record_at(fd, path, index_offset, hi - 1);
        if (!last) return last.error();
        piece.last_tile_id = last->tile_id;
      }
      segments_.push_back({part, piece});
      progress_.tiles_total += piece.records;
    }
    return {};
  }

  bool cancelled() const { return o_.cancel && o_.cancel->load(); }

  void tick(bool force = false) {
    if (!o_.on_progress) return;
    const auto now = Clock::now();
    if (!force && now - last_ < std::chrono::milliseconds(100)) return;
    last_ = now;
    progress_.seconds = std::chrono::duration<double>(now - t0_).count();
    o_.on_progress(progress_);
  }

  // Whether two payloads with equal keys are equal: within a part, distinct offsets are distinct
  // bytes (a part stores each payload once); across parts the bytes are compared.
  Result<bool> same(const PayloadRef& a, const PayloadRef& b, std::uint32_t length) {
    if (a.part == b.part) return a.offset == b.offset;
    Result<PartFiles::Open> fa = files_.open(a.part);
    if (!fa) return std::move(fa).error();
    cmp_a_.resize(length);
    if (Status s = pread_all(fa->fd, cmp_a_.data(), length, a.offset, *fa->path); !s)
      return s.error();
    Result<PartFiles::Open> fb = files_.open(b.part);
    if (!fb) return std::move(fb).error();
    cmp_b_.resize(length);
    if (Status s = pread_all(fb->fd, cmp_b_.data(), length, b.offset, *fb->path); !s)
      return s.error();
    return std::memcmp(cmp_a_.data(), cmp_b_.data(), length) == 0;
  }

  // Calls visit(part, record) for every tile in tile-id order.
  template <typename Visit>
  Status for_each_tile(Visit&& visit) {
    for (const SegmentRef& seg : segments_) {
      Result<PartFiles::Open> f = files_.open(seg.part);
      if (!f) return f.error();
      // visit() may open other parts (to compare payloads): keep this one's path.
      const std::filesystem::path path = *f->path;
      Status inner;
      Status st = read_records(f->fd, path, parts_[seg.part].index_offset, seg.segment.first_record,
                               seg.segment.records, [&](const PartRecord& r) {
                                 inner = visit(seg.part, r);
                                 return static_cast<bool>(inner);
                               });
      if (!st) return st;
      if (!inner) return inner;
      progress_.records_read += seg.segment.records;
      if (cancelled()) return make_error(ErrorCode::cancelled, "merge cancelled");
      tick();
    }
    return {};
  }

  Status lay_out(DirectoryBuilder& dirs, BitSpool& bits, WriterStats& stats) {
    DataLayout<PayloadRef> layout;
    std::uint64_t previous = 0;
    Status st = for_each_tile([&](std::uint32_t part, const PartRecord& r) -> Status {
      if (stats.addressed_tiles > 0 && r.tile_id <= previous)
        return make_error(ErrorCode::corrupt, "part " + files_.name(part) + " repeats tile id " +
                                                  std::to_string(r.tile_id));
      previous = r.tile_id;
      const PayloadKey key{r.hash_low, r.hash_high, r.length};
      auto placed = layout.place(
          key, PayloadRef{part, r.offset},
          [&](const PayloadRef& a, const PayloadRef& b) { return same(a, b, r.length); });
      if (!placed) return placed.error();
      if (Status s = bits.put(placed->fresh); !s) return s;
      if (Status s = dirs.add(r.tile_id, placed->offset, r.length); !s) return s;
      ++stats.addressed_tiles;
      ++progress_.tiles_done;
      return {};
    });
    if (!st) return st;
    stats.tile_bytes = layout.data_size();
    stats.tile_contents = layout.contents();
    return bits.flush();
  }

  // Without verification: runs of fresh payloads contiguous in one part, copied in the kernel.
  Status clone(BufferedOut& w, BitSpool& bits) {
    std::uint32_t part = 0;
    std::uint64_t begin = 0, end = 0;
    const auto flush = [&]() -> Status {
      if (end == begin) return {};
      Result<PartFiles::Open> f = files_.open(part);
      if (!f) return f.error();
      progress_.bytes_copied += end - begin;
      return w.clone_from(f->fd, *f->path, begin, end - begin);
    };
    Status st = for_each_tile([&](std::uint32_t p, const PartRecord& r) -> Status {
      Result<bool> fresh = bits.get();
      if (!fresh) return fresh.error();
      if (!*fresh) return {};
      if (p == part && r.offset == end) {
        end += r.length;
        return {};
      }
      if (Status s = flush(); !s) return s;
      part = p;
      begin = r.offset;
      end = r.offset + r.length;
      return {};
    });
    if (!st) return st;
    return flush();
  }

  Status copy(BufferedOut& w, BitSpool& bits) {
    if (!o_.verify) return clone(w, bits);
    PayloadWindow window;
    const std::uint64_t start = w.position();
    return for_each_tile([&](std::uint32_t part, const PartRecord& r) -> Status {
      Result<bool> fresh = bits.get();
      if (!fresh) return fresh.error();
      if (!*fresh) return {};
      Result<PartFiles::Open> f = files_.open(part);
      if (!f) return f.error();
      std::span<const std::uint8_t> bytes;
      if (Status s = window.read(f->fd, part, *f->path, r.offset, r.length, bytes); !s) return s;
      const XXH128_hash_t h = XXH3_128bits(bytes.data(), bytes.size());
      if (h.low64 != r.hash_low || h.high64 != r.hash_high) {
        Result<TileId> id = tile_id_to_zxy(r.tile_id);
        return corrupt(files_.name(part), "the payload of tile " +
                                              (id ? tile_name(*id) : std::to_string(r.tile_id)) +
                                              " does not match its checksum");
      }
      progress_.bytes_copied = w.position() + r.length - start;
      return w.write(bytes);
    });
  }

  const MergeOptions& o_;
  std::string metadata_json_;
  std::vector<MergePart> parts_;
  std::vector<SegmentRef> segments_;
  PartFiles files_;
  std::vector<std::uint8_t> cmp_a_, cmp_b_;
  MergeProgress progress_;
  Clock::time_point t0_, last_{};
};

}  // namespace

Result<std::unique_ptr<PartWriter>> PartWriter::create(std::filesystem::path path) {
  if (path.empty() || !path.has_filename())
    return make_error(ErrorCode::invalid_argument,
                      "part path '" + path.string() + "' names no file");
  Result<std::unique_ptr<TileSpool>> spool = TileSpool::create(path);
  if (!spool) return std::move(spool).error();
  return std::unique_ptr<PartWriter>(new PartWriterImpl(std::move(path), std::move(*spool)));
}

Result<PartInfo> read_part_info(const std::filesystem::path& path) {
  Result<Fd> fd = open_part(path);
  if (!fd) return std::move(fd).error();
  Result<PartLayout> l = scan_part(fd->get(), path, true);
  if (!l) return std::move(l).error();
  return std::move(l->info);
}

Result<std::unique_ptr<PartReader>> PartReader::open(const std::filesystem::path& path) {
  Result<Fd> fd = open_part(path);
  if (!fd) return std::move(fd).error();
  Result<PartLayout> l = scan_part(fd->get(), path, true);
  if (!l) return std::move(l).error();
  return std::unique_ptr<PartReader>(new PartReaderImpl(std::move(*fd), std::move(*l)));
}

Result<WriterStats> merge_parts(const MergeOptions& options) {
  if (options.archive.path.empty() || !options.archive.path.has_filename())
    return make_error(ErrorCode::invalid_argument,
                      "archive path '" + options.archive.path.string() + "' names no file");
  Merger m(options);
  return m.run();
}

}  // namespace vts::archive

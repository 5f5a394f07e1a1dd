// The spool behind archive::Writer and PartWriter (pmtiles_io.hpp).
#include <xxhash.h>

#include <mutex>

#include "pmtiles_io.hpp"

namespace vts::archive::detail {

Result<std::unique_ptr<TileSpool>> TileSpool::create(const std::filesystem::path& destination) {
  const std::filesystem::path dir =
      destination.has_parent_path() ? destination.parent_path() : std::filesystem::path(".");
  Result<std::pair<Fd, std::filesystem::path>> spool =
      create_unique(dir, "." + destination.filename().string() + ".spool-", 0600);
  if (!spool) return std::move(spool).error();
  // Unlinked at once: the descriptor keeps the data, and no crash can leave the spool behind.
  if (::unlink(spool->second.c_str()) != 0) return io_error("cannot unlink", spool->second, errno);
  return std::unique_ptr<TileSpool>(
      new TileSpool(std::move(spool->first), std::move(spool->second)));
}

Status TileSpool::add(TileId id, std::span<const std::uint8_t> payload) {
  if (id.z > 31 || std::uint64_t{id.x} >= (std::uint64_t{1} << id.z) ||
      std::uint64_t{id.y} >= (std::uint64_t{1} << id.z)) {
    return make_error(ErrorCode::invalid_argument, "tile " + tile_name(id) + " does not exist");
  }
  if (payload.empty()) {
    // PMTiles entries must have a length > 0; an absent tile is expressed by not adding it.
    return make_error(ErrorCode::invalid_argument,
                      "tile " + tile_name(id) + " has an empty payload");
  }
  if (payload.size() > std::numeric_limits<std::uint32_t>::max()) {
    return make_error(ErrorCode::too_large,
                      "tile " + tile_name(id) + " payload exceeds 4 GiB (the PMTiles limit)");
  }
  const std::uint64_t tile_id = zxy_to_tile_id(id.z, id.x, id.y);
  const XXH128_hash_t hash = XXH3_128bits(payload.data(), payload.size());  // outside the lock

  std::lock_guard lock(mutex_);
  if (closed_) return make_error(ErrorCode::invalid_argument, "add_tile after finish() or abort()");
  const std::uint64_t key = tile_id + 1;  // ids are < 2^63, so + 1 never wraps to the empty 0
  if (tile_ids_.find(mix(key), [&](std::uint64_t v) { return v == key; }) != 0) {
    return make_error(ErrorCode::invalid_argument, "tile " + tile_name(id) + " added twice");
  }

  std::uint64_t blob = 0;
  Status compare_status;
  const std::uint64_t found = blob_index_.find(hash.low64, [&](std::uint64_t v) {
    const Blob& b = blobs_[v - 1];
    if (b.hash_high != hash.high64 || b.hash_low != hash.low64 || b.length != payload.size()) {
      return false;
    }
    // Equal 128-bit hashes: confirm with the bytes, so a collision can never swap tiles.
    Result<bool> same = same_bytes(b, payload);
    if (!same) {
      compare_status = std::move(same).error();
      return true;
    }
    return *same;
  });
  if (!compare_status) return compare_status;
  if (found != 0) {
    blob = found - 1;
  } else {
    if (Status s = pwrite_all(fd_.get(), payload.data(), payload.size(), size_, path_); !s) {
      return s;
    }
    blob = blobs_.size();
    blobs_.push_back(
        Blob{size_, hash.low64, hash.high64, static_cast<std::uint32_t>(payload.size())});
    size_ += payload.size();
    blob_index_.insert(hash.low64, blob + 1,
                       [&](std::uint64_t v) { return blobs_[v - 1].hash_low; });
  }
  records_.push_back(Record{tile_id, blob});
  tile_ids_.insert(mix(key), key, [](std::uint64_t v) { return mix(v); });
  return {};
}

Result<bool> TileSpool::same_bytes(const Blob& b, std::span<const std::uint8_t> payload) {
  constexpr std::size_t kChunk = 1u << 16;
  scratch_.resize(std::min<std::size_t>(kChunk, payload.size()));
  for (std::size_t done = 0; done < payload.size();) {
    const std::size_t n = std::min(kChunk, payload.size() - done);
    if (Status s = pread_all(fd_.get(), scratch_.data(), n, b.spool_offset + done, path_); !s) {
      return s.error();
    }
    if (std::memcmp(scratch_.data(), payload.data() + done, n) != 0) return false;
    done += n;
  }
  return true;
}

bool TileSpool::close() {
  std::lock_guard lock(mutex_);
  if (closed_) return false;
  closed_ = true;
  tile_ids_.release();
  blob_index_.release();
  scratch_ = {};
  std::sort(records_.begin(), records_.end(),
            [](const Record& a, const Record& b) { return a.tile_id < b.tile_id; });
  return true;
}

void TileSpool::release() noexcept {
  std::lock_guard lock(mutex_);
  closed_ = true;
  records_ = {};
  blobs_ = {};
  tile_ids_.release();
  blob_index_.release();
  scratch_ = {};
  fd_.reset();  // already unlinked: closing frees its space
}

}  // namespace vts::archive::detail

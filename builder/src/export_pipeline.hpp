// What the exports share (export.cpp, export_mbtiles.cpp, export_gtiff.cpp): where output tiles
// go (TileSink), and the pipeline that feeds jobs from the calling thread to the encoder pool
// through its bounded queue (Feeder), stopping at the first error or at cancellation.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <thread>

#include "vts/archive/pmtiles.hpp"
#include "vts/base/result.hpp"
#include "vts/protocol/geometry.hpp"
#include "vts/protocol/tiling.hpp"
#include "work_queue.hpp"

namespace vts {
inline namespace builder {
namespace detail {

// Where output tiles go: a PMTiles writer, a folder or an MBTiles file.
class TileSink {
 public:
  virtual ~TileSink() = default;
  // Thread-safe. `id` is XYZ (row 0 at the top).
  virtual Status put(TileId id, std::span<const std::uint8_t> bytes) = 0;
  virtual Result<archive::WriterStats> finish(const std::string& metadata_json) = 0;
};

// What an MBTiles file's metadata table says (MBTiles 1.3).
struct MbtilesMetadata {
  std::string name, description, attribution, format;  // format: png, jpg or webp
  LonLatBounds bounds;
  double center_lon = 0, center_lat = 0;
  int center_zoom = 0, min_zoom = 0, max_zoom = 0;
};

// An MBTiles 1.3 database written into `path`, an empty file (the caller's temporary, which it
// renames into place: base/file_io.hpp write_file_atomically): the metadata rows, then one `tiles`
// row per put() (its TMS row: 2^z - 1 - y), in one transaction that finish() commits (its JSON
// argument is not used: MBTiles has its own metadata). io naming the file on any SQLite error.
Result<std::unique_ptr<TileSink>> open_mbtiles_sink(const std::filesystem::path& path,
                                                    const MbtilesMetadata& metadata);

// The first error of any worker, and the flag that stops the walk.
class FirstError {
 public:
  void set(Error e) {
    std::lock_guard lock(mutex_);
    if (!error_) error_ = std::move(e);
    failed_.store(true);
  }
  bool failed() const { return failed_.load(); }
  std::optional<Error> take() {
    std::lock_guard lock(mutex_);
    return std::move(error_);
  }

 private:
  std::mutex mutex_;
  std::optional<Error> error_;
  std::atomic<bool> failed_{false};
};

struct Counters {
  std::atomic<std::uint64_t> done{0}, written{0}, skipped{0};
};

struct FeederOptions {
  unsigned threads = 0;  // 0 = one per hardware thread
  const std::atomic<bool>* cancel = nullptr;
  // Called from the calling thread about ten times a second and once at the end.
  std::function<void(std::uint64_t done, std::uint64_t total)> on_progress;
};

// The pool the walks feed from the calling thread: the first error stops them, so does
// cancellation; progress (counters.done of total) is reported from the calling thread.
class Feeder {
 public:
  Feeder(const FeederOptions& o, const Counters& c, std::uint64_t total)
      : options_(o), counters_(c), total_(total) {
    auto q =
        start_encoders(o.threads ? o.threads : std::max(1u, std::thread::hardware_concurrency()));
    if (q)
      queue_ = std::move(q).value();
    else
      first_.set(std::move(q).error());
  }

  // Queues the job (blocking while the queue is full); false when the walk should stop (an
  // error, the pool's threads not starting included, or cancellation).
  bool submit(std::function<Status()> job) {
    if (first_.failed()) return false;
    if (options_.cancel && options_.cancel->load()) {
      first_.set(make_error(ErrorCode::cancelled, "export cancelled"));
      return false;
    }
    queue_->submit([this, job = std::move(job)] {
      if (first_.failed()) return;
      if (Status s = job(); !s) first_.set(s.error());
    });
    if (options_.on_progress && Clock::now() - last_ > std::chrono::milliseconds(100)) {
      last_ = Clock::now();
      options_.on_progress(counters_.done.load(), total_);
    }
    return true;
  }
  // Whether a job failed (jobs check it to stop early).
  bool failed() const { return first_.failed(); }
  // Waits for the queued jobs; the first error, else the walk's own status.
  Status finish(Status walked) {
    if (queue_) queue_->join();
    if (auto e = first_.take()) return *e;
    if (!walked) return walked;
    if (options_.on_progress) options_.on_progress(counters_.done.load(), total_);
    return {};
  }

 private:
  using Clock = std::chrono::steady_clock;
  const FeederOptions& options_;
  const Counters& counters_;
  std::uint64_t total_;
  Clock::time_point last_ = Clock::now();
  FirstError first_;
  // Last: joined before the members its jobs use go away. Null when its threads did not start.
  std::unique_ptr<WorkerPool> queue_;
};

}  // namespace detail
}  // namespace builder
}  // namespace vts

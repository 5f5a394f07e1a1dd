// The load engine of `vts loadtest`: simulated viewers streaming tiles through the real client
// stack (TileSource -> TileCache: fetcher, RAM and disk caches), driven by tile demand the caller
// computes per viewer and frame (the CLI uses the renderer's CPU demand simulator on a camera path;
// this library knows no cameras), measured per request and per camera move.
//
// Each viewer has its own source and TileCache (caches per CacheMode) and runs the GL viewer's own
// streaming policy, renderer::TileStream, over a physical texture of `resident_tiles` slots
// (SlotCache's rules: least recently used first, none used in the last `keep_frames` frames).
// Frame f of every viewer is due at start + f / fps; a driver thread that falls more than a frame
// behind skips to the frame due now (counted as late frames), as a renderer's frame rate drops,
// rather than replaying a backlog. At each frame the viewer takes its demand and
//   - hands it to its stream as the wanted list: every tile neither resident nor on its way nor
//     absent is asked for (in the list's order), what is on its way and no longer wanted is
//     cancelled; a tile whose request failed is asked for again after a back-off (250 ms,
//     doubling to 8 s), not at every frame. An answer takes a slot when it arrives;
//   - tracks camera moves: a move starts at a frame whose demand says `move` (and at frame 0). Its
//     time to first visible tile is from the move's due time to the earliest arrival, after the
//     move, among the frame's direct tiles (0 when the whole view was already resident; a coarse
//     tile held from before shows nothing new and does not count); its time to full resolution
//     runs until the latest arrival, at the first frame whose direct tiles are all resident
//     (absent tiles count as resolved). A move that is not complete after `view_timeout`, or when
//     the next move starts, is counted as incomplete and not in the histograms.
//
// Errors are counted by kind (LoadReport::errors_by_kind): "http_NNN" for an HTTP status >= 400,
// "connect" (refused, unreachable), "timeout", "truncated" (the body ended before its length),
// "reset", "empty_reply", "undecodable" (decode), "checksum" and "corrupt" (our tiles only: image
// tiles have no checksum), else the error code's name.
//
// Latency is measured from the intended send time, never from when a busy driver thread got
// round to it, so a stalled server or a lagging load generator cannot hide latency (no
// coordinated omission):
//   - closed loop (rate == 0): requests are issued at their frame; the intended time is the
//     frame's due time;
//   - open loop (rate > 0): the viewers' requests join one queue that a dispatcher drains at
//     exactly `rate` requests a second, whatever the responses; the intended time is the slot's
//     time. A slot with nothing queued is counted: before the first request is sent as a
//     start-up slot (the viewers still working out their first frame), after it as an idle slot
//     (the demand did not fill the rate).
// queue time = intended time to the request going on the wire (our queue, the fetcher's queue);
// ttfb = intended time to the first response byte (network only); total = intended time to the
// tile (or error) in hand. Cache hits have queue time and total, no ttfb.
//
// Threads: run_load_test() blocks. The run's loops run on one vts::WorkerPool: one driver per
// thread (`threads`) and, in open loop, the dispatcher; the calling thread reports progress and
// drains. `demand` is called from the driver threads, for different viewers concurrently but never
// twice at once for one viewer; `progress` from the calling thread.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "vts/base/result.hpp"
#include "vts/client/source.hpp"
#include "vts/loadtest/load_report.hpp"
#include "vts/protocol/geometry.hpp"
#include "vts/renderer/tile_stream.hpp"

namespace vts::loadtest {

// A tile a viewer's frame wants: the renderer's own request (tile, pixel coverage, direct).
using DemandTile = renderer::TileRequest;

struct ViewerDemand {
  std::vector<DemandTile> tiles;  // ancestors included, coarse first (FeedbackProcessor's order)
  bool move = false;              // the camera jumped / started a new view at this frame
  // The camera had not moved since the viewer's previous frame, so its tiles are the previous
  // frame's, not simulated again (a view's demand depends only on its camera).
  bool reused = false;
};

// `bias`: the viewer's mip bias (its TileStream's), to reduce the feedback with, as the GL viewer
// does.
using DemandFn =
    std::function<Result<ViewerDemand>(std::uint32_t viewer, std::uint64_t frame, double bias)>;

enum class CacheMode : std::uint8_t {
  none,  // every tile from the network (the target may itself be a cache daemon)
  ram,   // a RAM cache per viewer
  disk,  // RAM + a disk cache per viewer (cache_dir/viewer-N)
};

struct LoadProgress {
  double elapsed_s = 0;
  std::uint64_t requests = 0, errors = 0, in_flight = 0, moves_complete = 0;
  double requests_per_s = 0;      // over the last second
  std::uint64_t p99_ns = 0;       // total latency, last second
  std::uint64_t late_frames = 0;  // frames skipped because a driver thread fell a frame behind
};

// The progress line of `vts loadtest` for one LoadProgress: "[ 12s/30s] 5300 requests (441/s), 0
// errors, 12 in flight, p99 8.21 ms, 96 moves at full resolution[, N late frames]". A second in
// which no request completed has no latency to show: "no responses this second" stands in its
// place (never "p99 0 ns").
std::string progress_text(const LoadProgress& p, double duration_s);

struct LoadTestOptions {
  std::string target;  // any location open_source() accepts
  client::SourceOptions source;
  std::uint32_t viewers = 8;
  double fps = 30;
  double duration_s = 30;
  double rate = 0;  // > 0: open loop at this many requests a second
  CacheMode cache = CacheMode::none;
  std::filesystem::path cache_dir;    // CacheMode::disk: viewer folders are made under it
  std::size_t ram_bytes = 64u << 20;  // per viewer, CacheMode::ram and ::disk
  std::size_t resident_tiles = 256;   // per viewer: physical texture slots (as the viewer's)
  std::uint32_t keep_frames = 8;      // as VirtualTextureOptions::keep_frames
  std::chrono::milliseconds view_timeout{10000};
  std::chrono::milliseconds drain_timeout{5000};  // at the end, for requests still on their way
  int threads = 0;                                // driver threads; 0: one per core
  // Image targets (SourceInfo::image_format): decode every tile from the network (PNG, JPEG,
  // WebP); one that does not decode is an error of kind "undecodable" (and is not resident).
  bool decode = false;
  // Report fields passed through.
  std::string title, path_name, command_line;
  std::function<void(const LoadProgress&)> progress;  // about once a second
  const std::atomic<bool>* stop = nullptr;            // set to end the run early (SIGINT)
  // Every decision of each viewer's tile stream, in order per viewer (from the driver and the
  // cache's threads, never twice at once for one viewer): what VirtualTextureOptions::trace gives
  // for the GL viewer.
  std::function<void(std::uint32_t viewer, const renderer::StreamEvent&)> trace;
  // The run's time: every time it measures is read from `now`, and every wait (a frame's due time,
  // an open-loop slot, the progress and drain polls) is a `sleep_until`, called from the driver
  // threads, the dispatcher and the calling thread, and from no other thread. Unset:
  // std::chrono::steady_clock::now and std::this_thread::sleep_until. Tests pass a virtual clock
  // (vts::test::VirtualClock) so that a run of seconds takes none and its figures are exact.
  std::function<std::chrono::steady_clock::time_point()> now;
  std::function<void(std::chrono::steady_clock::time_point)> sleep_until;
};

// Extra figures of a run that LoadReport has no field for.
struct LoadRunStats {
  std::uint64_t frames = 0, late_frames = 0;
  std::uint64_t moves_incomplete = 0;  // timed out or superseded before full resolution
  std::uint64_t idle_slots = 0;        // open loop: slots with nothing to send after the first
  std::uint64_t startup_slots = 0;     // open loop: slots that passed before the first request
  std::uint64_t abandoned = 0;         // still on their way at the end of the drain
  double demand_cpu_ms_per_frame = 0;  // mean CPU time of the driver thread in the demand function
  std::uint64_t demand_reused = 0;     // frames whose camera had not moved (ViewerDemand::reused)
};

struct LoadTestResult {
  LoadReport report;
  LoadRunStats run;
};

// invalid_argument for options out of range (no viewers, fps or duration not positive, a
// negative rate, disk mode without cache_dir); the error of open_source() when the target cannot
// be opened (each viewer opens it: the first failure ends the run before it starts), or of the
// demand function (the run stops and reports it).
Result<LoadTestResult> run_load_test(const LoadTestOptions& options, const DemandFn& demand);

}  // namespace vts::loadtest

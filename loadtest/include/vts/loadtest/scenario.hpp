// What `vts loadtest` runs, from its arguments: the target and the viewers' caches, the viewers'
// tile demand on camera paths (the renderer's camera paths and CPU demand simulator, no GL), and
// the simulation figures of the result as JSON and as a terminal line.
#pragma once

#include <cstdint>
#include <string>

#include <nlohmann/json.hpp>

#include "vts/base/result.hpp"
#include "vts/loadtest/load_test.hpp"
#include "vts/protocol/geometry.hpp"

namespace vts::loadtest {

// Where requests go and which caches the viewers have, as `vts loadtest` names them.
struct LoadTarget {
  std::string url;             // the tileset under test
  std::string cache = "none";  // none, ram, disk or daemon
  std::string cache_dir;       // disk: folder for the viewers' caches
  std::string daemon;          // daemon: the cache daemon (in front of url) to go through
};

// Sets options.target, .cache and .cache_dir. invalid_argument when daemon has no daemon URL or
// disk no folder (naming the --daemon / --cache-dir arguments).
Status apply_target(const LoadTarget& target, LoadTestOptions& options);

// The tileset's geometry, from one look at options.target (open_source's errors).
Result<Geometry> target_geometry(const LoadTestOptions& options);

struct CameraDemandOptions {
  std::string path = "flyover";  // a preset (CameraPath::preset_names()) or a camera-path file
  std::uint32_t viewers = 8;
  double fps = 30, duration_s = 30;
  std::uint64_t seed = 1;  // presets: viewer v's places come from seed * 1000003 + v
  int width = 1280, height = 720;
  int feedback = 8, anisotropy = 8;  // the demand simulator's DemandOptions
  // One generator of several: its viewers are [first_viewer, first_viewer + viewers) of
  // total_viewers (0: viewers), so viewers replaying a camera file spread along it over all the
  // generators, not each generator's own.
  std::uint32_t first_viewer = 0, total_viewers = 0;
};

struct CameraDemand {
  DemandFn demand;        // as run_load_test() calls it; owns the paths and simulators
  std::string path_name;  // the preset's name or the file's name
};

// One path and demand simulator per viewer. Presets cover the run; a file path loops, and the
// viewers replaying it start evenly spread along it. Errors: not_found for a --path that is
// neither a preset nor a readable file (listing the presets), the path's parse error (naming the
// file), the simulator's.
Result<CameraDemand> camera_demand(const Geometry& geometry, const CameraDemandOptions& options);

// The figures of a run that the report has no field for, and the simulation settings:
// {viewer_frames, late_frames, moves_incomplete, idle_slots, startup_slots, abandoned,
// demand_cpu_ms_per_frame, demand_reused_frames, viewport [w, h], feedback_divisor, anisotropy,
// cache, retries}.
nlohmann::json simulation_json(const LoadRunStats& run, const CameraDemandOptions& camera,
                               const std::string& cache, int retries);
// "simulation: N viewer-frames (L late), demand ..." with the idle slots when open loop; with a
// newline.
std::string simulation_line(const LoadRunStats& run, bool open_loop);

}  // namespace vts::loadtest

// `vts bench accuracy`: what accuracy costs in time (docs/ACCURACY.md). Every knob of vtstream
// that trades fidelity for speed is measured on the same real image and reported as a table — per
// setting: the accuracy figure, the time it costs and the bytes it moves — with plots of the
// trade-off curves:
//   1. codec    codec x quality: lossless (zstd levels, filter on/off) and bc1 (fast/high/best):
//               PSNR and max error against the source, bytes per tile, encode/decode/upload
//               ms per tile, GPU bytes per tile;
//   2. feedback feedback resolution 1/1 ... 1/16: needed tiles found (against 1/1), frames to
//               convergence after a jump, CPU ms per frame;
//   3. filtering bilinear, trilinear, anisotropic 2/4/8: error against a supersampled reference of
//               the same view, frame time;
//   4. addressing float32 UV vs integer + fraction texel addresses at virtual sizes 2^15 ... 2^25:
//               max texel error against double precision, shader cost;
//   5. downsample the builder's downsampling filter: PSNR of each level against a high-quality
//               resize of the source, build time;
//   6. resampling the georeferenced warp's resampling method (near, bilinear, cubic, lanczos):
//               error against the analytic pattern the source was sampled from, build time.
//
// The GL tables (1's upload column, 2, 3, 4) need a current OpenGL 4.5 core context on the calling
// thread; run_accuracy() creates a hidden one. In a build without the renderer they are skipped
// (run_accuracy) and the codec table's upload column reads "not measured".
#pragma once

#include <filesystem>
#include <functional>
#include <limits>
#include <string>
#include <utility>
#include <variant>
#include <vector>

#include "vts/base/result.hpp"

namespace vts::accuracy {

// One column of a table: `key` names it in JSON, `title` heads it (with its unit) in text.
struct Column {
  std::string key;
  std::string title;
  int digits = 2;  // decimals shown for a number
};

// A cell: a number (NaN: not measured, shown "n/a", JSON null; +inf shown "inf", JSON "inf") or
// text.
using Cell = std::variant<double, std::string>;

// The number of a cell that was not measured.
inline constexpr double kNotMeasured = std::numeric_limits<double>::quiet_NaN();

struct PlotSeries {
  std::string label;
  std::vector<std::pair<double, double>> points;  // (x, y), drawn in this order
  std::vector<std::string> labels;  // optional, one per point: the setting it stands for
};

// A trade-off curve: usually accuracy (y) against time or bytes (x), one series per family.
struct TablePlot {
  std::string id;  // file name stem: <report>/<id>.svg
  std::string title, x_label, y_label;
  bool log_x = false, log_y = false;
  std::vector<PlotSeries> series;
};

struct AccuracyTable {
  std::string id;  // one of kAccuracyTableIds
  std::string title;
  std::vector<Column> columns;
  std::vector<std::vector<Cell>> rows;  // each row has columns.size() cells
  std::vector<std::string> notes;       // how it was measured; printed under the table
  std::vector<TablePlot> plots;
};

struct AccuracyContext {
  std::filesystem::path input;     // the source image (any format OpenImageIO reads)
  std::filesystem::path work_dir;  // scratch space (the caller creates and removes it)
  // A lossless archive of `input` built by the caller (tile size 256, border 4; quick: 64 and 4).
  std::filesystem::path archive;
  bool quick = false;             // ctest mode: fewest sizes, views and frames; same tables
  int width = 640, height = 400;  // viewport of the GL tables (quick: 160 x 100)
  std::function<void(const std::string&)> progress;  // a one-line status; may be empty
  void say(const std::string& line) const {
    if (progress) progress(line);
  }
};

// ---- the command
// ---------------------------------------------------------------------------------

inline constexpr const char* kAccuracyTableIds[] = {"codec",      "feedback",   "filtering",
                                                    "addressing", "downsample", "resampling"};

struct AccuracyOptions {
  std::filesystem::path input;      // empty: the Earth (xplanet's earth.jpg, 2048 x 1024)
  std::vector<std::string> tables;  // ids to run, in kAccuracyTableIds order; empty: all
  bool quick = false;               // AccuracyContext::quick
  int width = 0, height = 0;        // GL viewport; 0: 640 x 400 (quick: 160 x 100)
  std::filesystem::path work_dir;   // empty: a fresh directory under the system's temp dir
  bool keep_work_dir = false;
  std::function<void(const std::string&)> progress;
};

struct SkippedTable {
  std::string id;
  std::string reason;   // e.g. "no OpenGL 4.5 context: DISPLAY is not set"
  bool failed = false;  // true: the table ran and failed (an error), false: it could not run here
};

struct AccuracyReport {
  std::string command;  // the command line, for the record
  std::string date;     // UTC, ISO 8601
  std::string machine;  // CPU model, cores, memory
  std::string gl;       // GL_RENDERER / GL_VERSION, or why there is none
  std::string input;    // "earth.jpg 2048x1024 3ch uint8"
  bool quick = false;
  double seconds = 0;
  std::vector<AccuracyTable> tables;
  std::vector<SkippedTable> skipped;
};

// Runs the tables. Errors only for bad options (unknown table id, unreadable input, viewport out
// of range) or when the input cannot be built; a table that fails is listed in `skipped` with
// failed = true and its message, and the others still run.
Result<AccuracyReport> run_accuracy(const AccuracyOptions& options);

// The report as JSON (every table, column, cell, note and plot), as Markdown (a section per table:
// the table, its notes, links to its plots), and as SVG plots.
std::string to_json(const AccuracyReport& report);
std::string to_markdown(const AccuracyReport& report, const std::string& plot_prefix = "");
std::string plot_svg(const TablePlot& plot);
// Writes report.md, report.json and one <plot id>.svg per plot into `dir` (created if needed).
Status write_report(const AccuracyReport& report, const std::filesystem::path& dir);

// ---- the tables (each is also callable on its own) --------------------------------------------

Result<AccuracyTable> codec_table(const AccuracyContext& ctx);
Result<AccuracyTable> feedback_table(const AccuracyContext& ctx);    // GL
Result<AccuracyTable> filtering_table(const AccuracyContext& ctx);   // GL
Result<AccuracyTable> addressing_table(const AccuracyContext& ctx);  // GL
Result<AccuracyTable> downsample_table(const AccuracyContext& ctx);
// Builds its own georeferenced sources in ctx.work_dir; does not read ctx.input.
Result<AccuracyTable> resampling_table(const AccuracyContext& ctx);

}  // namespace vts::accuracy

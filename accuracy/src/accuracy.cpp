// `vts bench accuracy`: runs the tables of accuracy.hpp on one input and writes the report.
#include <sys/sysinfo.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <random>
#include <sstream>

#include "vts/accuracy/accuracy.hpp"
#include "vts/base/file_io.hpp"
#include "vts/builder/builder.hpp"
#include "vts/plot/svg_plot.hpp"

#ifdef VTS_ACCURACY_HAVE_GL
#include "vts/renderer/gl_context.hpp"
#endif

namespace vts::accuracy {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

constexpr const char* kDefaultInput = "/usr/share/xplanet/images/earth.jpg";

bool needs_gl(const std::string& id) {
  return id == "feedback" || id == "filtering" || id == "addressing";
}
#ifdef VTS_ACCURACY_HAVE_GL
// The codec table measures uploads when it can, and reads "n/a" there without GL.
bool uses_gl(const std::string& id) {
  return needs_gl(id) || id == "codec";
}
#endif

std::string utc_now() {
  const std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

std::string machine_description() {
  std::string model = "unknown CPU";
  std::ifstream cpu("/proc/cpuinfo");
  for (std::string line; std::getline(cpu, line);) {
    if (line.rfind("model name", 0) == 0) {
      model = line.substr(line.find(':') + 2);
      break;
    }
  }
  struct sysinfo si {};
  sysinfo(&si);
  const double gib = double(si.totalram) * si.mem_unit / (1024.0 * 1024 * 1024);
  char buf[64];
  std::snprintf(buf, sizeof buf, ", %.0f GiB RAM", gib);
  return model + ", " + std::to_string(sysconf(_SC_NPROCESSORS_ONLN)) + " cores" + buf;
}

Result<AccuracyTable> run_table(const std::string& id, const AccuracyContext& ctx) {
  if (id == "codec") return codec_table(ctx);
  if (id == "downsample") return downsample_table(ctx);
  if (id == "resampling") return resampling_table(ctx);
#ifdef VTS_ACCURACY_HAVE_GL
  if (id == "feedback") return feedback_table(ctx);
  if (id == "filtering") return filtering_table(ctx);
  if (id == "addressing") return addressing_table(ctx);
#endif
  return Error{ErrorCode::unsupported, "table " + id + " needs the renderer (VTS_BUILD_RENDERER)"};
}

// ---- formatting ---------------------------------------------------------------------------------

std::string cell_text(const Cell& c, int digits) {
  if (const auto* s = std::get_if<std::string>(&c)) return *s;
  const double v = std::get<double>(c);
  if (std::isnan(v)) return "n/a";
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", std::clamp(digits, 0, 9), v);
  return buf;
}

json cell_json(const Cell& c) {
  if (const auto* s = std::get_if<std::string>(&c)) return *s;
  const double v = std::get<double>(c);
  if (std::isnan(v)) return nullptr;
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  return v;
}

std::string markdown_escape(const std::string& s) {
  std::string out;
  for (char ch : s) {
    if (ch == '|') out += '\\';
    out += ch;
  }
  return out;
}

std::string format_tick(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

const char* const kColours[] = {"#1f77b4", "#d62728", "#2ca02c", "#ff7f0e",
                                "#9467bd", "#8c564b", "#e377c2", "#17becf"};

}  // namespace

// ---- the run
// ----------------------------------------------------------------------------------------

Result<AccuracyReport> run_accuracy(const AccuracyOptions& options) {
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<std::string> ids;
  for (const std::string& id : options.tables) {
    if (std::find_if(std::begin(kAccuracyTableIds), std::end(kAccuracyTableIds),
                     [&](const char* k) { return id == k; }) == std::end(kAccuracyTableIds))
      return Error{
          ErrorCode::invalid_argument,
          "unknown table \"" + id +
              "\" (known: codec, feedback, filtering, addressing, downsample, resampling)"};
  }
  for (const char* id : kAccuracyTableIds) {
    if (options.tables.empty() ||
        std::find(options.tables.begin(), options.tables.end(), id) != options.tables.end())
      ids.emplace_back(id);
  }
  AccuracyContext ctx;
  ctx.quick = options.quick;
  ctx.width = options.width > 0 ? options.width : (options.quick ? 160 : 640);
  ctx.height = options.height > 0 ? options.height : (options.quick ? 100 : 400);
  if (ctx.width > 4096 || ctx.height > 4096 || (options.width > 0) != (options.height > 0))
    return Error{ErrorCode::invalid_argument, "the viewport must be WxH with sides 1 to 4096"};
  ctx.progress = options.progress;
  ctx.input = options.input.empty() ? fs::path(kDefaultInput) : options.input;
  std::error_code ec;
  if (!fs::is_regular_file(ctx.input, ec))
    return Error{ErrorCode::not_found,
                 "input image " + ctx.input.string() + " does not exist" +
                     (options.input.empty() ? " (the default needs Debian's xplanet-images)" : "")};

  // Scratch space, removed at the end unless asked to keep it.
  fs::path work = options.work_dir;
  const bool own_work = work.empty();
  if (own_work) {
    std::random_device rd;
    work = fs::temp_directory_path() /
           ("vts-accuracy-" + std::to_string(::getpid()) + "-" + std::to_string(rd() % 100000));
  }
  fs::create_directories(work, ec);
  if (ec) return Error{ErrorCode::io, "cannot create " + work.string() + ": " + ec.message()};
  struct Cleanup {
    fs::path dir;
    bool active;
    ~Cleanup() {
      std::error_code e;
      if (active) fs::remove_all(dir, e);
    }
  } cleanup{work, own_work && !options.keep_work_dir};
  ctx.work_dir = work;

  AccuracyReport report;
  report.date = utc_now();
  report.machine = machine_description();
  report.quick = options.quick;

  // The lossless archive the tables read: the tileset every other knob is judged against.
  ctx.say("building the lossless archive of " + ctx.input.string());
  BuildOptions bo;
  bo.inputs = {ctx.input};
  bo.output = work / "lossless.pmtiles";
  bo.tile_size = options.quick ? 64 : 256;
  bo.border = 4;
  auto built = build_pyramid(bo);
  if (!built) return built.error();
  report.input = built->input_description;
  ctx.archive = bo.output;

#ifdef VTS_ACCURACY_HAVE_GL
  std::unique_ptr<renderer::GlContext> gl;
  std::string gl_error;
  report.gl = "not used by these tables";
  if (std::any_of(ids.begin(), ids.end(), uses_gl)) {
    renderer::GlContextOptions go;
    go.visible = false;
    go.width = 64;
    go.height = 64;
    go.vsync = false;
    go.title = "vts bench accuracy";
    auto c = renderer::GlContext::create(go);
    if (c) {
      gl = std::move(*c);
      gl->make_current();
      report.gl = gl->info().renderer + ", " + gl->info().version_text;
    } else {
      gl_error = c.error().message;
      report.gl = "none: " + gl_error;
    }
  }
#else
  const std::string gl_error = "this build has no renderer (VTS_BUILD_RENDERER=OFF)";
  report.gl = "none: " + gl_error;
  const bool gl = false;
#endif

  for (const std::string& id : ids) {
    if (needs_gl(id) && !gl) {
      report.skipped.push_back({id, "no OpenGL 4.5 context: " + gl_error, false});
      ctx.say("table " + id + " skipped: " + gl_error);
      continue;
    }
    ctx.say("table " + id + "...");
    const auto ts = std::chrono::steady_clock::now();
    auto table = run_table(id, ctx);
    if (!table) {
      report.skipped.push_back({id, table.error().message, true});
      ctx.say("table " + id + " failed: " + table.error().message);
      continue;
    }
    const double secs =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - ts).count();
    char buf[64];
    std::snprintf(buf, sizeof buf, "table %s: %zu rows in %.1f s", id.c_str(), table->rows.size(),
                  secs);
    ctx.say(buf);
    report.tables.push_back(std::move(*table));
  }
  report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return report;
}

// ---- writers ------------------------------------------------------------------------------------

std::string to_json(const AccuracyReport& r) {
  json j;
  j["command"] = r.command;
  j["date"] = r.date;
  j["machine"] = r.machine;
  j["gl"] = r.gl;
  j["input"] = r.input;
  j["quick"] = r.quick;
  j["seconds"] = r.seconds;
  j["tables"] = json::array();
  for (const AccuracyTable& t : r.tables) {
    json jt;
    jt["id"] = t.id;
    jt["title"] = t.title;
    jt["columns"] = json::array();
    for (const Column& c : t.columns) jt["columns"].push_back({{"key", c.key}, {"title", c.title}});
    jt["rows"] = json::array();
    for (const auto& row : t.rows) {
      json jr = json::object();
      for (std::size_t i = 0; i < row.size() && i < t.columns.size(); ++i)
        jr[t.columns[i].key] = cell_json(row[i]);
      jt["rows"].push_back(std::move(jr));
    }
    jt["notes"] = t.notes;
    jt["plots"] = json::array();
    for (const TablePlot& p : t.plots) {
      json jp{{"id", p.id},           {"title", p.title}, {"x_label", p.x_label},
              {"y_label", p.y_label}, {"log_x", p.log_x}, {"log_y", p.log_y}};
      jp["series"] = json::array();
      for (const PlotSeries& s : p.series) {
        json pts = json::array();
        for (const auto& [x, y] : s.points) pts.push_back({cell_json(x), cell_json(y)});
        json js{{"label", s.label}, {"points", pts}};
        if (!s.labels.empty()) js["labels"] = s.labels;
        jp["series"].push_back(std::move(js));
      }
      jt["plots"].push_back(std::move(jp));
    }
    j["tables"].push_back(std::move(jt));
  }
  j["skipped"] = json::array();
  for (const SkippedTable& s : r.skipped)
    j["skipped"].push_back({{"id", s.id}, {"reason", s.reason}, {"failed", s.failed}});
  return j.dump(2);
}

std::string to_markdown(const AccuracyReport& r, const std::string& plot_prefix) {
  std::ostringstream o;
  o << "Command: `" << r.command << "`  \n";
  o << "Date: " << r.date << "  \n";
  o << "Machine: " << r.machine << "  \n";
  o << "GL: " << r.gl << "  \n";
  o << "Input: " << r.input << (r.quick ? " (quick mode)" : "") << "  \n";
  char secs[32];
  std::snprintf(secs, sizeof secs, "%.0f s", r.seconds);
  o << "Run time: " << secs << "\n";
  int n = 0;
  for (const char* id : kAccuracyTableIds) {
    ++n;
    const auto t = std::find_if(r.tables.begin(), r.tables.end(),
                                [&](const AccuracyTable& x) { return x.id == id; });
    if (t == r.tables.end()) {
      const auto s = std::find_if(r.skipped.begin(), r.skipped.end(),
                                  [&](const SkippedTable& x) { return x.id == id; });
      if (s != r.skipped.end())
        o << "\n### " << n << ". " << id << "\n\n"
          << (s->failed ? "Failed: " : "Not run: ") << s->reason << "\n";
      continue;
    }
    o << "\n### " << n << ". " << t->title << "\n\n|";
    for (const Column& c : t->columns) o << " " << markdown_escape(c.title) << " |";
    o << "\n|";
    for (std::size_t i = 0; i < t->columns.size(); ++i) o << (i == 0 ? "---|" : "---:|");
    o << "\n";
    for (const auto& row : t->rows) {
      o << "|";
      for (std::size_t i = 0; i < t->columns.size(); ++i)
        o << " " << markdown_escape(i < row.size() ? cell_text(row[i], t->columns[i].digits) : "")
          << " |";
      o << "\n";
    }
    if (!t->notes.empty()) o << "\n";
    for (const std::string& note : t->notes) o << "- " << note << "\n";
    for (const TablePlot& p : t->plots)
      o << "\n![" << p.title << "](" << plot_prefix << p.id << ".svg)\n";
  }
  return o.str();
}

std::string plot_svg(const TablePlot& p) {
  using plot::Axis;
  using namespace vts::plot;
  Plot plot;
  plot.id = p.id;
  plot.title = p.title;
  plot.x_label = p.x_label;
  plot.y_label = p.y_label;
  plot.x_format = format_tick;
  plot.y_format = format_tick;
  double xlo = INFINITY, xhi = -INFINITY, ylo = INFINITY, yhi = -INFINITY;
  std::size_t k = 0;
  for (const PlotSeries& s : p.series) {
    Series out;
    out.key = s.label;
    out.label = s.label;
    out.color = kColours[k++ % std::size(kColours)];
    out.markers = true;
    out.point_labels = s.labels;
    for (const auto& [x, y] : s.points) {
      const bool ok =
          std::isfinite(x) && std::isfinite(y) && (!p.log_x || x > 0) && (!p.log_y || y > 0);
      out.points.emplace_back(ok ? x : NAN, ok ? y : NAN);
      if (!ok) continue;
      xlo = std::min(xlo, x);
      xhi = std::max(xhi, x);
      ylo = std::min(ylo, y);
      yhi = std::max(yhi, y);
    }
    plot.series.push_back(std::move(out));
  }
  if (!(xhi >= xlo)) return render_plot(plot, nullptr);
  const double right = kPlotWidth - 24, bottom = kPlotHeight - kMarginBottom;
  auto axis = [](bool log, double lo, double hi, double p0, double p1) {
    if (log) return Axis::logarithmic(lo, hi > lo ? hi : lo * 10, p0, p1);
    const double pad = hi > lo ? (hi - lo) * 0.05 : std::max(std::fabs(lo) * 0.1, 1.0);
    return Axis::linear(lo - pad, hi + pad, p0, p1);
  };
  AxisSet axes{axis(p.log_x, xlo, xhi, kMarginLeft, right),
               axis(p.log_y, ylo, yhi, bottom, kMarginTop), std::nullopt};
  return render_plot(plot, &axes);
}

Status write_report(const AccuracyReport& report, const fs::path& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return Error{ErrorCode::io, "cannot create " + dir.string() + ": " + ec.message()};
  auto write = [](const fs::path& path, const std::string& text) {
    return write_file_atomically(path, text);
  };
  if (auto s = write(dir / "report.md", "# vtstream accuracy report\n\n" + to_markdown(report)); !s)
    return s;
  if (auto s = write(dir / "report.json", to_json(report) + "\n"); !s) return s;
  for (const AccuracyTable& t : report.tables)
    for (const TablePlot& p : t.plots)
      if (auto s = write(dir / (p.id + ".svg"), plot_svg(p) + "\n"); !s) return s;
  return {};
}

}  // namespace vts::accuracy

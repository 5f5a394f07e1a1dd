// SVG line plots drawn as text, with no scripts and no external resources: linear or base-10
// logarithmic axes with "nice" ticks, any number of series on a left and an optional right axis,
// a legend above the plot area. Used by the load-test report (load_report.hpp) and by
// `vts bench accuracy` (accuracy/include/vts/accuracy/accuracy.hpp).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace vts::plot {

// `s` with every invalid UTF-8 sequence replaced by U+FFFD; with control_to_replacement, C0
// controls other than tab and newline, and DEL, too.
std::string valid_utf8(std::string_view s, bool control_to_replacement);
// Text for HTML and SVG: &, <, >, " and ' escaped (the input is expected to be valid UTF-8).
std::string html_escape(std::string_view s);
// Code points in valid UTF-8: the column width assumed when aligning.
std::size_t display_width(std::string_view s);
// Plain-number formatting for SVG coordinates ("12.5").
std::string px(double v);

inline constexpr double kPlotWidth = 760, kPlotHeight = 320;
inline constexpr double kMarginLeft = 76, kMarginTop = 40, kMarginBottom = 50;

using Formatter = std::function<std::string(double)>;

// A linear or base-10 logarithmic axis mapping [lo, hi] onto pixels [p0, p1], widened to "nice"
// bounds (1, 2 or 5 times a power of ten) so that it starts and ends on a tick.
class Axis {
 public:
  static Axis linear(double lo, double hi, double p0, double p1) {
    if (!(hi > lo)) hi = lo + 1;
    const double step = nice_step((hi - lo) / 5);
    Axis a(std::floor(lo / step) * step, std::ceil(hi / step) * step, p0, p1, false);
    for (double t = a.lo_; t <= a.hi_ + step * 1e-9; t += step) {
      a.ticks_.push_back(std::fabs(t) < step * 1e-9 ? 0.0 : t);
    }
    return a;
  }
  // lo > 0.
  static Axis logarithmic(double lo, double hi, double p0, double p1) {
    const double e0 = std::floor(std::log10(lo));
    double e1 = std::ceil(std::log10(hi));
    if (e1 <= e0) e1 = e0 + 1;
    Axis a(std::pow(10.0, e0), std::pow(10.0, e1), p0, p1, true);
    const bool fine = e1 - e0 <= 2;  // few decades: 1-2-5 ticks, else one per decade
    for (double e = e0; e <= e1; ++e) {
      const double decade = std::pow(10.0, e);
      a.ticks_.push_back(decade);
      if (fine && e < e1) {
        a.ticks_.push_back(2 * decade);
        a.ticks_.push_back(5 * decade);
      }
    }
    return a;
  }
  // Logarithmic when max / min_positive exceeds ratio_for_log (latencies with a heavy tail),
  // else linear from 0.
  static Axis automatic(double min_positive, double max, double p0, double p1,
                        double ratio_for_log = 50) {
    if (min_positive > 0 && max / min_positive > ratio_for_log) {
      return logarithmic(min_positive, max, p0, p1);
    }
    return linear(0, max > 0 ? max : 1, p0, p1);
  }

  double map(double v) const {
    double f;
    if (log_) {
      f = (std::log10(std::max(v, lo_)) - std::log10(lo_)) / (std::log10(hi_) - std::log10(lo_));
    } else {
      f = (v - lo_) / (hi_ - lo_);
    }
    return p0_ + std::clamp(f, 0.0, 1.0) * (p1_ - p0_);
  }
  const std::vector<double>& ticks() const { return ticks_; }

 private:
  Axis(double lo, double hi, double p0, double p1, bool log)
      : lo_(lo), hi_(hi), p0_(p0), p1_(p1), log_(log) {}

  static double nice_step(double raw) {
    const double magnitude = std::pow(10.0, std::floor(std::log10(raw)));
    const double f = raw / magnitude;
    return (f <= 1 ? 1 : f <= 2 ? 2 : f <= 5 ? 5 : 10) * magnitude;
  }

  double lo_, hi_, p0_, p1_;
  bool log_;
  std::vector<double> ticks_;
};

struct Series {
  std::string key;    // data-series attribute, for tests and styling
  std::string label;  // legend text
  std::string color;
  std::vector<std::pair<double, double>> points;  // a NaN y breaks the line
  bool right_axis = false;
  bool markers = false;
  std::vector<std::string> point_labels;  // drawn beside the markers, by index (may be shorter)
};

struct Plot {
  std::string id, title;
  std::string x_label, y_label, y2_label;
  Formatter x_format, y_format, y2_format;
  std::vector<Series> series;
};

struct AxisSet {
  Axis x, y;
  std::optional<Axis> y2;
};

// <text> at (x, y) with the given text-anchor ("start", "middle", "end") and extra attributes.
std::string svg_text(double x, double y, const std::string& text, const char* anchor,
                     const std::string& extra = "");
// The <svg> element for `plot`; `axes` is null when there is nothing to draw ("no data").
std::string render_plot(const Plot& plot, const AxisSet* axes);

}  // namespace vts::plot

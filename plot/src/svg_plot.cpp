#include "vts/plot/svg_plot.hpp"

#include <cstdio>

#include "vts/base/file_io.hpp"

namespace vts::plot {
namespace {

std::string buf_printf(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.1f", v);
  return buf;
}

}  // namespace

// `s` with every invalid UTF-8 sequence (bad lead byte, bad or missing continuation, overlong
// form, surrogate, beyond U+10FFFF) replaced by U+FFFD. With control_to_replacement, C0 controls
// other than tab and newline, and DEL, are replaced too (they have no business in a page or on a
// terminal, where ESC starts an escape sequence).
std::string valid_utf8(std::string_view s, bool control_to_replacement) {
  static constexpr std::string_view kReplacement = "\xEF\xBF\xBD";
  std::string out;
  out.reserve(s.size());
  std::size_t i = 0;
  auto cont = [&](std::size_t at, unsigned lo = 0x80, unsigned hi = 0xBF) {
    if (at >= s.size()) return false;
    const unsigned c = static_cast<unsigned char>(s[at]);
    return c >= lo && c <= hi;
  };
  while (i < s.size()) {
    const unsigned c = static_cast<unsigned char>(s[i]);
    std::size_t len = 0;
    if (c < 0x80) {
      if (control_to_replacement && ((c < 0x20 && c != '\t' && c != '\n') || c == 0x7F)) {
        out += kReplacement;
        ++i;
        continue;
      }
      len = 1;
    } else {
      // need: continuation bytes the lead byte announces; the first one's range excludes
      // overlong forms, surrogates and values past U+10FFFF.
      std::size_t need = 0;
      unsigned lo = 0x80, hi = 0xBF;
      if (c >= 0xC2 && c <= 0xDF) {
        need = 1;
      } else if (c >= 0xE0 && c <= 0xEF) {
        need = 2;
        lo = c == 0xE0 ? 0xA0 : 0x80;
        hi = c == 0xED ? 0x9F : 0xBF;
      } else if (c >= 0xF0 && c <= 0xF4) {
        need = 3;
        lo = c == 0xF0 ? 0x90 : 0x80;
        hi = c == 0xF4 ? 0x8F : 0xBF;
      }
      std::size_t have = 0;
      while (have < need && (have == 0 ? cont(i + 1, lo, hi) : cont(i + 1 + have))) ++have;
      if (need > 0 && have == need) {
        len = need + 1;
      } else {
        // One replacement for the lead byte and the continuations that did fit (the
        // "maximal subpart" practice of Unicode and the WHATWG decoder).
        out += kReplacement;
        i += 1 + have;
        continue;
      }
    }
    out.append(s.substr(i, len));
    i += len;
  }
  return out;
}

// Text for HTML element content and attribute values (double- or single-quoted).
std::string html_escape(std::string_view s) {
  return vts::html_escape(valid_utf8(s, true));
}

std::size_t display_width(std::string_view s) {
  return static_cast<std::size_t>(
      std::count_if(s.begin(), s.end(), [](char c) { return (c & 0xC0) != 0x80; }));
}

std::string px(double v) {
  return buf_printf(v);
}

std::string svg_text(double x, double y, const std::string& text, const char* anchor,
                     const std::string& extra) {
  return "<text x=\"" + px(x) + "\" y=\"" + px(y) + "\" text-anchor=\"" + anchor + "\"" + extra +
         ">" + html_escape(text) + "</text>";
}

std::string render_plot(const Plot& plot, const AxisSet* axes) {
  const double right = axes && axes->y2 ? kPlotWidth - 76 : kPlotWidth - 24;
  const double bottom = kPlotHeight - kMarginBottom;
  std::string s;
  s += "<svg class=\"plot\" id=\"" + html_escape(plot.id) +
       "\" xmlns=\"http://www.w3.org/2000/svg\" viewBox=\"0 0 " + px(kPlotWidth) + " " +
       px(kPlotHeight) + "\" width=\"" + px(kPlotWidth) + "\" height=\"" + px(kPlotHeight) +
       "\" role=\"img\" aria-label=\"" + html_escape(plot.title) + "\">\n";
  s += "<title>" + html_escape(plot.title) + "</title>\n";
  s += "<rect class=\"frame\" x=\"" + px(kMarginLeft) + "\" y=\"" + px(kMarginTop) + "\" width=\"" +
       px(right - kMarginLeft) + "\" height=\"" + px(bottom - kMarginTop) +
       "\" fill=\"#fff\" stroke=\"#888\"/>\n";
  if (axes == nullptr) {
    s += svg_text((kMarginLeft + right) / 2, (kMarginTop + bottom) / 2, "no data", "middle",
                  " class=\"no-data\" font-size=\"18\" fill=\"#666\"");
    s += "\n</svg>";
    return s;
  }

  // Grid, ticks and tick labels.
  s += "<g class=\"axis x-axis\" font-size=\"11\" fill=\"#333\">\n";
  for (double t : axes->x.ticks()) {
    const double x = axes->x.map(t);
    s += "<line x1=\"" + px(x) + "\" y1=\"" + px(kMarginTop) + "\" x2=\"" + px(x) + "\" y2=\"" +
         px(bottom) + "\" stroke=\"#e4e4e4\"/>";
    s += "<line x1=\"" + px(x) + "\" y1=\"" + px(bottom) + "\" x2=\"" + px(x) + "\" y2=\"" +
         px(bottom + 5) + "\" stroke=\"#333\"/>";
    s += svg_text(x, bottom + 18, plot.x_format(t), "middle") + "\n";
  }
  s += svg_text((kMarginLeft + right) / 2, kPlotHeight - 8, plot.x_label, "middle",
                " class=\"axis-label\" font-size=\"12\"");
  s += "\n</g>\n<g class=\"axis y-axis\" font-size=\"11\" fill=\"#333\">\n";
  for (double t : axes->y.ticks()) {
    const double y = axes->y.map(t);
    s += "<line x1=\"" + px(kMarginLeft) + "\" y1=\"" + px(y) + "\" x2=\"" + px(right) +
         "\" y2=\"" + px(y) + "\" stroke=\"#e4e4e4\"/>";
    s += "<line x1=\"" + px(kMarginLeft - 5) + "\" y1=\"" + px(y) + "\" x2=\"" + px(kMarginLeft) +
         "\" y2=\"" + px(y) + "\" stroke=\"#333\"/>";
    s += svg_text(kMarginLeft - 8, y + 4, plot.y_format(t), "end") + "\n";
  }
  const double mid_y = (kMarginTop + bottom) / 2;
  s += "<text class=\"axis-label\" font-size=\"12\" text-anchor=\"middle\" transform=\"translate(" +
       px(14) + " " + px(mid_y) + ") rotate(-90)\">" + html_escape(plot.y_label) +
       "</text>\n</g>\n";
  if (axes->y2) {
    s += "<g class=\"axis y2-axis\" font-size=\"11\" fill=\"#333\">\n";
    for (double t : axes->y2->ticks()) {
      const double y = axes->y2->map(t);
      s += "<line x1=\"" + px(right) + "\" y1=\"" + px(y) + "\" x2=\"" + px(right + 5) +
           "\" y2=\"" + px(y) + "\" stroke=\"#333\"/>";
      s += svg_text(right + 8, y + 4, plot.y2_format(t), "start") + "\n";
    }
    s += "<text class=\"axis-label\" font-size=\"12\" text-anchor=\"middle\" "
         "transform=\"translate(" +
         px(kPlotWidth - 12) + " " + px(mid_y) + ") rotate(90)\">" + html_escape(plot.y2_label) +
         "</text>\n</g>\n";
  }
  // The axis lines over the grid.
  s += "<path class=\"axis-line\" d=\"M" + px(kMarginLeft) + " " + px(kMarginTop) + "V" +
       px(bottom) + "H" + px(right) + (axes->y2 ? "V" + px(kMarginTop) : std::string()) +
       "\" fill=\"none\" stroke=\"#333\"/>\n";

  // Data.
  for (const Series& series : plot.series) {
    const Axis& ya = series.right_axis && axes->y2 ? *axes->y2 : axes->y;
    std::string d, marks;
    bool pen_down = false;
    for (const auto& point : series.points) {
      const auto& [vx, vy] = point;
      if (!std::isfinite(vx) || !std::isfinite(vy)) {
        pen_down = false;
        continue;
      }
      const double x = axes->x.map(vx), y = ya.map(vy);
      d += (pen_down ? "L" : "M") + px(x) + " " + px(y);
      pen_down = true;
      if (series.markers) {
        marks += "<circle cx=\"" + px(x) + "\" cy=\"" + px(y) + "\" r=\"2.5\"/>";
      }
      const std::size_t index = static_cast<std::size_t>(&point - series.points.data());
      if (index < series.point_labels.size() && !series.point_labels[index].empty()) {
        marks += svg_text(x + 5, y - 5, series.point_labels[index], "start",
                          " class=\"point-label\" font-size=\"10\"");
      }
    }
    if (d.empty()) continue;
    s += "<g class=\"series\" data-series=\"" + html_escape(series.key) + "\" fill=\"" +
         series.color + "\">\n<path d=\"" + d + "\" fill=\"none\" stroke=\"" + series.color +
         "\" stroke-width=\"1.8\" stroke-linejoin=\"round\"/>\n" + marks + "\n</g>\n";
  }

  // Legend, above the plot area.
  s += "<g class=\"legend\" font-size=\"12\" fill=\"#222\">\n";
  double lx = kMarginLeft;
  for (const Series& series : plot.series) {
    s += "<line x1=\"" + px(lx) + "\" y1=\"" + px(18) + "\" x2=\"" + px(lx + 22) + "\" y2=\"" +
         px(18) + "\" stroke=\"" + series.color + "\" stroke-width=\"3\"/>";
    s += svg_text(lx + 28, 22, series.label, "start") + "\n";
    lx += 28 + 7.0 * static_cast<double>(display_width(series.label)) + 22;
  }
  s += "</g>\n</svg>";
  return s;
}

}  // namespace vts::plot

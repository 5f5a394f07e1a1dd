// load_report_sample DIR [--empty] [--title TEXT] [--json FILE] [--summary FILE]
//
// Writes DIR/index.html, the load-test report, from synthetic but realistic data (a 90-second,
// 24-viewer open-loop run with a slow spell and a burst of 503s in the middle), so that the page
// can be checked in a real browser without running a load test. --empty writes the report of a
// run in which no request completed. --json and --summary also write the --json document and the
// terminal summary. Deterministic: the same arguments give the same bytes. Exit 0 on success, 1
// with a message on stderr otherwise.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <random>
#include <string>
#include <string_view>

#include "vts/loadtest/load_report.hpp"

namespace {

using vts::loadtest::LatencyHistogram;
using vts::loadtest::LoadReport;
using vts::loadtest::LoadSecond;

void synthesize(LoadReport& r) {
  std::mt19937_64 rng(20261123);
  r.viewers = 24;
  r.path = "orbit-zoom";
  r.fps = 60;
  r.mode = vts::loadtest::LoopMode::open;
  r.rate = 400;
  r.rate_unit = "req/s";
  r.duration_s = 90;
  std::lognormal_distribution<double> hit(std::log(60e3), 0.4);     // RAM/disk: ~60 us
  std::lognormal_distribution<double> network(std::log(8e6), 0.6);  // network: ~8 ms
  std::lognormal_distribution<double> slow(std::log(120e6), 0.8);   // the slow spell
  std::lognormal_distribution<double> queue(std::log(200e3), 1.0);  // time queued
  std::uniform_real_distribution<double> unit(0, 1);
  std::poisson_distribution<int> arrivals(380);
  for (int second = 0; second < 90; ++second) {
    const bool spell = second >= 40 && second < 52;
    LoadSecond sec;
    LatencyHistogram this_second;
    const int n = arrivals(rng) / (spell ? 2 : 1);
    for (int i = 0; i < n; ++i) {
      const double u = unit(rng);
      std::uint64_t bytes = 0;
      double ttfb;
      if (spell && u < 0.08) {  // the upstream answers 503 quickly
        ++sec.errors;
        r.errors_by_kind["http_503"] += 1;
        r.by_status[503] += 1;
        ttfb = network(rng);
      } else if (u < 0.55 && !spell) {
        ++r.tiers.ram;
        ttfb = hit(rng) * 0.3;
      } else if (u < 0.7) {
        ++r.tiers.disk;
        ttfb = hit(rng);
      } else if (u < 0.75) {
        ++r.tiers.revalidated;
        r.by_status[304] += 1;
        ttfb = spell ? slow(rng) : network(rng);
      } else {
        ++r.tiers.network;
        r.by_status[200] += 1;
        ttfb = spell ? slow(rng) : network(rng);
        bytes = 30000 + static_cast<std::uint64_t>(unit(rng) * 60000);
      }
      if (unit(rng) < 0.002) {
        ++sec.errors;
        r.errors_by_kind["timeout"] += 1;
      }
      const auto q = static_cast<std::uint64_t>(queue(rng));
      const auto t = static_cast<std::uint64_t>(ttfb);
      const std::uint64_t total = q + t + static_cast<std::uint64_t>(bytes / 2);  // 2 B/ns
      r.queue_time.record(q);
      r.ttfb.record(t);
      r.total.record(total);
      this_second.record(total);
      sec.bytes += bytes;
      ++sec.requests;
    }
    sec.p50_ns = this_second.percentile(50);
    sec.p90_ns = this_second.percentile(90);
    sec.p99_ns = this_second.percentile(99);
    r.requests += sec.requests;
    r.bytes += sec.bytes;
    r.errors += sec.errors;
    r.seconds.push_back(sec);
  }
  // Camera moves: 24 viewers, one move every 3 s.
  std::lognormal_distribution<double> first(std::log(15e6), 0.5), full(std::log(400e6), 0.7);
  for (int m = 0; m < 24 * 30; ++m) {
    const double f = first(rng);
    r.first_visible.record(static_cast<std::uint64_t>(f));
    r.full_resolution.record(static_cast<std::uint64_t>(f + full(rng)));
  }
  r.camera_moves = 24 * 30;
  r.cancelled = 1234;
  r.errors_by_kind["checksum"] = 2;
  r.errors += 2;
}

bool write_file(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << text;
  out.flush();
  if (!out) {
    std::fprintf(stderr, "load_report_sample: cannot write %s\n", path.c_str());
    return false;
  }
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr,
                 "usage: load_report_sample DIR [--empty] [--title TEXT] [--json FILE] "
                 "[--summary FILE]\n");
    return 1;
  }
  LoadReport r;
  r.title = "Synthetic load test: 24 viewers <orbit & zoom>";
  r.target = "http://127.0.0.1:8080/earth/{z}/{x}/{y}?a=1&b=2";
  r.command_line =
      "vts loadtest --viewers 24 --path orbit-zoom --fps 60 --rate 400 "
      "--report out/report http://127.0.0.1:8080/earth";
  r.start = std::chrono::system_clock::time_point(std::chrono::seconds(1795435200));
  bool empty = false;
  std::string json_path, summary_path;
  for (int i = 2; i < argc; ++i) {
    const std::string_view a = argv[i];
    const bool has_value = i + 1 < argc;
    if (a == "--empty") {
      empty = true;
    } else if (a == "--title" && has_value) {
      r.title = argv[++i];
    } else if (a == "--json" && has_value) {
      json_path = argv[++i];
    } else if (a == "--summary" && has_value) {
      summary_path = argv[++i];
    } else {
      std::fprintf(stderr, "load_report_sample: unknown or incomplete argument '%s'\n", argv[i]);
      return 1;
    }
  }
  if (!empty) synthesize(r);
  if (!json_path.empty() && !write_file(json_path, vts::loadtest::to_json(r).dump(2) + "\n")) {
    return 1;
  }
  if (!summary_path.empty() && !write_file(summary_path, vts::loadtest::summary_table(r))) return 1;
  const vts::Status s = vts::loadtest::write_html_report(r, argv[1]);
  if (!s.ok()) {
    std::fprintf(stderr, "load_report_sample: %s\n", s.error().to_string().c_str());
    return 1;
  }
  return 0;
}

// "unknown command 'buidl'; did you mean 'build'?": a word where a subcommand is expected that
// names none, with the nearest subcommand by edit distance; and the same for a mistyped option
// ("unknown option '--viewer' of 'vts loadtest'; did you mean '--viewers'?").
#include <algorithm>
#include <cctype>
#include <string>
#include <vector>

#include "commands.hpp"

namespace vts::cli {

namespace {

// Levenshtein distance (insertions, deletions, substitutions), plus swaps of two neighbours.
std::size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<std::vector<std::size_t>> d(a.size() + 1, std::vector<std::size_t>(b.size() + 1));
  for (std::size_t i = 0; i <= a.size(); ++i) d[i][0] = i;
  for (std::size_t j = 0; j <= b.size(); ++j) d[0][j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    for (std::size_t j = 1; j <= b.size(); ++j) {
      d[i][j] = std::min(
          {d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + (a[i - 1] == b[j - 1] ? 0 : 1)});
      if (i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1])
        d[i][j] = std::min(d[i][j], d[i - 2][j - 2] + 1);
    }
  }
  return d[a.size()][b.size()];
}

bool plain_word(const std::string& w) {
  return !w.empty() && std::all_of(w.begin(), w.end(), [](char c) {
    return std::islower(static_cast<unsigned char>(c)) || c == '-';
  });
}

struct Nearest {
  std::string name;  // "" when none is near enough to be a typo of the word
  std::size_t distance = ~std::size_t{0};
};

// The nearest of `names` to `w`, and its edit distance.
Nearest nearest(const std::string& w, const std::vector<std::string>& names) {
  Nearest best;
  for (const std::string& n : names) {
    const std::size_t d = edit_distance(w, n);
    if (d < best.distance) best = {n, d};
  }
  if (best.distance > std::max<std::size_t>(2, w.size() / 3)) best.name.clear();
  return best;
}

}  // namespace

std::string unknown_option(CLI::App& app, const std::vector<std::string>& extras) {
  CLI::App* cur = &app;
  std::string path = "vts";
  for (;;) {
    const std::vector<CLI::App*> parsed =
        cur->get_subcommands([](CLI::App* s) { return s->parsed(); });
    if (parsed.empty()) break;
    cur = parsed.front();
    path += " " + cur->get_name();
  }
  for (const std::string& e : extras) {
    if (e.size() < 3 || e.compare(0, 2, "--") != 0) continue;
    const std::string flag = e.substr(0, e.find('='));
    std::vector<std::string> names;
    for (const CLI::Option* o : cur->get_options())
      for (const std::string& l : o->get_lnames()) names.push_back("--" + l);
    std::string msg = "unknown option '" + flag + "' of '" + path + "'";
    if (const Nearest best = nearest(flag, names); !best.name.empty())
      msg += "; did you mean '" + best.name + "'?";
    return msg;
  }
  return "";
}

std::string unknown_command(CLI::App& app, int argc, char** argv) {
  CLI::App* cur = &app;
  std::string prefix;
  for (int i = 1; i < argc; ++i) {
    const std::string w = argv[i];
    if (w.empty() || w[0] == '-') return "";
    const std::vector<CLI::App*> subs = cur->get_subcommands({});
    if (subs.empty()) return "";
    auto named =
        std::find_if(subs.begin(), subs.end(), [&](CLI::App* s) { return s->check_name(w); });
    if (named != subs.end()) {
      cur = *named;
      prefix += cur->get_name() + " ";
      continue;
    }
    std::vector<std::string> names;
    for (CLI::App* s : subs) names.push_back(s->get_name());
    const Nearest best = nearest(w, names);
    // Below the top level a word may be a positional argument (vts loadtest URL): only a plain
    // word close to a subcommand is taken for a mistyped one.
    if (cur != &app && !(plain_word(w) && best.distance <= 2)) return "";
    std::string msg = "unknown command '" + prefix + w + "'";
    if (!best.name.empty()) msg += "; did you mean '" + prefix + best.name + "'?";
    return msg;
  }
  return "";
}

}  // namespace vts::cli

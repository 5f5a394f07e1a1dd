// vts-build — vtstream's build tooling: the commands that read images through OpenImageIO and
// GDAL (build, plan, merge, extract, export, bench accuracy). `vts` hands these commands over to
// it, with the same arguments, so users type `vts build ...` either way.
#include "commands.hpp"

int main(int argc, char** argv) {
  CLI::App app{"vtstream build tooling: cut images into tile pyramids, merge sharded builds",
               "vts"};
  std::vector<vts::cli::Adder> adders{&vts::cli::add_build, &vts::cli::add_plan,
                                      &vts::cli::add_merge, &vts::cli::add_extract,
                                      &vts::cli::add_export};
#ifdef VTS_HAVE_ACCURACY
  adders.push_back(&vts::cli::add_bench);
#endif
  return vts::cli::run_cli(app, adders, argc, argv);
}

// vts — the vtstream runtime: serving, caching, warming, load testing, viewing and inspecting
// archives, extracting a tile as PNG. It links neither GDAL nor OpenImageIO; the commands that cut
// images (build, plan, merge, export, bench, and extract of a level or to other image formats)
// live in `vts-build` (main_build.cpp), to which `vts` hands them over (handover.cpp), so
// `vts build ...` works wherever both are installed (and says that vts-build is missing where it
// is not).
#include "commands.hpp"

int main(int argc, char** argv) {
  if (const char* command = vts::cli::builder_command(argc, argv))
    return vts::cli::hand_over_to_builder(command, argc, argv);
  CLI::App app{"vtstream: build, serve and view planet-scale textures as streamed tile pyramids",
               "vts"};
#ifdef VTS_HAVE_BUILDER
  vts::cli::list_builder_commands(app);  // a server-only build neither lists nor has them
#endif
  std::vector<vts::cli::Adder> adders{&vts::cli::add_info,     &vts::cli::add_verify,
                                      &vts::cli::add_serve,    &vts::cli::add_sign,
                                      &vts::cli::add_cache,    &vts::cli::add_warm,
                                      &vts::cli::add_loadtest, &vts::cli::add_extract_runtime};
#ifdef VTS_HAVE_VIEWER
  adders.push_back(&vts::cli::add_view);
#endif
  return vts::cli::run_cli(app, adders, argc, argv);
}

// open_reader(): local files, sets and remote objects behind one call (vts/store/open.hpp).
#include "vts/store/open.hpp"

#include "vts/store/location.hpp"
#include "vts/store/store.hpp"

namespace vts::store {
namespace {

bool ends_with_manifest(std::string_view location) {
  const std::string_view path = location.substr(0, location.find_first_of("?#"));
  const std::string_view name = archive::kSetManifestName;
  return path.size() >= name.size() && path.substr(path.size() - name.size()) == name &&
         (path.size() == name.size() || path[path.size() - name.size() - 1] == '/');
}

// The location of `name` beside the manifest at `manifest` (its query, a pre-signed URL's
// signature, does not carry over: each archive needs its own).
std::string beside(const std::string& manifest, const std::string& name) {
  const std::string path = manifest.substr(0, manifest.find_first_of("?#"));
  return path.substr(0, path.rfind('/') + 1) + name;
}

Result<std::shared_ptr<archive::Reader>> open_remote_archive(const std::string& location,
                                                             const StoreOptions& options,
                                                             const archive::ReaderOptions& r) {
  Result<std::unique_ptr<archive::ByteSource>> source = open_object(location, options);
  if (!source) return std::move(source).error();
  return archive::Reader::open_source(std::move(*source), r);
}

}  // namespace

Result<std::shared_ptr<archive::Reader>> open_reader(const std::string& location,
                                                     const StoreOptions& options,
                                                     const archive::ReaderOptions& reader) {
  if (!is_remote(location)) return archive::Reader::open(location, reader);
  if (!ends_with_manifest(location)) return open_remote_archive(location, options, reader);
  Result<std::string> text = get_object(location, options, kMaxManifestBytes);
  if (!text) return std::move(text).error();
  Result<archive::SetManifest> m = archive::SetManifest::from_json(*text, location);
  if (!m) return std::move(m).error();
  return archive::open_set(*m, [&](const std::string& name) {
    return open_remote_archive(beside(location, name), options, reader);
  });
}

}  // namespace vts::store

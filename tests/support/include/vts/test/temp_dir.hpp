// A fresh, private directory under the system temporary directory, removed with everything in it
// when the object goes out of scope.
#pragma once

#include <filesystem>
#include <string>

namespace vts::test {

class TempDir {
 public:
  // Creates <tmp>/<prefix>-XXXXXX (mkdtemp); throws std::runtime_error when it cannot.
  explicit TempDir(const std::string& prefix = "vts-test");
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;

  const std::filesystem::path& path() const { return path_; }
  std::filesystem::path operator/(const std::filesystem::path& name) const { return path_ / name; }

 private:
  std::filesystem::path path_;
};

}  // namespace vts::test

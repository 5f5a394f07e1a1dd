#include "vts/test/address_space.hpp"

#include <fstream>
#include <string>

namespace vts::test {

std::uint64_t virtual_memory_bytes() {
  std::ifstream in("/proc/self/status");
  std::string key;
  while (in >> key) {
    if (key == "VmSize:") {
      std::uint64_t kib = 0;
      in >> kib;
      return kib * 1024;
    }
    in.ignore(1 << 20, '\n');
  }
  return 0;
}

AddressSpaceLimit::AddressSpaceLimit(std::uint64_t room) {
  getrlimit(RLIMIT_AS, &old_);
  const std::uint64_t now = virtual_memory_bytes();
  rlimit limited = old_;
  limited.rlim_cur = now + room;
  ok_ = now > 0 && setrlimit(RLIMIT_AS, &limited) == 0;
}

AddressSpaceLimit::~AddressSpaceLimit() {
  setrlimit(RLIMIT_AS, &old_);
}

}  // namespace vts::test

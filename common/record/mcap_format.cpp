#include "common/record/mcap_format.hpp"

#include <zlib.h>

#include <algorithm>

namespace teleop::record::mcap {

std::uint32_t crc32(std::uint32_t crc, std::string_view bytes) {
  uLong c = crc;
  // zlib takes a uInt length: feed blocks well below 4 GiB.
  constexpr std::size_t kBlock = std::size_t{1} << 30;
  while (!bytes.empty()) {
    const std::size_t n = std::min(bytes.size(), kBlock);
    c = ::crc32(c, reinterpret_cast<const Bytef*>(bytes.data()), static_cast<uInt>(n));
    bytes.remove_prefix(n);
  }
  return static_cast<std::uint32_t>(c);
}

std::uint32_t crc32_combine(std::uint32_t first, std::uint32_t second,
                            std::uint64_t second_length) {
  return static_cast<std::uint32_t>(
      ::crc32_combine(first, second, static_cast<z_off_t>(second_length)));
}

}  // namespace teleop::record::mcap

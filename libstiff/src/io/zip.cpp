#include "io/zip.hpp"

#include <array>

#include "stiff/error.hpp"

namespace stiff::detail {

uint32_t crc32(const std::string& data) {
  // A function-local static is initialised once, thread-safely (two exports may run at once).
  static const std::array<uint32_t, 256> table = [] {
    std::array<uint32_t, 256> t{};
    for (uint32_t i = 0; i < 256; ++i) {
      uint32_t c = i;
      for (int k = 0; k < 8; ++k) c = c & 1 ? 0xEDB88320u ^ (c >> 1) : c >> 1;
      t[i] = c;
    }
    return t;
  }();
  uint32_t c = 0xFFFFFFFFu;
  for (unsigned char b : data) c = table[(c ^ b) & 0xFF] ^ (c >> 8);
  return c ^ 0xFFFFFFFFu;
}

std::string zip_stored(const std::vector<ZipEntry>& entries) {
  std::string out, central;
  auto u16 = [](std::string* s, unsigned v) {
    s->push_back(static_cast<char>(v & 0xff));
    s->push_back(static_cast<char>((v >> 8) & 0xff));
  };
  auto u32 = [](std::string* s, uint32_t v) {
    for (int i = 0; i < 4; ++i) s->push_back(static_cast<char>((v >> (8 * i)) & 0xff));
  };
  const unsigned dos_time = 0, dos_date = (0 << 9) | (1 << 5) | 1;  // 1980-01-01 (reproducible)
  for (const auto& e : entries) {
    if (e.data.size() >= 0xFFFFFFFFull || out.size() >= 0xFFFFFFFFull)
      throw InvalidArgument("zip: '" + e.name + "' does not fit in a zip without zip64 (4 GiB)");
    const uint32_t crc = crc32(e.data), size = static_cast<uint32_t>(e.data.size());
    const uint32_t offset = static_cast<uint32_t>(out.size());
    u32(&out, 0x04034b50);
    u16(&out, 20), u16(&out, 0), u16(&out, 0), u16(&out, dos_time), u16(&out, dos_date);
    u32(&out, crc), u32(&out, size), u32(&out, size);
    u16(&out, static_cast<unsigned>(e.name.size())), u16(&out, 0);
    out += e.name;
    out += e.data;
    u32(&central, 0x02014b50);
    u16(&central, 0x031E), u16(&central, 20), u16(&central, 0), u16(&central, 0);
    u16(&central, dos_time), u16(&central, dos_date);
    u32(&central, crc), u32(&central, size), u32(&central, size);
    u16(&central, static_cast<unsigned>(e.name.size())), u16(&central, 0), u16(&central, 0);
    u16(&central, 0), u16(&central, 0);
    u32(&central, (e.executable ? 0100755u : 0100644u) << 16);
    u32(&central, offset);
    central += e.name;
  }
  const uint32_t cd_offset = static_cast<uint32_t>(out.size());
  out += central;
  u32(&out, 0x06054b50);
  u16(&out, 0), u16(&out, 0);
  u16(&out, static_cast<unsigned>(entries.size())),
      u16(&out, static_cast<unsigned>(entries.size()));
  u32(&out, static_cast<uint32_t>(central.size())), u32(&out, cd_offset);
  u16(&out, 0);
  return out;
}

}  // namespace stiff::detail

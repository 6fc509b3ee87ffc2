// The FMU's zip writer against the published CRC-32 check value and the archive layout of
// PKWARE's APPNOTE 6.3 (every importer unpacks the FMU with its own zip reader; the Python
// tests open exported FMUs with zipfile as well).
#include "io/zip.hpp"

#include <gtest/gtest.h>

#include <cstdint>
#include <string>

namespace {

uint32_t u32_at(const std::string& s, size_t at) {
  uint32_t v = 0;
  for (int i = 3; i >= 0; --i) v = (v << 8) | static_cast<unsigned char>(s[at + i]);
  return v;
}
unsigned u16_at(const std::string& s, size_t at) {
  return static_cast<unsigned char>(s[at]) | (static_cast<unsigned char>(s[at + 1]) << 8);
}

TEST(Zip, Crc32IsTheStandardOne) {
  // The check value of CRC-32/ISO-HDLC (the zip and Ethernet CRC) for "123456789".
  EXPECT_EQ(stiff::detail::crc32("123456789"), 0xCBF43926u);
  EXPECT_EQ(stiff::detail::crc32(""), 0u);
}

TEST(Zip, StoredArchiveHasTheAppnoteLayout) {
  const std::string data = "joint 1 2 3\n";
  const std::string z = stiff::detail::zip_stored(
      {{"resources/model.txt", data, false}, {"binaries/x.so", "ELF", true}});
  // Local file header of the first entry, its name and its bytes stored as they are.
  ASSERT_EQ(u32_at(z, 0), 0x04034b50u);
  EXPECT_EQ(u16_at(z, 8), 0u);  // method 0: stored
  EXPECT_EQ(u32_at(z, 14), stiff::detail::crc32(data));
  EXPECT_EQ(u32_at(z, 18), data.size());
  EXPECT_EQ(z.substr(30, 19), "resources/model.txt");
  EXPECT_EQ(z.substr(49, data.size()), data);
  // End of central directory: two entries, and its offset points at a central header whose
  // external attributes give the second entry mode 0755.
  const size_t eocd = z.size() - 22;
  ASSERT_EQ(u32_at(z, eocd), 0x06054b50u);
  EXPECT_EQ(u16_at(z, eocd + 10), 2u);
  const size_t cd = u32_at(z, eocd + 16);
  ASSERT_EQ(u32_at(z, cd), 0x02014b50u);
  const size_t second = cd + 46 + u16_at(z, cd + 28);
  ASSERT_EQ(u32_at(z, second), 0x02014b50u);
  EXPECT_EQ(u32_at(z, second + 38) >> 16, 0100755u);
}

}  // namespace

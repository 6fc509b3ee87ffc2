// A minimal zip writer: stored (uncompressed) entries with CRC-32, no zip64 (PKWARE APPNOTE
// 6.3). Enough for an FMU, whose importers all read stored entries; private to the core.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace stiff::detail {

struct ZipEntry {
  std::string name;  ///< path inside the archive, '/' separated
  std::string data;
  bool executable = false;  ///< Unix mode 0755 instead of 0644
};

/// CRC-32 (IEEE 802.3 polynomial, reflected), as zip stores it.
uint32_t crc32(const std::string& data);

/// The archive's bytes. Timestamps are 1980-01-01 so that the same entries give the same file.
/// Throws InvalidArgument when an entry or the archive reaches 4 GiB (that needs zip64).
std::string zip_stored(const std::vector<ZipEntry>& entries);

}  // namespace stiff::detail

#pragma once
/// @file
/// Images written byte by byte for tests of what decoders do with them: PNG
/// chunks, and palette images whose pixels may index past their palette.

#include <cstdint>
#include <string>

namespace hg::testing {

// PNG chunk CRC (ISO 3309), for chunks written by hand.
inline std::uint32_t PngCrc(const std::string& type_and_data) {
  std::uint32_t crc = 0xFFFFFFFFu;
  for (const char ch : type_and_data) {
    crc ^= static_cast<unsigned char>(ch);
    for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ ((crc & 1u) != 0 ? 0xEDB88320u : 0u);
  }
  return crc ^ 0xFFFFFFFFu;
}

inline std::string BigEndian(std::uint32_t v) {
  return {static_cast<char>(v >> 24), static_cast<char>(v >> 16), static_cast<char>(v >> 8),
          static_cast<char>(v)};
}

// An 8-bit palette PNG of `width` x `height` with a palette of black and
// white, every pixel `index`; the image data stored uncompressed.
inline std::string PalettePng(int width, int height, unsigned char index) {
  auto chunk = [](const std::string& type_and_data) {
    return BigEndian(static_cast<std::uint32_t>(type_and_data.size() - 4)) + type_and_data +
           BigEndian(PngCrc(type_and_data));
  };
  std::string raw;  // Filter byte 0 and the row's indices, row after row.
  for (int y = 0; y < height; ++y) {
    raw += '\0';
    raw.append(static_cast<std::size_t>(width), static_cast<char>(index));
  }
  std::uint32_t a = 1, b = 0;  // Adler-32.
  for (const char ch : raw) {
    a = (a + static_cast<unsigned char>(ch)) % 65521;
    b = (b + a) % 65521;
  }
  const auto n = static_cast<std::uint16_t>(raw.size());
  std::string zlib = {'\x78',
                      '\x01',
                      '\x01',
                      static_cast<char>(n),
                      static_cast<char>(n >> 8),
                      static_cast<char>(~n),
                      static_cast<char>((~n) >> 8)};
  zlib += raw + BigEndian((b << 16) | a);
  const std::string ihdr = "IHDR" + BigEndian(static_cast<std::uint32_t>(width)) +
                           BigEndian(static_cast<std::uint32_t>(height)) +
                           std::string("\x08\x03\x00\x00\x00", 5);
  return std::string("\x89PNG\r\n\x1a\n", 8) + chunk(ihdr) +
         chunk(std::string("PLTE\0\0\0\xff\xff\xff", 10)) + chunk("IDAT" + zlib) + chunk("IEND");
}

// An 8-bit palette BMP with a palette of two colours, black and white, every
// pixel `index`.
inline std::string PaletteBmp(int width, int height, unsigned char index) {
  auto le32 = [](std::uint32_t v) {
    return std::string{static_cast<char>(v), static_cast<char>(v >> 8), static_cast<char>(v >> 16),
                       static_cast<char>(v >> 24)};
  };
  const auto row = static_cast<std::uint32_t>((width + 3) / 4 * 4);
  const std::uint32_t offset = 14 + 40 + 2 * 4;
  std::string bmp = "BM" + le32(offset + row * height) + le32(0) + le32(offset);
  bmp += le32(40) + le32(static_cast<std::uint32_t>(width)) +
         le32(static_cast<std::uint32_t>(height)) + std::string("\x01\x00\x08\x00", 4) + le32(0) +
         le32(row * height) + le32(2835) + le32(2835) + le32(2) + le32(0);
  bmp += std::string("\0\0\0\0\xff\xff\xff\0", 8);
  for (int y = 0; y < height; ++y) {
    bmp.append(static_cast<std::size_t>(width), static_cast<char>(index));
    bmp.append(row - static_cast<std::uint32_t>(width), '\0');
  }
  return bmp;
}

}  // namespace hg::testing

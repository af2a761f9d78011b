#include "common/input_file.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <initializer_list>
#include <iterator>

#include "common/config_error.h"

namespace hg::common {

std::ifstream OpenInputFile(const std::string& path, const std::string& what,
                            std::ios::openmode mode) {
  const std::string cannot = what.empty() ? "cannot open" : "cannot open " + what;
  std::error_code ec;
  const std::filesystem::file_status status = std::filesystem::status(path, ec);
  if (status.type() == std::filesystem::file_type::not_found) {
    throw ConfigError::At(path, 0, cannot + ": no such file");
  }
  if (status.type() == std::filesystem::file_type::directory) {
    throw ConfigError::At(path, 0, cannot + ": is a folder, not a file");
  }
  // A named pipe would block the read until someone writes into it (a stop
  // signal unanswered meanwhile), a device may never end.
  if (status.type() == std::filesystem::file_type::fifo ||
      status.type() == std::filesystem::file_type::socket ||
      status.type() == std::filesystem::file_type::character ||
      status.type() == std::filesystem::file_type::block) {
    throw ConfigError::At(path, 0, cannot + ": not a regular file (a pipe, socket or device)");
  }
  errno = 0;
  std::ifstream in(path, mode | std::ios::in);
  if (!in) {
    throw ConfigError::At(path, 0, errno != 0 ? cannot + ": " + std::strerror(errno) : cannot);
  }
  return in;
}

std::string ReadInputFile(const std::string& path, const std::string& what,
                          std::ios::openmode mode) {
  std::ifstream in = OpenInputFile(path, what, mode);
  std::string text;
  try {
    text.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  } catch (const std::exception& e) {  // The stream buffer's own errors (EISDIR, EIO).
    throw ConfigError::At(path, 0, std::string("read error: ") + e.what());
  }
  if (in.bad()) throw ConfigError::At(path, 0, "read error");
  return text;
}

namespace {

/// The next number of a PNM header, after whitespace or comments, into
/// *number; *at ends just past its digits (at most 9). False without digits.
bool ReadPnmNumber(const unsigned char* bytes, std::size_t n, std::size_t* at, long long* number) {
  *number = 0;
  while (*at < n && (std::isspace(bytes[*at]) != 0 || bytes[*at] == '#')) {
    if (bytes[*at] == '#') {
      while (*at < n && bytes[*at] != '\n') ++*at;
    } else {
      ++*at;
    }
  }
  const std::size_t start = *at;
  while (*at < n && *at - start < 9 && std::isdigit(bytes[*at]) != 0) {
    *number = *number * 10 + (bytes[*at] - '0');
    ++*at;
  }
  return *at != start;
}

/// A binary PGM/PPM header (P5, P6): width, height and maxval into
/// `numbers`; *at ends just past maxval. False when a number is missing or
/// is not followed by whitespace.
bool ReadPnmHeader(const unsigned char* bytes, std::size_t n, std::size_t* at,
                   long long (&numbers)[3]) {
  *at = 2;
  for (long long& number : numbers) {
    if (!ReadPnmNumber(bytes, n, at, &number) || *at >= n || std::isspace(bytes[*at]) == 0) {
      return false;
    }
  }
  return true;
}

/// Width and height of a PNM header (P1 to P6) into `size`.
bool ReadPnmSize(const unsigned char* bytes, std::size_t n, long long (&size)[2]) {
  std::size_t at = 2;
  return ReadPnmNumber(bytes, n, &at, &size[0]) && ReadPnmNumber(bytes, n, &at, &size[1]);
}

std::uint32_t BigEndian32(const unsigned char* b) {
  return (std::uint32_t{b[0]} << 24) | (std::uint32_t{b[1]} << 16) | (std::uint32_t{b[2]} << 8) |
         std::uint32_t{b[3]};
}

std::int32_t LittleEndian32(const unsigned char* b) {
  return static_cast<std::int32_t>(std::uint32_t{b[0]} | (std::uint32_t{b[1]} << 8) |
                                   (std::uint32_t{b[2]} << 16) | (std::uint32_t{b[3]} << 24));
}

/// The size a JPEG's start-of-frame segment states; false without one.
bool ReadJpegSize(const unsigned char* bytes, std::size_t n, long long* width, long long* height) {
  std::size_t at = 2;
  while (at + 4 <= n) {
    if (bytes[at] != 0xFF) return false;
    const unsigned char marker = bytes[at + 1];
    if (marker == 0xFF) {  // Fill byte.
      ++at;
      continue;
    }
    if (marker == 0xD8 || marker == 0x01 || (marker >= 0xD0 && marker <= 0xD7)) {
      at += 2;  // No segment follows.
      continue;
    }
    if (marker == 0xD9 || marker == 0xDA) return false;  // End, or the scan: no frame header.
    const std::size_t length = (std::size_t{bytes[at + 2]} << 8) | bytes[at + 3];
    const bool frame_header =
        marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC;
    if (frame_header) {
      if (length < 7 || at + 9 > n) return false;
      *height = (static_cast<long long>(bytes[at + 5]) << 8) | bytes[at + 6];
      *width = (static_cast<long long>(bytes[at + 7]) << 8) | bytes[at + 8];
      return true;
    }
    if (length < 2) return false;
    at += 2 + length;
  }
  return false;
}

/// CRC-32 of PNG chunks (ISO 3309, the one zlib computes).
std::uint32_t PngCrc(const unsigned char* bytes, std::size_t n) {
  std::uint32_t crc = 0xFFFFFFFFU;
  for (std::size_t i = 0; i < n; ++i) {
    crc ^= bytes[i];
    for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xEDB88320U & (0U - (crc & 1U)));
  }
  return crc ^ 0xFFFFFFFFU;
}

void AppendBigEndian32(std::uint32_t v, std::string* out) {
  for (int shift = 24; shift >= 0; shift -= 8) out->push_back(static_cast<char>(v >> shift));
}

void PutLittleEndian32(std::uint32_t v, std::string* out, std::size_t at) {
  for (int i = 0; i < 4; ++i) (*out)[at + i] = static_cast<char>(v >> (8 * i));
}

std::optional<std::string> PngWithPaletteFilled(const unsigned char* bytes, std::size_t n,
                                                unsigned char value) {
  // IHDR first: bit depth at byte 24, colour type at 25.
  if (n < 33 || std::memcmp(bytes + 12, "IHDR", 4) != 0 || bytes[25] != 3) return std::nullopt;
  const int depth = bytes[24];
  if (depth != 1 && depth != 2 && depth != 4 && depth != 8) return std::nullopt;
  const std::size_t colours = std::size_t{1} << depth;
  std::size_t at = 8;
  while (n - at >= 12) {
    const std::size_t length = BigEndian32(bytes + at);
    if (length > n - at - 12) return std::nullopt;  // The decoder refuses it.
    if (std::memcmp(bytes + at + 4, "PLTE", 4) == 0) {
      if (length % 3 != 0 || length / 3 >= colours) return std::nullopt;
      std::string out(reinterpret_cast<const char*>(bytes), at);
      std::string chunk = "PLTE";
      chunk.append(reinterpret_cast<const char*>(bytes + at + 8), length);
      chunk.append(3 * colours - length, static_cast<char>(value));
      AppendBigEndian32(static_cast<std::uint32_t>(3 * colours), &out);
      out += chunk;
      AppendBigEndian32(PngCrc(reinterpret_cast<const unsigned char*>(chunk.data()), chunk.size()),
                        &out);
      out.append(reinterpret_cast<const char*>(bytes + at + 12 + length), n - at - 12 - length);
      return out;
    }
    if (std::memcmp(bytes + at + 4, "IDAT", 4) == 0) return std::nullopt;
    at += 12 + length;
  }
  return std::nullopt;
}

std::optional<std::string> BmpWithPaletteFilled(const unsigned char* bytes, std::size_t n,
                                                unsigned char value) {
  // BITMAPINFOHEADER and later: bits a pixel at 28, colours used at 46; the
  // palette (4 bytes a colour) follows the header, the pixels start at the
  // offset at 10.
  if (n < 54 || bytes[0] != 'B' || bytes[1] != 'M') return std::nullopt;
  const auto header = static_cast<std::uint32_t>(LittleEndian32(bytes + 14));
  const int bits = bytes[28] | (bytes[29] << 8);
  if (header < 40 || header > n - 14 || bits < 1 || bits > 8) return std::nullopt;
  const std::uint32_t colours = 1U << bits;
  const auto used = static_cast<std::uint32_t>(LittleEndian32(bytes + 46));
  if (used == 0 || used >= colours) return std::nullopt;        // 0: all of them.
  const std::size_t end = 14 + header + std::size_t{used} * 4;  // The palette's end.
  if (end > n) return std::nullopt;
  const std::size_t added = std::size_t{colours - used} * 4;
  std::string out(reinterpret_cast<const char*>(bytes), end);
  for (std::uint32_t i = used; i < colours; ++i) {
    out.append(3, static_cast<char>(value));
    out.push_back(0);
  }
  out.append(reinterpret_cast<const char*>(bytes + end), n - end);
  PutLittleEndian32(colours, &out, 46);
  const auto offset = static_cast<std::uint32_t>(LittleEndian32(bytes + 10));
  if (offset >= end) PutLittleEndian32(offset + static_cast<std::uint32_t>(added), &out, 10);
  const auto size = static_cast<std::uint32_t>(LittleEndian32(bytes + 2));
  if (size != 0) PutLittleEndian32(size + static_cast<std::uint32_t>(added), &out, 2);
  return out;
}

}  // namespace

std::optional<std::string> WithPaletteFilled(std::string_view text, unsigned char value) {
  const auto* bytes = reinterpret_cast<const unsigned char*>(text.data());
  if (auto png = PngWithPaletteFilled(bytes, text.size(), value)) return png;
  return BmpWithPaletteFilled(bytes, text.size(), value);
}

ImageHeaderFacts InspectImageHeader(std::string_view text) {
  const auto* bytes = reinterpret_cast<const unsigned char*>(text.data());
  const std::size_t n = text.size();
  ImageHeaderFacts facts;
  static constexpr unsigned char kPngSignature[] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
  if (n >= sizeof(kPngSignature) && std::memcmp(bytes, kPngSignature, 8) == 0) {
    // IHDR comes first: its colour type (byte 9 of its data) 4 is grey +
    // alpha, 6 RGBA.
    if (n >= 26 && std::memcmp(bytes + 12, "IHDR", 4) == 0) {
      facts.png_alpha = bytes[25] == 4 || bytes[25] == 6;
      facts.width = BigEndian32(bytes + 16);
      facts.height = BigEndian32(bytes + 20);
    }
    // Chunks before the image data (tRNS must precede IDAT).
    std::size_t at = sizeof(kPngSignature);
    while (n - at >= 12) {
      const std::size_t length = (std::size_t{bytes[at]} << 24) |
                                 (std::size_t{bytes[at + 1]} << 16) |
                                 (std::size_t{bytes[at + 2]} << 8) | std::size_t{bytes[at + 3]};
      if (std::memcmp(bytes + at + 4, "tRNS", 4) == 0) facts.png_colour_key = true;
      if (std::memcmp(bytes + at + 4, "IDAT", 4) == 0 || length > n - at - 12) break;
      at += 12 + length;
    }
    return facts;
  }
  if (n >= 2 && bytes[0] == 'P' && (bytes[1] == '5' || bytes[1] == '6')) {
    std::size_t at = 0;
    long long numbers[3];
    if (ReadPnmHeader(bytes, n, &at, numbers)) facts.pnm_maxval = static_cast<int>(numbers[2]);
  }
  if (n >= 2 && bytes[0] == 'P' && bytes[1] >= '1' && bytes[1] <= '6') {
    long long size[2];
    if (ReadPnmSize(bytes, n, size)) {
      facts.width = size[0];
      facts.height = size[1];
    }
  } else if (n >= 26 && bytes[0] == 'B' && bytes[1] == 'M') {
    const std::int32_t header = LittleEndian32(bytes + 14);
    if (header == 12) {  // BITMAPCOREHEADER: 16-bit sizes.
      facts.width = bytes[18] | (bytes[19] << 8);
      facts.height = bytes[20] | (bytes[21] << 8);
    } else if (header >= 40) {
      facts.width = std::abs(static_cast<long long>(LittleEndian32(bytes + 18)));
      // Negative: rows stored top-down.
      facts.height = std::abs(static_cast<long long>(LittleEndian32(bytes + 22)));
    }
  } else if (n >= 4 && bytes[0] == 0xFF && bytes[1] == 0xD8) {
    long long width = 0, height = 0;
    if (ReadJpegSize(bytes, n, &width, &height)) {
      facts.width = width;
      facts.height = height;
    }
  }
  return facts;
}

bool IsTrustedImageFormat(std::string_view text) {
  const auto* b = reinterpret_cast<const unsigned char*>(text.data());
  const std::size_t n = text.size();
  auto starts = [&](std::initializer_list<unsigned char> sig) {
    return n >= sig.size() && std::equal(sig.begin(), sig.end(), b);
  };
  return starts({0x89, 'P', 'N', 'G'}) ||                           // PNG
         (n >= 2 && b[0] == 'P' && b[1] >= '1' && b[1] <= '7') ||   // PNM, PAM
         starts({'B', 'M'}) ||                                      // BMP
         starts({'I', 'I', 42, 0}) || starts({'M', 'M', 0, 42}) ||  // TIFF
         starts({0xFF, 0xD8}) ||                                    // JPEG
         starts({0xFF, 0x4F, 0xFF, 0x51}) ||                        // JPEG 2000 stream
         starts({0, 0, 0, 0x0C, 'j', 'P', ' ', ' '});               // JP2
}

bool IsCompleteImage(std::string_view text) {
  const auto* bytes = reinterpret_cast<const unsigned char*>(text.data());
  static constexpr unsigned char kPngSignature[] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
  static constexpr unsigned char kPngEnd[] = {0,   0,   0,    0,    'I',  'E',
                                              'N', 'D', 0xAE, 0x42, 0x60, 0x82};
  const std::size_t n = text.size();
  if (n >= sizeof(kPngSignature) && std::memcmp(bytes, kPngSignature, 8) == 0) {
    // Chunk by chunk (length, type, data, CRC) up to a whole IEND chunk;
    // bytes after it (some tools append some) are no part of the image.
    std::size_t at = sizeof(kPngSignature);
    while (n - at >= sizeof(kPngEnd)) {
      if (std::memcmp(bytes + at, kPngEnd, sizeof(kPngEnd)) == 0) return true;
      const std::size_t length = (std::size_t{bytes[at]} << 24) |
                                 (std::size_t{bytes[at + 1]} << 16) |
                                 (std::size_t{bytes[at + 2]} << 8) | std::size_t{bytes[at + 3]};
      if (length > n - at - 12) return false;  // Cut inside this chunk.
      at += 12 + length;
    }
    return false;
  }
  if (n >= 2 && bytes[0] == 0xFF && bytes[1] == 0xD8) {
    std::size_t end = n;  // Zero padding after the end marker is harmless.
    while (end > 4 && bytes[end - 1] == 0) --end;
    return end >= 4 && bytes[end - 2] == 0xFF && bytes[end - 1] == 0xD9;
  }
  if (n >= 2 && bytes[0] == 'P' && (bytes[1] == '5' || bytes[1] == '6')) {
    // Header: magic, width, height, maxval, then one whitespace byte before
    // the pixels.
    std::size_t at = 0;
    long long numbers[3];
    if (!ReadPnmHeader(bytes, n, &at, numbers)) return false;
    ++at;  // The single whitespace byte.
    const long long channels = bytes[1] == '6' ? 3 : 1;
    const long long sample_bytes = numbers[2] > 255 ? 2 : 1;
    return n >= at &&
           static_cast<long long>(n - at) >= numbers[0] * numbers[1] * channels * sample_bytes;
  }
  return true;
}

}  // namespace hg::common

#pragma once
/// @file
/// Opening input files with errors that name the file and say what is wrong.

#include <fstream>
#include <optional>
#include <string>
#include <string_view>

namespace hg::common {

/// Opens `path` for reading. A folder, a missing or unreadable file throws
/// ConfigError "PATH: cannot open WHAT: REASON" (`what`, e.g. "mask", may be
/// empty), instead of a stream that fails later with a message naming nothing.
[[nodiscard]] std::ifstream OpenInputFile(const std::string& path, const std::string& what,
                                          std::ios::openmode mode = std::ios::in);

/// The whole content of `path`, with OpenInputFile's errors and "read error".
[[nodiscard]] std::string ReadInputFile(const std::string& path, const std::string& what,
                                        std::ios::openmode mode = std::ios::in);

/// Whether an encoded image of a format that decoders accept half-read is all
/// there: a PNG ends with its IEND chunk, a JPEG with its end-of-image marker
/// (zero padding after it allowed),
/// a binary PGM/PPM holds every pixel its header announces. Other formats are
/// left to their decoder (true). A file cut short (disk full while recording,
/// a copy interrupted) is to be refused rather than decoded: libjpeg fills the
/// missing rows with grey, and libpng and OpenCV print on stderr.
[[nodiscard]] bool IsCompleteImage(std::string_view bytes);

/// What an encoded image's own header says that a decoder may drop.
struct ImageHeaderFacts {
  /// A binary PGM/PPM (P5, P6): its maxval, whose samples OpenCV does not
  /// scale to 8 bits (a 0/1 mask with maxval 1 decodes as 0/1, not 0/255);
  /// 0 for other formats.
  int pnm_maxval = 0;
  /// A PNG with a tRNS chunk: transparency by a colour key, which OpenCV
  /// drops from grey and RGB images.
  bool png_colour_key = false;
  /// A PNG with an alpha channel (grey + alpha or RGBA), which a grey or
  /// colour decode drops.
  bool png_alpha = false;
  /// The size the header states, read without decoding: PNG, PBM/PGM/PPM
  /// (P1 to P6), BMP and JPEG; 0 x 0 for other formats or a header that
  /// cannot be read. A decoder allocates what the header states, so a file of
  /// a few bytes can ask for gigabytes: check this first.
  long long width = 0;
  long long height = 0;
};
[[nodiscard]] ImageHeaderFacts InspectImageHeader(std::string_view bytes);

/// A palette image (PNG colour type 3, BMP of 1 to 8 bits a pixel) whose
/// palette has fewer colours than its pixels can index: a copy with the
/// palette filled up with the grey `value`; nullopt for any other image. A
/// pixel that indexes past the palette is damage, which decoders read as
/// black (background in a mask) without a word: decode the image as it is
/// and with the palette filled, and refuse it when the two differ.
[[nodiscard]] std::optional<std::string> WithPaletteFilled(std::string_view bytes,
                                                           unsigned char value);

/// Whether an encoded image is of a format whose decoder reads an 8-bit mask
/// as written, by its signature: PNG, PNM/PAM, BMP, TIFF, JPEG, JPEG 2000.
/// Others are refused rather than trusted: OpenCV's Sun raster decoder, for
/// one, returns an 8-bit grey image as all zeros (a mask as all background).
[[nodiscard]] bool IsTrustedImageFormat(std::string_view bytes);
/// The formats IsTrustedImageFormat() takes, for messages.
inline constexpr const char* kTrustedImageFormats = "PNG, PGM/PPM/PBM/PAM, BMP, TIFF or JPEG";

}  // namespace hg::common

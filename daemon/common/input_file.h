#pragma once
/// @file
/// Opening input files with errors that name the file and say what is wrong.

#include <fstream>
#include <string>

namespace hg::common {

/// Opens `path` for reading. A folder, a missing or unreadable file throws
/// ConfigError "PATH: cannot open WHAT: REASON" (`what`, e.g. "mask", may be
/// empty), instead of a stream that fails later with a message naming nothing.
[[nodiscard]] std::ifstream OpenInputFile(const std::string& path, const std::string& what,
                                          std::ios::openmode mode = std::ios::in);

/// The whole content of `path`, with OpenInputFile's errors and "read error".
[[nodiscard]] std::string ReadInputFile(const std::string& path, const std::string& what,
                                        std::ios::openmode mode = std::ios::in);

}  // namespace hg::common

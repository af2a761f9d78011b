#include "common/input_file.h"

#include <cerrno>
#include <cstring>
#include <filesystem>
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

}  // namespace hg::common

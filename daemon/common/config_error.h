#pragma once
/// @file
/// The one exception type for bad input at load and tool boundaries.

#include <stdexcept>
#include <string>

namespace hg::common {

/// Bad user input (config, mesh, mask). The message is one line and names the
/// file, the line where known, and the problem: "cams.yaml:12: K: needs 9 numbers".
class ConfigError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;

  /// Formats "file:line: message" (line omitted when < 1).
  static ConfigError At(const std::string& file, int line, const std::string& message) {
    return ConfigError(line >= 1 ? file + ":" + std::to_string(line) + ": " + message
                                 : file + ": " + message);
  }
};

}  // namespace hg::common

#pragma once
/// @file
/// Runs a command-line tool of the project and captures its exit code and output.

#include <string>

namespace hg::testing {

struct ProcessResult {
  int code = -1;
  std::string out;
  std::string err;
};

/// Runs `binary args` through the shell, stdout and stderr captured through
/// temporary files that are removed again.
ProcessResult RunTool(const std::string& binary, const std::string& args);

}  // namespace hg::testing
